//! [`Offboard`]: a setpoint stream owned by the library. [`Offboard::start`] sends the
//! latest [`Setpoint`] at a fixed rate from a task of its own (never from the caller's: a
//! slow caller does not starve the stream, and PX4 1.16 leaves OFFBOARD 1 s, its
//! COM_OF_LOSS_T, after the last setpoint), switches the vehicle into PX4's OFFBOARD or ArduPilot's GUIDED once setpoints
//! flow, and holds position when the session stops — also when it is dropped (a program
//! that crashes outright leaves the vehicle to its own failsafe: PX4 falls back to Position
//! mode 1 s after the last setpoint, ArduPilot stops after its GUIDED timeout, 3 s).
//!
//! Setpoints: velocity and position in the local NED frame (the origin of the vehicle's
//! LOCAL_POSITION_NED), velocity in the body frame, and attitude with thrust.

use core::time::Duration;
use std::sync::{Arc, Mutex};

use mavstack_dialects::common::{
    AttitudeTargetTypemask, MavFrame, MavMessage, PositionTargetTypemask, SetAttitudeTarget,
    SetPositionTargetLocalNed,
};
use tokio::sync::watch;

use super::{System, SystemError, lock};
use crate::modes::Flavour;

/// The slowest stream [`Offboard::start`] accepts (Hz): PX4 wants setpoints at 2 Hz or more,
/// and leaves OFFBOARD 1 s (COM_OF_LOSS_T) after the last.
pub const MIN_RATE_HZ: f32 = 2.0;

/// The fastest stream [`Offboard::start`] accepts (Hz).
pub const MAX_RATE_HZ: f32 = 100.0;

/// The fastest speed a setpoint may ask for (m/s).
pub const MAX_SPEED: f32 = 100.0;

/// Setpoints sent before the mode is switched (PX4 refuses OFFBOARD without them).
const BEFORE_MODE: u64 = 3;

/// One setpoint of an offboard stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Setpoint {
    /// Velocity north, east, down (m/s), facing `yaw_deg` (degrees from north) when given.
    VelocityNed {
        /// North (m/s).
        north: f32,
        /// East (m/s).
        east: f32,
        /// Down (m/s).
        down: f32,
        /// Heading to face (degrees), or keep the current one.
        yaw_deg: Option<f32>,
    },
    /// Position north, east, down of the local origin (m), facing `yaw_deg` when given.
    PositionNed {
        /// North (m).
        north: f32,
        /// East (m).
        east: f32,
        /// Down (m: negative is up).
        down: f32,
        /// Heading to face (degrees), or keep the current one.
        yaw_deg: Option<f32>,
    },
    /// Velocity forward, right, down in the body frame (m/s), turning at `yaw_rate_dps`.
    VelocityBody {
        /// Forward (m/s).
        forward: f32,
        /// Right (m/s).
        right: f32,
        /// Down (m/s).
        down: f32,
        /// Turn rate (degrees a second).
        yaw_rate_dps: f32,
    },
    /// Attitude (degrees) and thrust (0–1).
    Attitude {
        /// Roll (degrees, ±90).
        roll_deg: f32,
        /// Pitch (degrees, ±90).
        pitch_deg: f32,
        /// Yaw (degrees).
        yaw_deg: f32,
        /// Thrust, 0–1.
        thrust: f32,
    },
}

impl Setpoint {
    /// Zero velocity: stay where it is.
    pub const STILL: Self = Self::VelocityNed {
        north: 0.0,
        east: 0.0,
        down: 0.0,
        yaw_deg: None,
    };

    /// Checks every number: finite, speeds within [`MAX_SPEED`], angles and thrust in range.
    ///
    /// # Errors
    /// [`SystemError::Invalid`] naming the value.
    pub fn check(&self) -> Result<(), SystemError> {
        let finite = |name: &str, v: f32| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(SystemError::Invalid(format!(
                    "setpoint: {name} {v} is not a number"
                )))
            }
        };
        let speed = |name: &str, v: f32| {
            finite(name, v)?;
            if v.abs() > MAX_SPEED {
                return Err(SystemError::Invalid(format!(
                    "setpoint: {name} {v} m/s is beyond ±{MAX_SPEED} m/s"
                )));
            }
            Ok(())
        };
        match *self {
            Self::VelocityNed {
                north,
                east,
                down,
                yaw_deg,
            } => {
                speed("north", north)?;
                speed("east", east)?;
                speed("down", down)?;
                yaw_deg.map_or(Ok(()), |y| finite("yaw", y))
            }
            Self::PositionNed {
                north,
                east,
                down,
                yaw_deg,
            } => {
                finite("north", north)?;
                finite("east", east)?;
                finite("down", down)?;
                yaw_deg.map_or(Ok(()), |y| finite("yaw", y))
            }
            Self::VelocityBody {
                forward,
                right,
                down,
                yaw_rate_dps,
            } => {
                speed("forward", forward)?;
                speed("right", right)?;
                speed("down", down)?;
                finite("yaw rate", yaw_rate_dps)
            }
            Self::Attitude {
                roll_deg,
                pitch_deg,
                yaw_deg,
                thrust,
            } => {
                for (name, v) in [("roll", roll_deg), ("pitch", pitch_deg)] {
                    finite(name, v)?;
                    if v.abs() > 90.0 {
                        return Err(SystemError::Invalid(format!(
                            "setpoint: {name} {v}° is beyond ±90°"
                        )));
                    }
                }
                finite("yaw", yaw_deg)?;
                finite("thrust", thrust)?;
                if !(0.0..=1.0).contains(&thrust) {
                    return Err(SystemError::Invalid(format!(
                        "setpoint: thrust {thrust} is not within 0-1"
                    )));
                }
                Ok(())
            }
        }
    }

    /// The message that carries it to system `(sysid, compid)`.
    #[must_use]
    pub fn message(&self, target: (u8, u8), time_boot_ms: u32) -> MavMessage {
        use PositionTargetTypemask as M;
        let accel = M::AX_IGNORE | M::AY_IGNORE | M::AZ_IGNORE;
        let yaw_mask = |yaw: Option<f32>| match yaw {
            Some(_) => M::YAW_RATE_IGNORE,
            None => M::YAW_IGNORE | M::YAW_RATE_IGNORE,
        };
        let local = |frame, type_mask, xyz: [f32; 3], v: [f32; 3], yaw: f32, yaw_rate: f32| {
            MavMessage::SetPositionTargetLocalNed(SetPositionTargetLocalNed {
                time_boot_ms,
                target_system: target.0,
                target_component: target.1,
                coordinate_frame: frame,
                type_mask,
                x: xyz[0],
                y: xyz[1],
                z: xyz[2],
                vx: v[0],
                vy: v[1],
                vz: v[2],
                yaw,
                yaw_rate,
                ..SetPositionTargetLocalNed::default()
            })
        };
        match *self {
            Self::VelocityNed {
                north,
                east,
                down,
                yaw_deg,
            } => local(
                MavFrame::LOCAL_NED,
                M::X_IGNORE | M::Y_IGNORE | M::Z_IGNORE | accel | yaw_mask(yaw_deg),
                [0.0; 3],
                [north, east, down],
                yaw_deg.map_or(0.0, f32::to_radians),
                0.0,
            ),
            Self::PositionNed {
                north,
                east,
                down,
                yaw_deg,
            } => local(
                MavFrame::LOCAL_NED,
                M::VX_IGNORE | M::VY_IGNORE | M::VZ_IGNORE | accel | yaw_mask(yaw_deg),
                [north, east, down],
                [0.0; 3],
                yaw_deg.map_or(0.0, f32::to_radians),
                0.0,
            ),
            Self::VelocityBody {
                forward,
                right,
                down,
                yaw_rate_dps,
            } => local(
                MavFrame::BODY_NED,
                M::X_IGNORE | M::Y_IGNORE | M::Z_IGNORE | accel | M::YAW_IGNORE,
                [0.0; 3],
                [forward, right, down],
                0.0,
                yaw_rate_dps.to_radians(),
            ),
            Self::Attitude {
                roll_deg,
                pitch_deg,
                yaw_deg,
                thrust,
            } => MavMessage::SetAttitudeTarget(SetAttitudeTarget {
                time_boot_ms,
                target_system: target.0,
                target_component: target.1,
                type_mask: AttitudeTargetTypemask::BODY_ROLL_RATE_IGNORE
                    | AttitudeTargetTypemask::BODY_PITCH_RATE_IGNORE
                    | AttitudeTargetTypemask::BODY_YAW_RATE_IGNORE,
                q: quaternion(
                    roll_deg.to_radians(),
                    pitch_deg.to_radians(),
                    yaw_deg.to_radians(),
                ),
                thrust,
                ..SetAttitudeTarget::default()
            }),
        }
    }
}

/// The quaternion (w, x, y, z) of roll, pitch and yaw (radians, ZYX order).
#[must_use]
pub fn quaternion(roll: f32, pitch: f32, yaw: f32) -> [f32; 4] {
    let (sr, cr) = (roll / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    let (sy, cy) = (yaw / 2.0).sin_cos();
    [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]
}

/// Offboard control of a system (from [`System::offboard`]).
#[derive(Clone, Debug)]
pub struct Offboard {
    system: System,
}

/// A running setpoint stream (from [`Offboard::start`]): [`set`](Self::set) changes what
/// it sends; [`stop`](Self::stop), or dropping it, ends the stream and holds position.
#[derive(Debug)]
pub struct OffboardSession {
    system: System,
    latest: Arc<Mutex<Setpoint>>,
    stream: tokio::task::AbortHandle,
    sent: watch::Receiver<u64>,
    stopped: bool,
}

impl Offboard {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// The mode setpoints fly in: PX4's OFFBOARD, ArduPilot's GUIDED.
    fn mode(&self) -> &'static str {
        match self.system.flavour() {
            Some(Flavour::Px4) => "OFFBOARD",
            _ => "GUIDED",
        }
    }

    /// Starts streaming `first` at `rate_hz` (2–100) from a task of the library's, and once
    /// three setpoints went out switches the vehicle into the mode that follows them (PX4
    /// OFFBOARD, ArduPilot GUIDED), waiting until it reports that mode.
    ///
    /// # Errors
    /// [`SystemError::Invalid`] (a rate out of range, a bad setpoint, a vehicle not armed:
    /// nothing sent); those of [`Modes::set`](super::Modes::set) (the stream is stopped
    /// again, nothing held).
    pub async fn start(
        &self,
        rate_hz: f32,
        first: Setpoint,
    ) -> Result<OffboardSession, SystemError> {
        if !(rate_hz.is_finite() && (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate_hz)) {
            return Err(SystemError::Invalid(format!(
                "offboard: rate {rate_hz} Hz is not within {MIN_RATE_HZ}-{MAX_RATE_HZ} Hz \
                 (PX4 leaves OFFBOARD 1 s after the last setpoint)"
            )));
        }
        first.check()?;
        if !self.system.armed_soon().await {
            return Err(SystemError::Invalid(
                "offboard: the vehicle is not armed (arm it and take off first)".to_owned(),
            ));
        }
        let latest = Arc::new(Mutex::new(first));
        let (count, sent) = watch::channel(0u64);
        let stream = tokio::spawn(stream(
            self.system.clone(),
            Arc::clone(&latest),
            Duration::from_secs_f32(1.0 / rate_hz),
            count,
        ))
        .abort_handle();
        let mut session = OffboardSession {
            system: self.system.clone(),
            latest,
            stream,
            sent,
            stopped: false,
        };
        let flowing = session.sent.wait_for(|&n| n >= BEFORE_MODE).await.is_ok();
        let entered = if flowing {
            self.system.modes().set(self.mode()).await.map(drop)
        } else {
            Err(SystemError::Stopped)
        };
        if let Err(e) = entered {
            session.stream.abort();
            session.stopped = true;
            return Err(e);
        }
        Ok(session)
    }
}

/// Sends the latest setpoint every `period` until aborted, counting in `count`.
async fn stream(
    system: System,
    latest: Arc<Mutex<Setpoint>>,
    period: Duration,
    count: watch::Sender<u64>,
) {
    let mut tick = tokio::time::interval(period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let started = tokio::time::Instant::now();
    let target = system.target();
    loop {
        tick.tick().await;
        let setpoint = *lock(&latest);
        let ms = u32::try_from(started.elapsed().as_millis()).unwrap_or(u32::MAX);
        let message = setpoint.message((target.system, target.component), ms);
        if system.send(&message).await.is_err() {
            return;
        }
        count.send_modify(|n| *n += 1);
    }
}

impl OffboardSession {
    /// Sends `setpoint` from the next tick on.
    ///
    /// # Errors
    /// [`SystemError::Invalid`] (the stream keeps the setpoint before it).
    pub fn set(&self, setpoint: Setpoint) -> Result<(), SystemError> {
        setpoint.check()?;
        *lock(&self.latest) = setpoint;
        Ok(())
    }

    /// Velocity north, east, down (m/s), facing `yaw_deg` when given.
    ///
    /// # Errors
    /// As [`set`](Self::set).
    pub fn set_velocity_ned(
        &self,
        north: f32,
        east: f32,
        down: f32,
        yaw_deg: Option<f32>,
    ) -> Result<(), SystemError> {
        self.set(Setpoint::VelocityNed {
            north,
            east,
            down,
            yaw_deg,
        })
    }

    /// Position north, east, down of the local origin (m), facing `yaw_deg` when given.
    ///
    /// # Errors
    /// As [`set`](Self::set).
    pub fn set_position_ned(
        &self,
        north: f32,
        east: f32,
        down: f32,
        yaw_deg: Option<f32>,
    ) -> Result<(), SystemError> {
        self.set(Setpoint::PositionNed {
            north,
            east,
            down,
            yaw_deg,
        })
    }

    /// Velocity forward, right, down in the body frame (m/s), turning at `yaw_rate_dps`.
    ///
    /// # Errors
    /// As [`set`](Self::set).
    pub fn set_velocity_body(
        &self,
        forward: f32,
        right: f32,
        down: f32,
        yaw_rate_dps: f32,
    ) -> Result<(), SystemError> {
        self.set(Setpoint::VelocityBody {
            forward,
            right,
            down,
            yaw_rate_dps,
        })
    }

    /// Attitude (degrees) and thrust (0–1).
    ///
    /// # Errors
    /// As [`set`](Self::set).
    pub fn set_attitude(
        &self,
        roll_deg: f32,
        pitch_deg: f32,
        yaw_deg: f32,
        thrust: f32,
    ) -> Result<(), SystemError> {
        self.set(Setpoint::Attitude {
            roll_deg,
            pitch_deg,
            yaw_deg,
            thrust,
        })
    }

    /// How many setpoints went out so far.
    #[must_use]
    pub fn sent(&self) -> u64 {
        *self.sent.borrow()
    }

    /// Ends the stream and holds position (see [`Action::hold`](super::Action::hold)),
    /// waiting until the vehicle reports the hold mode.
    ///
    /// # Errors
    /// Those of [`Action::hold`](super::Action::hold).
    pub async fn stop(mut self) -> Result<(), SystemError> {
        self.stopped = true;
        // Zero velocity while the mode changes, then nothing.
        *lock(&self.latest) = Setpoint::STILL;
        let held = self.system.action().hold().await;
        self.stream.abort();
        held
    }
}

impl Drop for OffboardSession {
    fn drop(&mut self) {
        if self.stopped {
            return;
        }
        // Dropped without stop(): still hold, from a task of its own.
        *lock(&self.latest) = Setpoint::STILL;
        let (system, stream) = (self.system.clone(), self.stream.clone());
        if let Ok(rt) = tokio::runtime::Handle::try_current() {
            rt.spawn(async move {
                if let Err(e) = system.action().hold().await {
                    tracing::warn!("offboard stream dropped: holding position failed: {e}");
                }
                stream.abort();
            });
        } else {
            stream.abort();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn setpoints_that_cannot_be_flown_are_refused_by_name() {
        let nan = Setpoint::VelocityNed {
            north: f32::NAN,
            east: 0.0,
            down: 0.0,
            yaw_deg: None,
        };
        assert!(matches!(nan.check(), Err(SystemError::Invalid(m)) if m.contains("north")));
        let fast = Setpoint::VelocityBody {
            forward: 0.0,
            right: 101.0,
            down: 0.0,
            yaw_rate_dps: 0.0,
        };
        assert!(matches!(fast.check(), Err(SystemError::Invalid(m)) if m.contains("right")));
        let tilted = Setpoint::Attitude {
            roll_deg: 0.0,
            pitch_deg: 95.0,
            yaw_deg: 0.0,
            thrust: 0.5,
        };
        assert!(matches!(tilted.check(), Err(SystemError::Invalid(m)) if m.contains("pitch")));
        let thrust = Setpoint::Attitude {
            roll_deg: 0.0,
            pitch_deg: 0.0,
            yaw_deg: 0.0,
            thrust: 1.5,
        };
        assert!(matches!(thrust.check(), Err(SystemError::Invalid(m)) if m.contains("thrust")));
        assert!(Setpoint::STILL.check().is_ok());
    }

    #[test]
    fn each_setpoint_ignores_what_it_does_not_set() {
        use PositionTargetTypemask as M;
        let v = Setpoint::VelocityNed {
            north: 3.0,
            east: 0.0,
            down: 0.0,
            yaw_deg: None,
        };
        let MavMessage::SetPositionTargetLocalNed(m) = v.message((1, 1), 0) else {
            panic!("a local setpoint");
        };
        assert!(m.type_mask.contains(M::X_IGNORE | M::YAW_IGNORE));
        assert!(!m.type_mask.contains(M::VX_IGNORE));
        assert_eq!((m.vx, m.coordinate_frame), (3.0, MavFrame::LOCAL_NED));
        let p = Setpoint::PositionNed {
            north: 0.0,
            east: 10.0,
            down: -10.0,
            yaw_deg: Some(90.0),
        };
        let MavMessage::SetPositionTargetLocalNed(m) = p.message((1, 1), 0) else {
            panic!("a local setpoint");
        };
        assert!(m.type_mask.contains(M::VX_IGNORE) && !m.type_mask.contains(M::YAW_IGNORE));
        assert!((m.yaw - core::f32::consts::FRAC_PI_2).abs() < 1e-6);
    }

    #[test]
    fn quaternions_of_level_and_of_a_quarter_turn() {
        assert_eq!(quaternion(0.0, 0.0, 0.0), [1.0, 0.0, 0.0, 0.0]);
        let q = quaternion(0.0, 0.0, core::f32::consts::FRAC_PI_2);
        let half = core::f32::consts::FRAC_1_SQRT_2;
        assert!((q[0] - half).abs() < 1e-6 && (q[3] - half).abs() < 1e-6);
        assert!(q[1].abs() < 1e-6 && q[2].abs() < 1e-6);
    }
}
