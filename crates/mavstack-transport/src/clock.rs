//! The transport's clock: monotonic microseconds anchored to the Unix epoch.
//!
//! Every connection in a process reads the same clock. It is a [`std::time::Instant`] (so it
//! never jumps backwards) whose zero was set, once per process, to the wall clock's reading:
//! `now().as_micros()` is "microseconds since the Unix epoch" as well as monotonic, so a
//! received frame's time can go straight into a tlog record. Over a long run it drifts from
//! the wall clock as far as the system clock is slewed or stepped; it never follows a step.
//!
//! ```
//! let a = mavstack_transport::clock::now();
//! let b = mavstack_transport::clock::now();
//! assert!(b >= a);
//! assert!(a.as_micros() > 1_600_000_000_000_000); // after September 2020
//! ```

use core::time::Duration;
use std::sync::OnceLock;

use mavstack_core::time::Instant;

/// The process's anchor: a monotonic reading and the wall clock's microseconds at it.
fn anchor() -> &'static (std::time::Instant, u64) {
    static ANCHOR: OnceLock<(std::time::Instant, u64)> = OnceLock::new();
    ANCHOR.get_or_init(|| {
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX));
        (std::time::Instant::now(), wall)
    })
}

/// The current time: monotonic, in microseconds since (about) the Unix epoch.
#[must_use]
pub fn now() -> Instant {
    let (mono, wall) = anchor();
    Instant::from_micros(
        wall.saturating_add(u64::try_from(mono.elapsed().as_micros()).unwrap_or(u64::MAX)),
    )
}

/// The [`std::time::Instant`] of `t`: for sleeping until a state machine's deadline. Instants
/// before the anchor map to the anchor (already past), instants too far ahead to represent
/// to a year from the anchor.
#[must_use]
pub(crate) fn to_std(t: Instant) -> std::time::Instant {
    let (mono, wall) = anchor();
    let ahead = Duration::from_micros(t.as_micros().saturating_sub(*wall));
    mono.checked_add(ahead)
        .or_else(|| mono.checked_add(Duration::from_secs(365 * 24 * 3600)))
        .unwrap_or(*mono)
}

/// The tokio instant of `t` (the same instant on tokio's clock).
#[must_use]
pub fn to_tokio(t: Instant) -> tokio::time::Instant {
    tokio::time::Instant::from_std(to_std(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converts_both_ways() {
        let before = std::time::Instant::now();
        let t = now();
        let after = std::time::Instant::now();
        // A reading maps to an instant between the std readings around it (microseconds
        // are the clock's grain: one either side).
        let grain = Duration::from_micros(1);
        let std_t = to_std(t);
        assert!(std_t + grain >= before, "{std_t:?} before {before:?}");
        assert!(std_t <= after + grain, "{std_t:?} after {after:?}");
        // Durations carry over exactly, both ways.
        let later = t + Duration::from_millis(250);
        assert_eq!(
            to_std(later).duration_since(std_t),
            Duration::from_millis(250)
        );
        assert_eq!(
            to_tokio(later).duration_since(to_tokio(t)),
            Duration::from_millis(250)
        );
        // Far past and far future never panic.
        let _ = to_std(Instant::ZERO);
        let _ = to_std(Instant::MAX);
    }
}
