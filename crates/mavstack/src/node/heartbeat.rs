//! The node's own HEARTBEAT timer, sans-IO: the driver asks it at every turn whether one is
//! due and wakes for [`Heartbeat::next`].
//!
//! The period holds on average whatever the turns: the next HEARTBEAT is due a period after
//! the last one was due, not after the turn that sent it, so a late turn does not push every
//! later HEARTBEAT back. A turn more than a period late sends one HEARTBEAT, not a burst.

use core::time::Duration;

use mavstack_core::time::Instant;

/// The node's own HEARTBEAT: its encoded payload, period and next time.
pub(super) struct Heartbeat {
    pub(super) payload: Vec<u8>,
    pub(super) period: Duration,
    pub(super) next: Instant,
}

impl Heartbeat {
    /// Whether a HEARTBEAT is due at `now`; if so, the timer moves on to the next one.
    pub(super) fn due(&mut self, now: Instant) -> bool {
        if now < self.next {
            return false;
        }
        self.next += self.period;
        if self.next <= now {
            // More than a period late: start again from now.
            self.next = now + self.period;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T0: Instant = Instant::from_secs(1_000);

    fn timer(period_ms: u64) -> Heartbeat {
        Heartbeat {
            payload: vec![0; 9],
            period: Duration::from_millis(period_ms),
            next: T0,
        }
    }

    /// Turns every `step_us` over `span_ms` of virtual time: how many HEARTBEATs went out.
    fn count(hb: &mut Heartbeat, step_us: u64, span_ms: u64) -> u64 {
        let mut sent = 0;
        let mut t = T0;
        while t < T0 + Duration::from_millis(span_ms) {
            sent += u64::from(hb.due(t));
            t += Duration::from_micros(step_us);
        }
        sent
    }

    #[test]
    fn woken_at_its_deadlines_it_sends_one_per_period() {
        let mut hb = timer(100);
        let mut sent = 0;
        let mut t = T0;
        while t < T0 + Duration::from_secs(10) {
            assert!(hb.due(t), "due at its own deadline");
            assert!(!hb.due(t), "once per deadline");
            sent += 1;
            t = hb.next;
        }
        assert_eq!(sent, 100, "10 s at 100 ms");
    }

    #[test]
    fn turns_at_any_other_times_keep_the_period() {
        // Turns every 7 ms (so each HEARTBEAT is up to 7 ms late), and every 30 ms: still
        // one per 100 ms over 10 s, not one per 105 or 120 ms.
        assert_eq!(count(&mut timer(100), 7_000, 10_000), 100);
        assert_eq!(count(&mut timer(100), 30_000, 10_000), 100);
        assert_eq!(count(&mut timer(1_000), 1_234, 60_000), 60);
    }

    #[test]
    fn a_long_stall_sends_one_not_a_burst() {
        let mut hb = timer(100);
        assert!(hb.due(T0));
        let late = T0 + Duration::from_secs(2);
        assert!(hb.due(late));
        assert!(!hb.due(late), "no catch-up burst");
        assert_eq!(hb.next, late + Duration::from_millis(100));
    }
}
