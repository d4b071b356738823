//! The gimbal protocol (v2), in both roles.
//!
//! A **gimbal manager** is the component ground stations talk to (usually the autopilot, or
//! a companion computer); it drives a **gimbal device**, which is either a MAVLink component
//! of its own or, with an id from 1 to 6, something the manager drives itself (servos, a
//! serial gimbal). Ground stations find managers with REQUEST_MESSAGE(GIMBAL_MANAGER_INFORMATION),
//! take control with MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, point with
//! MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW (confirmed) or GIMBAL_MANAGER_SET_PITCHYAW (a stream),
//! at a location with MAV_CMD_DO_SET_ROI_LOCATION (and MAV_CMD_DO_SET_ROI_NONE to stop),
//! and read where the gimbal looks from GIMBAL_DEVICE_ATTITUDE_STATUS.
//!
//! ```text
//!  ground station                        manager (1/1 or 1/154)            device (1..6, or 1/155)
//!  REQUEST_MESSAGE(280) ──────────────►  GIMBAL_MANAGER_INFORMATION
//!  DO_GIMBAL_MANAGER_CONFIGURE ───────►  GIMBAL_MANAGER_STATUS (who is in control, 5 Hz)
//!  DO_GIMBAL_MANAGER_PITCHYAW ────────►  setpoint ──────────────────────►  moves
//!  ◄──────────────────────────────────── GIMBAL_DEVICE_ATTITUDE_STATUS ◄─  where it looks
//! ```
//!
//! **Client**: [`GimbalDiscovery`] finds the managers of a system; [`GimbalInfo`] is one of
//! them, and builds the commands and messages for it ([`GimbalInfo::set_angles`] and the
//! rest), refusing what its limits do not allow before anything is sent.
//! [`Attitude::from_status`] reads GIMBAL_DEVICE_ATTITUDE_STATUS as degrees in the frame its
//! flags say. **Server**: [`GimbalManager`], a manager in front of a device that its owner
//! drives (a companion's servos, the simulator's model).

mod angles;
mod discovery;
mod manager;

#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub use angles::fuzz_gimbal_angles;
pub use angles::{
    Attitude, Euler, YawFrame, euler_from_quaternion, look_at, quaternion_from_euler, wrap_deg,
};
pub use discovery::{DiscoveryConfig, GimbalDiscovery};
pub use manager::{
    DeviceAttitude, GimbalManager, ManagerConfig, ManagerEvent, Setpoint, VehicleState,
};

use alloc::string::String;

use mavstack_dialects::common::{
    CommandInt, CommandLong, GimbalDeviceAttitudeStatus, GimbalManagerCapFlags, GimbalManagerFlags,
    GimbalManagerInformation, GimbalManagerSetPitchyaw, MavCmd, MavFrame,
};

use crate::Address;
use crate::command::Command;

/// Radians to degrees, for the protocol's limits.
const DEG_PER_RAD: f32 = 180.0 / core::f32::consts::PI;

/// The largest device id of a gimbal device without a component of its own.
pub const MAX_NON_MAVLINK_DEVICE: u8 = 6;

/// An angle's range, in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    /// The least.
    pub min: f32,
    /// The most.
    pub max: f32,
}

impl Range {
    /// The range `min..=max` in radians, in degrees; `None` when it says nothing (a NaN,
    /// an infinite bound or `min >= max`, which some managers send for "unknown").
    ///
    /// A bound beyond a full turn (2π) cannot be radians: PX4 1.16 sends its `MNT_RANGE_*`
    /// parameters, degrees, in these fields (pitch ±90 and yaw ±360 as "radians", i.e.
    /// ±5157° and ±20626°, which would let every angle through). Such a range is taken as
    /// degrees.
    #[must_use]
    pub fn from_radians(min: f32, max: f32) -> Option<Self> {
        /// A full turn and a little: beyond it a bound is in degrees.
        const TURN: f32 = core::f32::consts::TAU * 1.001;
        let scale = if min.abs() > TURN || max.abs() > TURN {
            1.0
        } else {
            DEG_PER_RAD
        };
        let (min, max) = (min * scale, max * scale);
        (min.is_finite() && max.is_finite() && min < max).then_some(Self { min, max })
    }

    /// Whether `v` is within it (a thousandth of a degree of slack for the conversions).
    #[must_use]
    pub fn contains(self, v: f32) -> bool {
        v >= self.min - 1e-3 && v <= self.max + 1e-3
    }
}

/// Why a gimbal request was not sent.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GimbalError {
    /// A value that must be a number is NaN or infinite.
    #[error("{what} is not a number")]
    NotANumber {
        /// Which value.
        what: &'static str,
    },
    /// An angle outside what the gimbal can do (its manager's limits, or the protocol's).
    #[error("{what} {value}° is outside the gimbal's limits ({min}° to {max}°)")]
    OutOfLimits {
        /// Which angle (pitch, yaw).
        what: &'static str,
        /// The angle asked for.
        value: f32,
        /// The least it takes.
        min: f32,
        /// The most it takes.
        max: f32,
    },
    /// A location that is not one.
    #[error("latitude {lat}, longitude {lon} is not a location")]
    BadLocation {
        /// The latitude given.
        lat: f64,
        /// The longitude given.
        lon: f64,
    },
}

/// Who takes or gives up control of a gimbal ([`GimbalInfo::configure`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Control {
    /// Us, in primary control.
    Primary,
    /// Us, in secondary control (the primary controller keeps it).
    Secondary,
    /// Nobody, as far as we are concerned: we give up whatever control we have.
    Release,
}

/// A gimbal manager of a system, as its GIMBAL_MANAGER_INFORMATION describes it.
#[derive(Clone, Debug, PartialEq)]
pub struct GimbalInfo {
    /// The manager's address (its system and component).
    pub manager: Address,
    /// The device it manages: a component id, or 1 to 6 for one without a component.
    pub device_id: u8,
    /// GIMBAL_MANAGER_CAP_FLAGS.
    pub cap_flags: GimbalManagerCapFlags,
    /// Roll limits, when given.
    pub roll: Option<Range>,
    /// Pitch limits, when given.
    pub pitch: Option<Range>,
    /// Yaw limits, when given.
    pub yaw: Option<Range>,
    /// The device's vendor (GIMBAL_DEVICE_INFORMATION), when it came.
    pub vendor: String,
    /// The device's model, when it came.
    pub model: String,
    /// The name its user gave the device, when it came.
    pub custom_name: String,
}

impl GimbalInfo {
    /// The manager `manager` described by `info`.
    #[must_use]
    pub fn from_information(manager: Address, info: &GimbalManagerInformation) -> Self {
        Self {
            manager,
            device_id: info.gimbal_device_id,
            cap_flags: info.cap_flags,
            roll: Range::from_radians(info.roll_min, info.roll_max),
            pitch: Range::from_radians(info.pitch_min, info.pitch_max),
            yaw: Range::from_radians(info.yaw_min, info.yaw_max),
            vendor: String::new(),
            model: String::new(),
            custom_name: String::new(),
        }
    }

    /// Whether a GIMBAL_DEVICE_ATTITUDE_STATUS from `from` is this gimbal's: a device with a
    /// component of its own sends it from that component with `gimbal_device_id` 0; one
    /// without is reported by its manager with its id (or 0, by older managers).
    #[must_use]
    pub fn owns_status(&self, from: Address, status: &GimbalDeviceAttitudeStatus) -> bool {
        if from.system != self.manager.system {
            return false;
        }
        if self.device_id > MAX_NON_MAVLINK_DEVICE {
            status.gimbal_device_id == 0 && from.component == self.device_id
        } else {
            from.component == self.manager.component
                && (status.gimbal_device_id == self.device_id || status.gimbal_device_id == 0)
        }
    }

    /// Checks a pitch and a yaw against its limits (or, where it gives none, the
    /// protocol's: pitch −90…90, yaw −180…180). `None` is "leave as it is".
    ///
    /// # Errors
    /// [`GimbalError::NotANumber`], [`GimbalError::OutOfLimits`].
    pub fn check_angles(&self, pitch: Option<f32>, yaw: Option<f32>) -> Result<(), GimbalError> {
        let check = |what, v: Option<f32>, limits: Option<Range>, default: Range| {
            let Some(v) = v else { return Ok(()) };
            if !v.is_finite() {
                return Err(GimbalError::NotANumber { what });
            }
            let r = limits.unwrap_or(default);
            if r.contains(v) {
                Ok(())
            } else {
                Err(GimbalError::OutOfLimits {
                    what,
                    value: v,
                    min: r.min,
                    max: r.max,
                })
            }
        };
        let pitch_range = Range {
            min: -90.0,
            max: 90.0,
        };
        let yaw_range = Range {
            min: -180.0,
            max: 180.0,
        };
        check("pitch", pitch, self.pitch, pitch_range)?;
        check("yaw", yaw, self.yaw, yaw_range)
    }

    /// MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW to point the gimbal at `pitch_deg` (positive up)
    /// and `yaw_deg` (positive right) in `frame`.
    ///
    /// # Errors
    /// As [`check_angles`](Self::check_angles): nothing is built for an angle it cannot take.
    pub fn set_angles(
        &self,
        pitch_deg: f32,
        yaw_deg: f32,
        frame: YawFrame,
    ) -> Result<Command, GimbalError> {
        self.check_angles(Some(pitch_deg), Some(yaw_deg))?;
        Ok(self.pitch_yaw_command([pitch_deg, yaw_deg, f32::NAN, f32::NAN], frame))
    }

    /// MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW to turn the gimbal at `pitch_dps` and `yaw_dps`
    /// degrees per second (the angles left to the rates).
    ///
    /// # Errors
    /// [`GimbalError::NotANumber`].
    pub fn set_rates(
        &self,
        pitch_dps: f32,
        yaw_dps: f32,
        frame: YawFrame,
    ) -> Result<Command, GimbalError> {
        finite("pitch rate", pitch_dps)?;
        finite("yaw rate", yaw_dps)?;
        Ok(self.pitch_yaw_command([f32::NAN, f32::NAN, pitch_dps, yaw_dps], frame))
    }

    fn pitch_yaw_command(&self, p: [f32; 4], frame: YawFrame) -> Command {
        Command::Long(CommandLong {
            command: MavCmd::DO_GIMBAL_MANAGER_PITCHYAW,
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: manager_flags(frame).0 as f32,
            param6: 0.0,
            param7: f32::from(self.device_id),
            ..CommandLong::default()
        })
    }

    /// GIMBAL_MANAGER_SET_PITCHYAW (unconfirmed, for streaming at a rate): angles and
    /// rates in degrees and degrees per second, `None` for "not set".
    ///
    /// # Errors
    /// As [`check_angles`](Self::check_angles); a rate that is NaN or infinite.
    pub fn pitch_yaw_message(
        &self,
        angles: (Option<f32>, Option<f32>),
        rates: (Option<f32>, Option<f32>),
        frame: YawFrame,
    ) -> Result<GimbalManagerSetPitchyaw, GimbalError> {
        self.check_angles(angles.0, angles.1)?;
        if let Some(r) = rates.0 {
            finite("pitch rate", r)?;
        }
        if let Some(r) = rates.1 {
            finite("yaw rate", r)?;
        }
        let rad = |v: Option<f32>| v.map_or(f32::NAN, |d| d / DEG_PER_RAD);
        Ok(GimbalManagerSetPitchyaw {
            target_system: self.manager.system,
            target_component: self.manager.component,
            flags: manager_flags(frame),
            gimbal_device_id: self.device_id,
            pitch: rad(angles.0),
            yaw: rad(angles.1),
            pitch_rate: rad(rates.0),
            yaw_rate: rad(rates.1),
        })
    }

    /// MAV_CMD_DO_SET_ROI_LOCATION (as COMMAND_INT, MAV_FRAME_GLOBAL) to keep the gimbal
    /// on a location: latitude and longitude in degrees, altitude in metres above mean sea
    /// level.
    ///
    /// # Errors
    /// [`GimbalError::BadLocation`], [`GimbalError::NotANumber`] for the altitude.
    pub fn point_at(&self, lat: f64, lon: f64, alt_amsl: f32) -> Result<Command, GimbalError> {
        if !(lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0 && lon.abs() <= 180.0) {
            return Err(GimbalError::BadLocation { lat, lon });
        }
        finite("altitude", alt_amsl)?;
        Ok(Command::Int(CommandInt {
            command: MavCmd::DO_SET_ROI_LOCATION,
            frame: MavFrame::GLOBAL,
            param1: f32::from(self.device_id),
            x: libm::round(lat * 1e7) as i32,
            y: libm::round(lon * 1e7) as i32,
            z: alt_amsl,
            ..CommandInt::default()
        }))
    }

    /// MAV_CMD_DO_SET_ROI_NONE: stop pointing at a location.
    #[must_use]
    pub fn clear_roi(&self) -> Command {
        Command::Long(CommandLong {
            command: MavCmd::DO_SET_ROI_NONE,
            param1: f32::from(self.device_id),
            ..CommandLong::default()
        })
    }

    /// MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE for `own` (our address) taking or giving up
    /// control: primary control sets us as primary and leaves the secondary as it is;
    /// secondary the other way round; release removes us from both ("−3: remove control if
    /// currently in control").
    #[must_use]
    pub fn configure(&self, own: Address, control: Control) -> Command {
        const UNCHANGED: f32 = -1.0;
        const REMOVE_IF_OURS: f32 = -3.0;
        let us = [f32::from(own.system), f32::from(own.component)];
        let (primary, secondary) = match control {
            Control::Primary => (us, [UNCHANGED; 2]),
            Control::Secondary => ([UNCHANGED; 2], us),
            Control::Release => ([REMOVE_IF_OURS; 2], [REMOVE_IF_OURS; 2]),
        };
        Command::Long(CommandLong {
            command: MavCmd::DO_GIMBAL_MANAGER_CONFIGURE,
            param1: primary[0],
            param2: primary[1],
            param3: secondary[0],
            param4: secondary[1],
            param7: f32::from(self.device_id),
            ..CommandLong::default()
        })
    }
}

/// The manager flags of a request in `frame`: roll and pitch locked to the horizon, yaw as
/// the frame says (both the explicit frame flag and, for older managers, YAW_LOCK).
#[must_use]
pub const fn manager_flags(frame: YawFrame) -> GimbalManagerFlags {
    let base = GimbalManagerFlags::ROLL_LOCK.0 | GimbalManagerFlags::PITCH_LOCK.0;
    GimbalManagerFlags(match frame {
        YawFrame::Earth => {
            base | GimbalManagerFlags::YAW_LOCK.0 | GimbalManagerFlags::YAW_IN_EARTH_FRAME.0
        }
        YawFrame::Vehicle => base | GimbalManagerFlags::YAW_IN_VEHICLE_FRAME.0,
    })
}

fn finite(what: &'static str, v: f32) -> Result<(), GimbalError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(GimbalError::NotANumber { what })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_beyond_a_turn_are_read_as_degrees_as_px4_sends_them() {
        // Radians: -π/2..π/6 is -90..30 degrees.
        let r = Range::from_radians(-core::f32::consts::FRAC_PI_2, core::f32::consts::FRAC_PI_6)
            .expect("a range");
        assert!(
            (r.min + 90.0).abs() < 1e-3 && (r.max - 30.0).abs() < 1e-3,
            "{r:?}"
        );
        // PX4 1.16: MNT_RANGE_PITCH 180 and MNT_RANGE_YAW 720 as -90..90 and -360..360.
        assert_eq!(
            Range::from_radians(-90.0, 90.0),
            Some(Range {
                min: -90.0,
                max: 90.0
            })
        );
        assert_eq!(
            Range::from_radians(-360.0, 360.0),
            Some(Range {
                min: -360.0,
                max: 360.0
            })
        );
        // A full turn each way in radians is still radians.
        let turn = Range::from_radians(-core::f32::consts::TAU, core::f32::consts::TAU);
        assert!(
            turn.is_some_and(|r| (r.max - 360.0).abs() < 1e-2),
            "{turn:?}"
        );
        assert_eq!(Range::from_radians(f32::NAN, 1.0), None);
        assert_eq!(Range::from_radians(1.0, 1.0), None);
    }

    fn info(pitch: (f32, f32), yaw: (f32, f32)) -> GimbalInfo {
        let rad = |d: f32| d / DEG_PER_RAD;
        GimbalInfo::from_information(
            Address::new(1, 1),
            &GimbalManagerInformation {
                gimbal_device_id: 1,
                pitch_min: rad(pitch.0),
                pitch_max: rad(pitch.1),
                yaw_min: rad(yaw.0),
                yaw_max: rad(yaw.1),
                ..Default::default()
            },
        )
    }

    #[test]
    fn angles_outside_the_limits_build_nothing() {
        let g = info((-90.0, 30.0), (-160.0, 160.0));
        assert!(g.set_angles(-45.0, 100.0, YawFrame::Vehicle).is_ok());
        assert!(matches!(
            g.set_angles(45.0, 0.0, YawFrame::Vehicle),
            Err(GimbalError::OutOfLimits { what: "pitch", value: 45.0, min, max })
                if (min + 90.0).abs() < 1e-3 && (max - 30.0).abs() < 1e-3
        ));
        assert!(matches!(
            g.set_angles(0.0, 170.0, YawFrame::Vehicle),
            Err(GimbalError::OutOfLimits { what: "yaw", .. })
        ));
        assert_eq!(
            g.set_angles(f32::NAN, 0.0, YawFrame::Vehicle),
            Err(GimbalError::NotANumber { what: "pitch" })
        );
    }

    #[test]
    fn limits_that_say_nothing_fall_back_to_the_protocols() {
        let g = info((0.0, 0.0), (f32::NAN, 1.0));
        assert_eq!(g.pitch, None);
        assert_eq!(g.yaw, None);
        assert!(g.set_angles(-90.0, 180.0, YawFrame::Earth).is_ok());
        assert!(g.set_angles(-91.0, 0.0, YawFrame::Earth).is_err());
    }

    #[test]
    fn commands_carry_the_device_and_the_frame() {
        let g = info((-90.0, 30.0), (-180.0, 180.0));
        let Command::Long(c) = g.set_angles(-30.0, 10.0, YawFrame::Earth).unwrap() else {
            panic!()
        };
        assert_eq!(c.command, MavCmd::DO_GIMBAL_MANAGER_PITCHYAW);
        assert_eq!((c.param1, c.param2, c.param7), (-30.0, 10.0, 1.0));
        assert!(c.param3.is_nan() && c.param4.is_nan());
        let flags = GimbalManagerFlags(c.param5 as u32);
        assert_eq!(YawFrame::of_manager(flags), YawFrame::Earth);
        let Command::Int(roi) = g.point_at(47.397742, 8.545594, 500.0).unwrap() else {
            panic!()
        };
        assert_eq!(
            (roi.x, roi.y, roi.z, roi.frame),
            (473977420, 85455940, 500.0, MavFrame::GLOBAL)
        );
        assert!(g.point_at(91.0, 0.0, 0.0).is_err());
        let Command::Long(c) = g.configure(Address::new(255, 190), Control::Primary) else {
            panic!()
        };
        assert_eq!(
            (c.param1, c.param2, c.param3, c.param4),
            (255.0, 190.0, -1.0, -1.0)
        );
        let Command::Long(c) = g.configure(Address::new(255, 190), Control::Release) else {
            panic!()
        };
        assert_eq!((c.param1, c.param3), (-3.0, -3.0));
    }

    #[test]
    fn whose_status() {
        let mut g = info((-90.0, 30.0), (-180.0, 180.0));
        let s = |id| GimbalDeviceAttitudeStatus {
            gimbal_device_id: id,
            ..Default::default()
        };
        assert!(g.owns_status(Address::new(1, 1), &s(1)));
        assert!(!g.owns_status(Address::new(1, 1), &s(2)));
        assert!(!g.owns_status(Address::new(2, 1), &s(1)));
        g.device_id = 154;
        assert!(g.owns_status(Address::new(1, 154), &s(0)));
        assert!(!g.owns_status(Address::new(1, 1), &s(0)));
    }
}
