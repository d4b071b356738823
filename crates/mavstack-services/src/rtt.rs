//! Round-trip time estimation for retransmission timeouts (RFC 6298's estimator).
//!
//! The protocols' fixed timeouts (250 ms per mission item, 500 ms per parameter request)
//! are right for a slow telemetry radio and far too long on a fast link: each lost frame
//! costs a whole timeout. A client measures the round trip of every request answered on its
//! first send (Karn's rule: never a retransmitted one, whose answer is ambiguous) and waits
//! `srtt + 4 × rttvar` instead, never less than [`Rtt::FLOOR`] and never more than the
//! protocol's fixed value, which stays the ceiling (and the wait until a first sample).

use core::time::Duration;

use mavstack_core::time::Instant;

/// A smoothed round-trip time and its variation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Rtt {
    /// Smoothed RTT and RTT variation, µs; `None` until the first sample.
    estimate: Option<(u64, u64)>,
}

impl Rtt {
    /// The shortest wait ever used: scheduling jitter on a loaded host is in this range.
    pub(crate) const FLOOR: Duration = Duration::from_millis(20);

    /// Takes one sample: a request sent at `sent` answered at `now`.
    pub(crate) fn sample(&mut self, sent: Instant, now: Instant) {
        let r = u64::try_from(now.saturating_duration_since(sent).as_micros()).unwrap_or(u64::MAX);
        self.estimate = Some(match self.estimate {
            None => (r, r / 2),
            Some((srtt, rttvar)) => {
                let rttvar = (3 * rttvar + srtt.abs_diff(r)) / 4;
                let srtt = (7 * srtt + r) / 8;
                (srtt, rttvar)
            }
        });
    }

    /// The smoothed round trip in µs, once there is a sample.
    pub(crate) fn srtt_us(&self) -> Option<u64> {
        self.estimate.map(|(srtt, _)| srtt)
    }

    /// How long to wait for an answer: the estimate's timeout within
    /// [[`Rtt::FLOOR`], `ceiling`], or `ceiling` before any sample.
    pub(crate) fn timeout(&self, ceiling: Duration) -> Duration {
        match self.estimate {
            None => ceiling,
            Some((srtt, rttvar)) => Duration::from_micros(srtt.saturating_add(4 * rttvar))
                .max(Self::FLOOR)
                .min(ceiling),
        }
    }
}

impl Rtt {
    /// The wait before send number `attempt` (1 = the first) is given up on: the timeout,
    /// doubled for each resend already made (RFC 6298's back-off), at most `ceiling`.
    pub(crate) fn backoff(&self, ceiling: Duration, attempt: u8) -> Duration {
        let doublings = u32::from(attempt.saturating_sub(1)).min(16);
        self.timeout(ceiling)
            .saturating_mul(1 << doublings)
            .min(ceiling)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converges_to_the_link_and_stays_within_bounds() {
        let mut rtt = Rtt::default();
        let ceiling = Duration::from_millis(250);
        assert_eq!(rtt.timeout(ceiling), ceiling);
        let t0 = Instant::from_millis(1000);
        for _ in 0..20 {
            rtt.sample(t0, t0 + Duration::from_millis(2));
        }
        assert_eq!(rtt.timeout(ceiling), Rtt::FLOOR);
        for _ in 0..20 {
            rtt.sample(t0, t0 + Duration::from_millis(100));
        }
        let t = rtt.timeout(ceiling);
        assert!(t > Duration::from_millis(100) && t <= ceiling, "{t:?}");
        rtt.sample(t0, t0 + Duration::from_secs(5));
        assert_eq!(rtt.timeout(ceiling), ceiling);
    }

    #[test]
    fn backoff_doubles_up_to_the_ceiling() {
        let mut rtt = Rtt::default();
        let t0 = Instant::from_millis(1000);
        for _ in 0..20 {
            rtt.sample(t0, t0 + Duration::from_millis(1));
        }
        let ceiling = Duration::from_millis(250);
        let waits: alloc::vec::Vec<u128> = (1..=6)
            .map(|a| rtt.backoff(ceiling, a).as_millis())
            .collect();
        assert_eq!(waits, [20, 40, 80, 160, 250, 250]);
    }
}
