//! [`Action`]: flying a vehicle the same way whatever its autopilot — take off to a height
//! above home and wait until it is reached, land, return home, hold, go to a point and wait
//! until there. ArduPilot is flown in GUIDED (NAV_TAKEOFF with a height above home,
//! SET_POSITION_TARGET_GLOBAL_INT), PX4 with its own commands (NAV_TAKEOFF with an altitude
//! above mean sea level, MAV_CMD_DO_REPOSITION).
//!
//! Every method checks what it is given and the vehicle's state first: a height or a point
//! that is not a number, or a takeoff while disarmed, is an error and nothing is sent.

use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_dialects::common::{
    CommandInt, GlobalPositionInt, MavCmd, MavFrame, MavMessage, PositionTargetTypemask,
    SetPositionTargetGlobalInt,
};
use mavstack_services::command::Command;

use super::{System, SystemError};
use crate::modes::Flavour;

/// How often GLOBAL_POSITION_INT is asked for while an action waits on the position.
const POSITION_HZ: f32 = 5.0;

/// Climb or travel slower than this (m/s) on average and a wait gives up.
const SLOWEST: f32 = 0.3;

/// The least time a wait for a height or a point is given.
const LEAST_WAIT: Duration = Duration::from_secs(30);

/// How close to a goto's point counts as there (m, horizontally and vertically).
pub const GOTO_RADIUS_M: f32 = 1.5;

/// The share of a takeoff's height that counts as reached.
pub const TAKEOFF_REACHED: f32 = 0.95;

/// The highest height above home a takeoff or goto accepts (m).
pub const MAX_HEIGHT_M: f32 = 10_000.0;

/// MAV_DO_REPOSITION_FLAGS_CHANGE_MODE: DO_REPOSITION switches PX4 to its Hold mode.
const REPOSITION_CHANGE_MODE: f32 = 1.0;

/// Flying a system (from [`System::action`]).
#[derive(Clone, Debug)]
pub struct Action {
    system: System,
}

/// Metres between two points given in degrees (equirectangular: exact enough for the few
/// kilometres a goto covers).
#[must_use]
pub fn distance_m(lat1: f64, lon1: f64, lat2: f64, lon2: f64) -> f64 {
    const EARTH_M: f64 = 6_371_000.0;
    let (p1, p2) = (lat1.to_radians(), lat2.to_radians());
    let x = (lon2 - lon1).to_radians() * f64::midpoint(p1, p2).cos();
    let y = p2 - p1;
    (x * x + y * y).sqrt() * EARTH_M
}

fn invalid(what: impl Into<String>) -> SystemError {
    SystemError::Invalid(what.into())
}

/// `height` as a height above home a vehicle can be sent to.
fn check_height(what: &str, height: f32) -> Result<(), SystemError> {
    if !height.is_finite() || !(-MAX_HEIGHT_M..=MAX_HEIGHT_M).contains(&height) {
        return Err(invalid(format!(
            "{what}: height {height} m is not a number within ±{MAX_HEIGHT_M} m"
        )));
    }
    Ok(())
}

/// A point a vehicle can be sent to.
pub(super) fn check_point(what: &str, lat: f64, lon: f64) -> Result<(), SystemError> {
    if !(lat.is_finite() && (-90.0..=90.0).contains(&lat)) {
        return Err(invalid(format!(
            "{what}: latitude {lat} is not within ±90°"
        )));
    }
    if !(lon.is_finite() && (-180.0..=180.0).contains(&lon)) {
        return Err(invalid(format!(
            "{what}: longitude {lon} is not within ±180°"
        )));
    }
    Ok(())
}

impl Action {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// Whether it is armed (its latest HEARTBEAT).
    #[must_use]
    pub fn armed(&self) -> bool {
        self.system.armed()
    }

    /// Whether it is in the air (see [`Telemetry::in_air`](super::Telemetry::in_air)).
    #[must_use]
    pub fn in_air(&self) -> bool {
        self.system.telemetry().in_air()
    }

    /// Arms it.
    ///
    /// # Errors
    /// [`SystemError::Command`] with the vehicle's reasons when it refuses.
    pub async fn arm(&self) -> Result<(), SystemError> {
        self.system.commands().arm().await.map(drop)
    }

    /// Disarms it (`force`: even in the air).
    ///
    /// # Errors
    /// As [`arm`](Self::arm).
    pub async fn disarm(&self, force: bool) -> Result<(), SystemError> {
        self.system.commands().disarm(force).await.map(drop)
    }

    /// Takes off to `height_m` above home and returns once it reports at least 95 % of it
    /// (GLOBAL_POSITION_INT's height above home): ArduPilot in GUIDED with NAV_TAKEOFF, PX4
    /// with NAV_TAKEOFF at home's altitude above mean sea level plus the height. `progress`
    /// hears the height reached (m) as it climbs.
    ///
    /// # Errors
    /// [`SystemError::Invalid`] (not armed, a height that is not a number or not above 0;
    /// nothing sent); [`SystemError::Command`] (refused, with its reasons);
    /// [`SystemError::NotDone`] (it did not get there, or disarmed on the way, with what it
    /// said).
    pub async fn takeoff(
        &self,
        height_m: f32,
        mut progress: impl FnMut(f32),
    ) -> Result<(), SystemError> {
        check_height("takeoff", height_m)?;
        if height_m <= 0.0 {
            return Err(invalid(format!(
                "takeoff: height {height_m} m is not above home"
            )));
        }
        if !self.system.armed_soon().await {
            return Err(invalid("takeoff: the vehicle is not armed (arm it first)"));
        }
        let said_before = self.system.said_count();
        self.stream_position().await;
        let commands = self.system.commands();
        if self.system.flavour() != Some(Flavour::Px4) {
            self.system.modes().set("GUIDED").await?;
        }
        let command = commands.build("takeoff", &[height_m]).await?;
        commands.send(command).await?;
        let goal = height_m * TAKEOFF_REACHED;
        let limit = LEAST_WAIT.max(Duration::from_secs_f32(height_m / SLOWEST));
        let reached = self
            .system
            .wait_state(limit, |s| {
                let Some(p) = s.position else { return false };
                let h = p.relative_alt as f32 / 1000.0;
                progress(h);
                h >= goal || s.armed() == Some(false)
            })
            .await;
        let height = self.height().unwrap_or(f32::NAN);
        if !reached || !self.armed() || height < goal {
            return Err(SystemError::NotDone {
                what: format!(
                    "takeoff to {height_m} m: at {height:.1} m{}",
                    if self.armed() { "" } else { ", disarmed" }
                ),
                statustext: self.system.said_since(said_before).await,
            });
        }
        Ok(())
    }

    /// Its height above home (m), from its latest GLOBAL_POSITION_INT.
    fn height(&self) -> Option<f32> {
        self.system
            .state()
            .position
            .map(|p| p.relative_alt as f32 / 1000.0)
    }

    /// Makes sure GLOBAL_POSITION_INT comes (ArduPilot streams nothing until asked).
    async fn stream_position(&self) {
        if !self
            .system
            .comes(GlobalPositionInt::ID, Duration::from_millis(600))
            .await
        {
            let _ = self
                .system
                .telemetry()
                .request_rate(GlobalPositionInt::ID, POSITION_HZ)
                .await;
        }
    }

    /// Lands where it is (the standard `land` mode: ArduPilot's LAND, PX4's AUTO.LAND).
    ///
    /// # Errors
    /// Those of [`Modes::set`](super::Modes::set).
    pub async fn land(&self) -> Result<(), SystemError> {
        self.system.modes().set("land").await.map(drop)
    }

    /// Waits until it has landed and disarmed (what LAND and RTL end with), telling
    /// `progress` its height above home (m) as it comes down.
    ///
    /// # Errors
    /// [`SystemError::NotDone`] when it is still armed after `limit`, with what it said.
    pub async fn wait_landed(
        &self,
        limit: Duration,
        mut progress: impl FnMut(f32),
    ) -> Result<(), SystemError> {
        let said_before = self.system.said_count();
        self.stream_position().await;
        let landed = self
            .system
            .wait_state(limit, |s| {
                if let Some(p) = s.position {
                    progress(p.relative_alt as f32 / 1000.0);
                }
                s.armed() == Some(false)
            })
            .await;
        if landed {
            return Ok(());
        }
        Err(SystemError::NotDone {
            what: format!(
                "not landed and disarmed within {} s (at {:.1} m)",
                limit.as_secs(),
                self.height().unwrap_or(f32::NAN)
            ),
            statustext: self.system.said_since(said_before).await,
        })
    }

    /// Returns home (the standard `safe_recovery` mode: ArduPilot's RTL, PX4's Return).
    ///
    /// # Errors
    /// Those of [`Modes::set`](super::Modes::set).
    pub async fn return_home(&self) -> Result<(), SystemError> {
        self.system.modes().set("safe_recovery").await.map(drop)
    }

    /// Holds position (ArduPilot Copter's and Plane's LOITER, Rover's HOLD, PX4's Hold).
    ///
    /// # Errors
    /// Those of [`Modes::set`](super::Modes::set).
    pub async fn hold(&self) -> Result<(), SystemError> {
        self.system.modes().set(self.hold_mode()?).await.map(drop)
    }

    /// The mode that holds position on this vehicle.
    pub(super) fn hold_mode(&self) -> Result<&'static str, SystemError> {
        match self.system.flavour() {
            Some(Flavour::Px4) => Ok("AUTO.LOITER"),
            Some(Flavour::ArduCopter | Flavour::ArduPlane) => Ok("LOITER"),
            Some(Flavour::ArduRover) => Ok("HOLD"),
            Some(Flavour::ArduSub) => Ok("POSHOLD"),
            Some(Flavour::ArduTracker) | None => Err(SystemError::UnknownMode {
                autopilot: self.system.flavour().map(|f| f.to_string()),
                name: "hold".to_owned(),
                known: Vec::new(),
            }),
        }
    }

    /// Goes to `lat_deg`, `lon_deg` at `height_m` above home (facing `yaw_deg` when given):
    /// ArduPilot in GUIDED with a position target, PX4 with MAV_CMD_DO_REPOSITION (at home's
    /// altitude above mean sea level plus the height). With `wait`, returns once it is within
    /// 1.5 m of the point; `progress` hears the distance left (m).
    ///
    /// # Errors
    /// [`SystemError::Invalid`] (a point or height that is not a number, not in the air;
    /// nothing sent); [`SystemError::Command`] (refused); [`SystemError::NotDone`] (it did
    /// not get there).
    pub async fn goto(
        &self,
        lat_deg: f64,
        lon_deg: f64,
        height_m: f32,
        yaw_deg: Option<f32>,
        wait: bool,
        mut progress: impl FnMut(f32),
    ) -> Result<(), SystemError> {
        check_point("goto", lat_deg, lon_deg)?;
        check_height("goto", height_m)?;
        if yaw_deg.is_some_and(|y| !y.is_finite()) {
            return Err(invalid("goto: yaw is not a number"));
        }
        if !self.system.armed_soon().await {
            return Err(invalid("goto: the vehicle is not armed"));
        }
        let said_before = self.system.said_count();
        self.stream_position().await;
        let lat_e7 = (lat_deg * 1e7).round() as i32;
        let lon_e7 = (lon_deg * 1e7).round() as i32;
        if self.system.flavour() == Some(Flavour::Px4) {
            let home = self
                .system
                .telemetry()
                .home_amsl(Duration::from_secs(3))
                .await
                .ok_or_else(|| invalid("goto: PX4's home altitude did not come"))?;
            let command = Command::Int(CommandInt {
                command: MavCmd::DO_REPOSITION,
                frame: MavFrame::GLOBAL,
                param1: -1.0,
                param2: REPOSITION_CHANGE_MODE,
                param4: yaw_deg.map_or(f32::NAN, f32::to_radians),
                x: lat_e7,
                y: lon_e7,
                z: home + height_m,
                ..CommandInt::default()
            });
            self.system.commands().send(command).await?;
        } else {
            self.system.modes().set("GUIDED").await?;
            let target = self.system.target();
            let mut mask = PositionTargetTypemask::VX_IGNORE
                | PositionTargetTypemask::VY_IGNORE
                | PositionTargetTypemask::VZ_IGNORE
                | PositionTargetTypemask::AX_IGNORE
                | PositionTargetTypemask::AY_IGNORE
                | PositionTargetTypemask::AZ_IGNORE
                | PositionTargetTypemask::YAW_RATE_IGNORE;
            if yaw_deg.is_none() {
                mask |= PositionTargetTypemask::YAW_IGNORE;
            }
            let setpoint = SetPositionTargetGlobalInt {
                target_system: target.system,
                target_component: target.component,
                coordinate_frame: MavFrame::GLOBAL_RELATIVE_ALT_INT,
                type_mask: mask,
                lat_int: lat_e7,
                lon_int: lon_e7,
                alt: height_m,
                yaw: yaw_deg.map_or(0.0, f32::to_radians),
                ..SetPositionTargetGlobalInt::default()
            };
            self.system
                .send(&MavMessage::SetPositionTargetGlobalInt(setpoint))
                .await?;
        }
        if !wait {
            return Ok(());
        }
        let start = self.system.telemetry().last_position();
        let far = start.map_or(100.0, |p| {
            distance_m(p.lat_deg, p.lon_deg, lat_deg, lon_deg) as f32
        });
        let limit = LEAST_WAIT.max(Duration::from_secs_f32(far / SLOWEST));
        let there = self
            .system
            .wait_state(limit, |s| {
                let Some(p) = s.position else { return false };
                let left = distance_m(
                    f64::from(p.lat) * 1e-7,
                    f64::from(p.lon) * 1e-7,
                    lat_deg,
                    lon_deg,
                ) as f32;
                let up = (p.relative_alt as f32 / 1000.0 - height_m).abs();
                progress(left);
                (left <= GOTO_RADIUS_M && up <= GOTO_RADIUS_M) || s.armed() == Some(false)
            })
            .await;
        if !there || !self.armed() {
            let left = self
                .system
                .telemetry()
                .last_position()
                .map_or(f64::NAN, |p| {
                    distance_m(p.lat_deg, p.lon_deg, lat_deg, lon_deg)
                });
            return Err(SystemError::NotDone {
                what: format!("goto: {left:.1} m from the point"),
                statustext: self.system.said_since(said_before).await,
            });
        }
        Ok(())
    }
}
