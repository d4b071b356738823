//! [`ManualControl`]: sticks as MANUAL_CONTROL, sent at a fixed rate from a task of the
//! library's for as long as a [`ManualSession`] is open (a vehicle in a position mode takes
//! them as its pilot's; when they stop it keeps its failsafe).

use core::time::Duration;
use std::sync::{Arc, Mutex};

use mavstack_dialects::common::{ManualControl as ManualControlMessage, MavMessage};

use super::offboard::{MAX_RATE_HZ, MIN_RATE_HZ};
use super::{System, SystemError, lock};

/// Stick positions: `x` (pitch: forward), `y` (roll: right) and `r` (yaw: clockwise) in
/// −1…1, `z` (throttle) in 0…1 (0.5 holds height in position modes), and buttons.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sticks {
    /// Forward (−1…1).
    pub x: f32,
    /// Right (−1…1).
    pub y: f32,
    /// Throttle (0…1).
    pub z: f32,
    /// Yaw (−1…1).
    pub r: f32,
    /// Buttons 0–15, a bit each.
    pub buttons: u16,
}

impl Sticks {
    /// Centred sticks, half throttle: hold.
    pub const CENTRED: Self = Self {
        x: 0.0,
        y: 0.0,
        z: 0.5,
        r: 0.0,
        buttons: 0,
    };

    /// Checks the ranges.
    ///
    /// # Errors
    /// [`SystemError::Invalid`] naming the stick.
    pub fn check(&self) -> Result<(), SystemError> {
        for (name, v, low) in [
            ("x", self.x, -1.0),
            ("y", self.y, -1.0),
            ("r", self.r, -1.0),
            ("z", self.z, 0.0),
        ] {
            if !(v.is_finite() && (low..=1.0).contains(&v)) {
                return Err(SystemError::Invalid(format!(
                    "manual control: {name} {v} is not within {low}-1"
                )));
            }
        }
        Ok(())
    }

    /// As MANUAL_CONTROL for system `target` (axes scaled to ±1000, throttle to 0–1000).
    #[must_use]
    pub fn message(&self, target: u8) -> MavMessage {
        let axis = |v: f32| (v * 1000.0).round() as i16;
        MavMessage::ManualControl(ManualControlMessage {
            target,
            x: axis(self.x),
            y: axis(self.y),
            z: axis(self.z),
            r: axis(self.r),
            buttons: self.buttons,
            ..ManualControlMessage::default()
        })
    }
}

/// Manual control of a system (from [`System::manual_control`]).
#[derive(Clone, Debug)]
pub struct ManualControl {
    system: System,
}

/// An open stream of MANUAL_CONTROL (from [`ManualControl::start`]); dropping it stops the
/// stream.
#[derive(Debug)]
pub struct ManualSession {
    latest: Arc<Mutex<Sticks>>,
    stream: tokio::task::AbortHandle,
}

impl ManualControl {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// Sends [`Sticks::CENTRED`] (then what [`ManualSession::set`] gives) at `rate_hz`
    /// (2–100) until the session ends.
    ///
    /// # Errors
    /// [`SystemError::Invalid`] for a rate out of range.
    pub fn start(&self, rate_hz: f32) -> Result<ManualSession, SystemError> {
        if !(rate_hz.is_finite() && (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate_hz)) {
            return Err(SystemError::Invalid(format!(
                "manual control: rate {rate_hz} Hz is not within {MIN_RATE_HZ}-{MAX_RATE_HZ} Hz"
            )));
        }
        let latest = Arc::new(Mutex::new(Sticks::CENTRED));
        let system = self.system.clone();
        let sticks = Arc::clone(&latest);
        let period = Duration::from_secs_f32(1.0 / rate_hz);
        let stream = tokio::spawn(async move {
            let mut tick = tokio::time::interval(period);
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            let target = system.target().system;
            loop {
                tick.tick().await;
                let now = *lock(&sticks);
                if system.send(&now.message(target)).await.is_err() {
                    return;
                }
            }
        })
        .abort_handle();
        Ok(ManualSession { latest, stream })
    }
}

impl ManualSession {
    /// Sends `sticks` from the next tick on.
    ///
    /// # Errors
    /// [`SystemError::Invalid`] (the stream keeps the sticks before).
    pub fn set(&self, sticks: Sticks) -> Result<(), SystemError> {
        sticks.check()?;
        *lock(&self.latest) = sticks;
        Ok(())
    }
}

impl Drop for ManualSession {
    fn drop(&mut self) {
        self.stream.abort();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sticks_out_of_range_are_refused_and_scaled_to_the_protocols_units() {
        let wild = Sticks {
            x: 1.5,
            ..Sticks::CENTRED
        };
        assert!(matches!(wild.check(), Err(SystemError::Invalid(m)) if m.contains('x')));
        let nan = Sticks {
            z: f32::NAN,
            ..Sticks::CENTRED
        };
        assert!(nan.check().is_err());
        let MavMessage::ManualControl(m) = Sticks {
            x: 0.5,
            y: -1.0,
            z: 0.5,
            r: 0.0,
            buttons: 3,
        }
        .message(1) else {
            panic!("MANUAL_CONTROL");
        };
        assert_eq!((m.x, m.y, m.z, m.r, m.buttons), (500, -1000, 500, 0, 3));
    }
}
