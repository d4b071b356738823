//! Time for sans-IO state machines: a plain monotonic instant in microseconds.
//!
//! State machines never read a clock. Their driver reads one and passes the time in as an
//! [`Instant`]; the state machine answers with deadlines of the same type
//! (`poll_timeout() -> Option<Instant>`). An [`Instant`] is a count of microseconds since an
//! epoch the driver chooses (boot, process start, the Unix epoch); only differences between
//! instants of the same driver mean anything. It is `no_std`, `Copy` and 8 bytes.
//!
//! Arithmetic never panics: adding past the end saturates at [`Instant::MAX`], subtracting
//! below the epoch saturates at [`Instant::ZERO`], and the difference of two instants is zero
//! when the "later" one is earlier.
//!
//! ```
//! use core::time::Duration;
//! use mavstack_core::time::Instant;
//! let start = Instant::from_micros(1_000);
//! let deadline = start + Duration::from_millis(5);
//! assert_eq!(deadline.as_micros(), 6_000);
//! assert_eq!(deadline - start, Duration::from_millis(5));
//! assert_eq!(start - deadline, Duration::ZERO); // saturates
//! assert!(deadline > start);
//! ```

use core::ops::{Add, AddAssign, Sub, SubAssign};
use core::time::Duration;

/// A point in monotonic time: microseconds since the driver's epoch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Instant(u64);

/// Whole microseconds of `d`, saturating at `u64::MAX`.
fn micros(d: Duration) -> u64 {
    u64::try_from(d.as_micros()).unwrap_or(u64::MAX)
}

impl Instant {
    /// The epoch itself.
    pub const ZERO: Self = Self(0);
    /// The last representable instant (about 584,000 years after the epoch).
    pub const MAX: Self = Self(u64::MAX);

    /// The instant `us` microseconds after the epoch.
    #[must_use]
    pub const fn from_micros(us: u64) -> Self {
        Self(us)
    }

    /// The instant `ms` milliseconds after the epoch (saturating).
    #[must_use]
    pub const fn from_millis(ms: u64) -> Self {
        Self(ms.saturating_mul(1_000))
    }

    /// The instant `s` seconds after the epoch (saturating).
    #[must_use]
    pub const fn from_secs(s: u64) -> Self {
        Self(s.saturating_mul(1_000_000))
    }

    /// Microseconds since the epoch.
    #[must_use]
    pub const fn as_micros(self) -> u64 {
        self.0
    }

    /// The time since the epoch.
    #[must_use]
    pub const fn since_epoch(self) -> Duration {
        Duration::from_micros(self.0)
    }

    /// `self + d`, or `None` past [`Instant::MAX`].
    #[must_use]
    pub fn checked_add(self, d: Duration) -> Option<Self> {
        u64::try_from(d.as_micros())
            .ok()
            .and_then(|us| self.0.checked_add(us))
            .map(Self)
    }

    /// `self - d`, or `None` before the epoch.
    #[must_use]
    pub fn checked_sub(self, d: Duration) -> Option<Self> {
        u64::try_from(d.as_micros())
            .ok()
            .and_then(|us| self.0.checked_sub(us))
            .map(Self)
    }

    /// The time from `earlier` to `self`, or `None` if `earlier` is later.
    #[must_use]
    pub const fn checked_duration_since(self, earlier: Self) -> Option<Duration> {
        match self.0.checked_sub(earlier.0) {
            Some(us) => Some(Duration::from_micros(us)),
            None => None,
        }
    }

    /// The time from `earlier` to `self`, zero if `earlier` is later.
    #[must_use]
    pub const fn saturating_duration_since(self, earlier: Self) -> Duration {
        Duration::from_micros(self.0.saturating_sub(earlier.0))
    }
}

impl Add<Duration> for Instant {
    type Output = Self;

    /// Saturates at [`Instant::MAX`].
    fn add(self, d: Duration) -> Self {
        Self(self.0.saturating_add(micros(d)))
    }
}

impl AddAssign<Duration> for Instant {
    fn add_assign(&mut self, d: Duration) {
        *self = *self + d;
    }
}

impl Sub<Duration> for Instant {
    type Output = Self;

    /// Saturates at [`Instant::ZERO`].
    fn sub(self, d: Duration) -> Self {
        Self(self.0.saturating_sub(micros(d)))
    }
}

impl SubAssign<Duration> for Instant {
    fn sub_assign(&mut self, d: Duration) {
        *self = *self - d;
    }
}

impl Sub for Instant {
    type Output = Duration;

    /// [`Instant::saturating_duration_since`]: zero if `other` is later.
    fn sub(self, other: Self) -> Duration {
        self.saturating_duration_since(other)
    }
}

impl core::fmt::Display for Instant {
    /// Seconds since the epoch with microsecond precision, e.g. `12.000345s`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}.{:06}s", self.0 / 1_000_000, self.0 % 1_000_000)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_saturates() {
        let t = Instant::from_secs(2);
        assert_eq!(
            t + Duration::from_micros(5),
            Instant::from_micros(2_000_005)
        );
        assert_eq!(Instant::MAX + Duration::from_secs(1), Instant::MAX);
        assert_eq!(Instant::ZERO - Duration::from_secs(1), Instant::ZERO);
        assert_eq!(t - Instant::from_secs(3), Duration::ZERO);
        assert_eq!(t - Instant::from_millis(500), Duration::from_millis(1_500));
        assert_eq!(Instant::MAX.checked_add(Duration::from_micros(1)), None);
        assert_eq!(Instant::ZERO.checked_sub(Duration::from_micros(1)), None);
        assert_eq!(t.checked_duration_since(Instant::from_secs(3)), None);
        assert_eq!(Instant::from_secs(u64::MAX), Instant::MAX);
        let mut u = t;
        u += Duration::from_secs(1);
        u -= Duration::from_millis(250);
        assert_eq!(u, Instant::from_millis(2_750));
        assert_eq!(t + Duration::MAX, Instant::MAX);
    }

    #[test]
    fn displays_seconds() {
        extern crate std;
        use std::string::ToString as _;
        assert_eq!(Instant::from_micros(12_000_345).to_string(), "12.000345s");
        assert_eq!(Instant::ZERO.to_string(), "0.000000s");
    }
}
