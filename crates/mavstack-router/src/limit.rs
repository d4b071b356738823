//! Rate limits on what a link sends: per message and source, and a byte budget.

use alloc::collections::BTreeMap;
use alloc::vec::Vec;

use mavstack_core::time::Instant;

use crate::config::RateLimits;

/// One link's limiter state.
#[derive(Clone, Debug, Default)]
pub(crate) struct Limiter {
    /// (message id, minimum interval in µs).
    per_message: Vec<(u32, u64)>,
    last: BTreeMap<(u8, u8, u32), Instant>,
    bucket: Option<Bucket>,
}

/// A token bucket in byte-microseconds: `rate` bytes per second, a burst of one second.
#[derive(Clone, Copy, Debug)]
struct Bucket {
    rate: i64,
    tokens: i64,
    at: Instant,
}

const MICROS: i64 = 1_000_000;

impl Limiter {
    pub(crate) fn new(limits: &RateLimits) -> Self {
        Self {
            per_message: limits
                .per_message
                .iter()
                .map(|&(id, hz)| (id, 1_000_000 / u64::from(hz.max(1))))
                .collect(),
            last: BTreeMap::new(),
            bucket: limits.bytes_per_s.map(|rate| Bucket {
                rate: i64::from(rate),
                tokens: i64::from(rate) * MICROS,
                at: Instant::ZERO,
            }),
        }
    }

    /// Whether a frame of `msg_id` from `(sysid, compid)` may go now (and records it).
    pub(crate) fn allow_message(
        &mut self,
        now: Instant,
        sysid: u8,
        compid: u8,
        msg_id: u32,
    ) -> bool {
        let Some(&(_, interval)) = self.per_message.iter().find(|(id, _)| *id == msg_id) else {
            return true;
        };
        let key = (sysid, compid, msg_id);
        // 10 % slack, so that a source sending at exactly the limit is not halved by jitter.
        let min_gap = interval - interval / 10;
        match self.last.get_mut(&key) {
            Some(last)
                if now.saturating_duration_since(*last).as_micros() < u128::from(min_gap) =>
            {
                false
            }
            Some(last) => {
                *last = now;
                true
            }
            None => {
                self.last.insert(key, now);
                true
            }
        }
    }

    /// Takes `len` bytes from the budget: telemetry only if they are there; control always
    /// (the budget may go negative, delaying telemetry after it).
    pub(crate) fn spend(&mut self, now: Instant, len: usize, control: bool) -> bool {
        let Some(b) = &mut self.bucket else {
            return true;
        };
        let elapsed =
            i64::try_from(now.saturating_duration_since(b.at).as_micros()).unwrap_or(i64::MAX);
        if b.at == Instant::ZERO {
            b.at = now;
        } else {
            b.tokens = b
                .tokens
                .saturating_add(elapsed.saturating_mul(b.rate))
                .min(b.rate * MICROS);
            b.at = now;
        }
        let cost = i64::try_from(len)
            .unwrap_or(i64::MAX)
            .saturating_mul(MICROS);
        if control || b.tokens >= cost {
            b.tokens -= cost;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::time::Duration;

    #[test]
    fn per_message_rate() {
        let mut l = Limiter::new(&RateLimits {
            per_message: alloc::vec![(30, 10)],
            bytes_per_s: None,
        });
        let mut now = Instant::from_secs(10);
        let mut passed = 0;
        for _ in 0..100 {
            if l.allow_message(now, 1, 1, 30) {
                passed += 1;
            }
            assert!(
                l.allow_message(now, 1, 1, 33),
                "other messages are not limited"
            );
            now += Duration::from_millis(20); // 50 Hz for 2 s
        }
        assert_eq!(passed, 20);
        // Another source has its own allowance.
        assert!(l.allow_message(now, 2, 1, 30));
    }

    #[test]
    fn byte_budget_lets_control_through() {
        let mut l = Limiter::new(&RateLimits {
            per_message: alloc::vec![],
            bytes_per_s: Some(1000),
        });
        let t = Instant::from_secs(1);
        assert!(l.spend(t, 600, false));
        assert!(!l.spend(t, 600, false));
        assert!(l.spend(t, 600, true), "control always goes");
        assert!(
            !l.spend(t + Duration::from_millis(500), 400, false),
            "budget in debt"
        );
        assert!(l.spend(t + Duration::from_millis(1500), 100, false));
    }
}
