//! [`Control`]: what pilots and companion computers send the craft — GUIDED targets and
//! OFFBOARD setpoints (SET_POSITION_TARGET_LOCAL_NED, SET_POSITION_TARGET_GLOBAL_INT,
//! SET_ATTITUDE_TARGET) and sticks (MANUAL_CONTROL) — kept with the time they came, turned
//! into the craft's [`Demand`] at each step, and the failsafes of their loss, as each flight
//! stack has them:
//!
//! - ArduPilot takes targets in GUIDED only (others are ignored); a velocity or attitude
//!   target is followed for GUID_TIMEOUT (3 s), then the craft stops and holds
//!   (`ModeGuided::get_timeout_ms`, ArduCopter/mode_guided.cpp); a position target holds
//!   until replaced. MANUAL_CONTROL overrides the RC sticks for RC_OVERRIDE_TIME (3 s);
//!   then SITL's own RC (centred) holds.
//! - PX4 keeps the latest setpoint whatever its mode; OFFBOARD follows it, and 1 s
//!   (COM_OF_LOSS_T) after the last one falls back to Position mode with "Failsafe
//!   activated" (COM_OBL_RC_ACT 0), CURRENT_MODE's intended mode staying OFFBOARD; in that
//!   Position mode without any manual control the craft sinks and lands (as PX4 1.16 SITL
//!   did, about 0.6 m/s), then takes the intended mode back. Manual control lost for 0.5 s
//!   (COM_RC_LOSS_T) in a mode that needs it: Hold with "Failsafe activated: entering Hold
//!   for 5 seconds", then Return with "Failsafe activated" (COM_FAIL_ACT_T, NAV_RCL_ACT).

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    AttitudeTargetTypemask, ManualControl, MavFrame, MavMessage, MavSeverity,
    PositionTargetTypemask, SetAttitudeTarget, SetPositionTargetGlobalInt,
    SetPositionTargetLocalNed,
};
use mavstack_services::Address;

use crate::Autopilot;
use crate::flight::{Demand, Flight, HOME_AMSL, Position};
use crate::modes::{self, Behaviour, Entry, Mode};

/// ArduPilot's GUID_TIMEOUT default: a velocity or attitude target is followed this long.
pub(crate) const GUIDED_TIMEOUT: Duration = Duration::from_secs(3);

/// ArduPilot's RC_OVERRIDE_TIME default: MANUAL_CONTROL overrides the sticks this long.
const RC_OVERRIDE: Duration = Duration::from_secs(3);

/// PX4's COM_OF_LOSS_T default: OFFBOARD needs a setpoint this recent.
pub(crate) const OFFBOARD_LOSS: Duration = Duration::from_secs(1);

/// PX4's COM_RC_LOSS_T default: modes with manual control need MANUAL_CONTROL this recent.
pub(crate) const STICKS_LOSS: Duration = Duration::from_millis(500);

/// PX4's COM_FAIL_ACT_T default: the Hold before a failsafe's action.
const FAILSAFE_HOLD: Duration = Duration::from_secs(5);

/// A setpoint, in the local frame of the craft.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Setpoint {
    /// A velocity demand (NED).
    Velocity {
        ned: [f32; 3],
        yaw: Option<f32>,
        yaw_rate: f32,
    },
    /// A point.
    Position { at: Position, yaw: Option<f32> },
    /// An attitude and climb rate.
    Attitude {
        roll: f32,
        pitch: f32,
        yaw: f32,
        climb: f32,
    },
}

/// Sticks: forward, right and yaw in −1…1, throttle in 0…1.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sticks {
    x: f32,
    y: f32,
    z: f32,
    r: f32,
}

/// A PX4 failsafe in progress: the mode the user asked for, which the vehicle flies again
/// when it has landed (CURRENT_MODE's `intended_custom_mode` meanwhile).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Failsafe {
    /// No offboard setpoint: Position mode.
    OffboardLost { intended: Mode },
    /// No manual control: Hold, then Return at `act_at`.
    SticksLost {
        intended: Mode,
        act_at: Option<Instant>,
    },
}

/// The pilot's and companion computers' inputs, with the time each came; see the
/// [module docs](self).
#[derive(Debug)]
pub(crate) struct Control {
    autopilot: Autopilot,
    setpoint: Option<(Setpoint, Instant)>,
    sticks: Option<(Sticks, Instant)>,
    /// Whether MANUAL_CONTROL ever came (PX4's manual control loss needs it first).
    sticks_seen: bool,
    failsafe: Option<Failsafe>,
    /// Lines for STATUSTEXT.
    said: Vec<(MavSeverity, String)>,
}

/// The radians of a quaternion's roll, pitch and yaw (ZYX).
fn euler(q: [f32; 4]) -> (f32, f32, f32) {
    let [w, x, y, z] = q;
    let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
    let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
    let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    (roll, pitch, yaw)
}

/// `[forward, right]` turned into `[north, east]` for a craft heading `heading` (radians).
fn to_ned(forward: f32, right: f32, heading: f32) -> [f32; 2] {
    let (sin, cos) = heading.sin_cos();
    [forward * cos - right * sin, forward * sin + right * cos]
}

/// A stick's value beyond its dead zone `dz`, rescaled to −1…1.
fn beyond(v: f32, dz: f32) -> f32 {
    if v.abs() <= dz {
        0.0
    } else {
        (v - dz.copysign(v)) / (1.0 - dz)
    }
}

/// A MANUAL_CONTROL axis (±1000, INT16_MAX: not given) as −1…1.
fn axis(v: i16, unset: f32) -> f32 {
    if v == i16::MAX {
        unset
    } else {
        (f32::from(v) / 1000.0).clamp(-1.0, 1.0)
    }
}

impl Control {
    pub(crate) fn new(autopilot: Autopilot) -> Self {
        Self {
            autopilot,
            setpoint: None,
            sticks: None,
            sticks_seen: false,
            failsafe: None,
            said: Vec::new(),
        }
    }

    /// What to say in STATUSTEXT, oldest first.
    pub(crate) fn take_said(&mut self) -> Vec<(MavSeverity, String)> {
        core::mem::take(&mut self.said)
    }

    /// Whether an offboard setpoint came within PX4's COM_OF_LOSS_T.
    pub(crate) fn setpoints_fresh(&self, now: Instant) -> bool {
        self.setpoint
            .is_some_and(|(_, at)| now.saturating_duration_since(at) <= OFFBOARD_LOSS)
    }

    /// Whether MANUAL_CONTROL came within PX4's COM_RC_LOSS_T.
    pub(crate) fn sticks_fresh(&self, now: Instant) -> bool {
        self.sticks
            .is_some_and(|(_, at)| now.saturating_duration_since(at) <= STICKS_LOSS)
    }

    /// The mode the user asked for while a failsafe flies another (PX4).
    pub(crate) fn intended(&self) -> Option<Mode> {
        match self.failsafe? {
            Failsafe::OffboardLost { intended } | Failsafe::SticksLost { intended, .. } => {
                Some(intended)
            }
        }
    }

    /// A mode the user asked for ends any failsafe.
    pub(crate) fn user_mode_change(&mut self) {
        self.failsafe = None;
    }

    /// Takes a setpoint or sticks addressed to `own`; other messages are not ours.
    pub(crate) fn handle_message(
        &mut self,
        now: Instant,
        own: Address,
        flight: &mut Flight,
        message: &MavMessage,
    ) {
        let ours = |system: u8, component: u8| own.is_reached_by(Address::new(system, component));
        match message {
            MavMessage::SetPositionTargetLocalNed(m)
                if ours(m.target_system, m.target_component) =>
            {
                let setpoint = Self::local(flight, m);
                self.take(now, flight, setpoint);
            }
            MavMessage::SetPositionTargetGlobalInt(m)
                if ours(m.target_system, m.target_component) =>
            {
                let setpoint = Self::global(m);
                self.take(now, flight, setpoint);
            }
            MavMessage::SetAttitudeTarget(m) if ours(m.target_system, m.target_component) => {
                let setpoint = Self::attitude(flight, m);
                self.take(now, flight, setpoint);
            }
            MavMessage::ManualControl(m) if m.target == own.system => self.stick(now, m),
            _ => {}
        }
    }

    /// A setpoint that came (`None`: one that cannot be flown, which stops ArduPilot).
    fn take(&mut self, now: Instant, flight: &mut Flight, setpoint: Option<Setpoint>) {
        match self.autopilot {
            Autopilot::Ardupilot => {
                // GUIDED only; a bad target stops it where it is.
                if flight.mode().behaviour != Behaviour::Guided {
                    return;
                }
                self.setpoint = None;
                flight.set_demand(None);
                match setpoint {
                    Some(Setpoint::Position { at, .. }) => {
                        flight.go_to(Some(at.lat), Some(at.lon), Some(at.alt));
                    }
                    Some(s) => {
                        flight.clear_target();
                        self.setpoint = Some((s, now));
                    }
                    None => flight.clear_target(),
                }
            }
            Autopilot::Px4 => {
                if let Some(s) = setpoint {
                    self.setpoint = Some((s, now));
                }
            }
        }
    }

    fn stick(&mut self, now: Instant, m: &ManualControl) {
        let sticks = Sticks {
            x: axis(m.x, 0.0),
            y: axis(m.y, 0.0),
            z: if m.z == i16::MAX {
                0.5
            } else {
                (f32::from(m.z) / 1000.0).clamp(0.0, 1.0)
            },
            r: axis(m.r, 0.0),
        };
        self.sticks = Some((sticks, now));
        self.sticks_seen = true;
    }

    /// SET_POSITION_TARGET_LOCAL_NED as a setpoint: a position where X, Y and Z are all
    /// given, else a velocity where VX, VY and VZ are, in LOCAL_NED, LOCAL_OFFSET_NED,
    /// BODY_NED or BODY_OFFSET_NED (positions in the last three relative to the craft).
    fn local(flight: &Flight, m: &SetPositionTargetLocalNed) -> Option<Setpoint> {
        use PositionTargetTypemask as T;
        let mask = m.type_mask;
        let body = matches!(
            m.coordinate_frame,
            MavFrame::BODY_NED | MavFrame::BODY_OFFSET_NED
        );
        let offset = body || m.coordinate_frame == MavFrame::LOCAL_OFFSET_NED;
        if !(offset || m.coordinate_frame == MavFrame::LOCAL_NED) {
            return None;
        }
        let heading = flight.heading();
        let yaw = (!mask.contains(T::YAW_IGNORE) && m.yaw.is_finite()).then_some(m.yaw);
        let yaw_rate = if mask.contains(T::YAW_RATE_IGNORE) || !m.yaw_rate.is_finite() {
            0.0
        } else {
            m.yaw_rate
        };
        let given = |bits: [PositionTargetTypemask; 3], v: [f32; 3]| {
            !bits.iter().any(|&b| mask.contains(b)) && v.iter().all(|x| x.is_finite())
        };
        if given([T::X_IGNORE, T::Y_IGNORE, T::Z_IGNORE], [m.x, m.y, m.z]) {
            let [mut north, mut east] = if body {
                to_ned(m.x, m.y, heading)
            } else {
                [m.x, m.y]
            };
            let mut down = m.z;
            if offset {
                let [n, e, d] = flight.local_position();
                north += n;
                east += e;
                down += d;
            }
            return Some(Setpoint::Position {
                at: flight.local_point(north, east, -down),
                yaw,
            });
        }
        if given(
            [T::VX_IGNORE, T::VY_IGNORE, T::VZ_IGNORE],
            [m.vx, m.vy, m.vz],
        ) {
            let [north, east] = if body {
                to_ned(m.vx, m.vy, heading)
            } else {
                [m.vx, m.vy]
            };
            return Some(Setpoint::Velocity {
                ned: [north, east, m.vz],
                yaw,
                yaw_rate,
            });
        }
        None
    }

    /// SET_POSITION_TARGET_GLOBAL_INT as a setpoint: a point (altitude above mean sea level
    /// in GLOBAL and GLOBAL_INT, above home in the relative and terrain frames, the
    /// simulator having no terrain), else a velocity.
    fn global(m: &SetPositionTargetGlobalInt) -> Option<Setpoint> {
        use PositionTargetTypemask as T;
        let mask = m.type_mask;
        let yaw = (!mask.contains(T::YAW_IGNORE) && m.yaw.is_finite()).then_some(m.yaw);
        let position = ![T::X_IGNORE, T::Y_IGNORE, T::Z_IGNORE]
            .iter()
            .any(|&b| mask.contains(b));
        if position {
            let alt = match m.coordinate_frame {
                MavFrame::GLOBAL | MavFrame::GLOBAL_INT => m.alt - HOME_AMSL,
                MavFrame::GLOBAL_RELATIVE_ALT
                | MavFrame::GLOBAL_RELATIVE_ALT_INT
                | MavFrame::GLOBAL_TERRAIN_ALT
                | MavFrame::GLOBAL_TERRAIN_ALT_INT => m.alt,
                _ => return None,
            };
            let (lat, lon) = (f64::from(m.lat_int) / 1e7, f64::from(m.lon_int) / 1e7);
            if !(alt.is_finite() && lat.abs() <= 90.0 && lon.abs() <= 180.0) {
                return None;
            }
            return Some(Setpoint::Position {
                at: Position { lat, lon, alt },
                yaw,
            });
        }
        let velocity = ![T::VX_IGNORE, T::VY_IGNORE, T::VZ_IGNORE]
            .iter()
            .any(|&b| mask.contains(b));
        (velocity && [m.vx, m.vy, m.vz].iter().all(|v| v.is_finite())).then_some(
            Setpoint::Velocity {
                ned: [m.vx, m.vy, m.vz],
                yaw,
                yaw_rate: if mask.contains(T::YAW_RATE_IGNORE) {
                    0.0
                } else {
                    m.yaw_rate
                },
            },
        )
    }

    /// SET_ATTITUDE_TARGET as a setpoint: the quaternion's tilt and heading (level at the
    /// current heading when ignored), thrust as a climb rate as ArduPilot reads it by
    /// default (0.5 holds the height, 1 climbs at the full climb rate, 0 descends at the full
    /// descent rate; PX4's hover thrust is near 0.5 too).
    fn attitude(flight: &Flight, m: &SetAttitudeTarget) -> Option<Setpoint> {
        use AttitudeTargetTypemask as T;
        if m.type_mask.contains(T::THROTTLE_IGNORE) || !m.thrust.is_finite() {
            return None;
        }
        let (roll, pitch, yaw) = if m.type_mask.contains(T::ATTITUDE_IGNORE) {
            (0.0, 0.0, flight.heading())
        } else {
            let norm = m.q.iter().map(|v| v * v).sum::<f32>().sqrt();
            if norm.is_nan() || (norm - 1.0).abs() >= 1e-3 {
                return None;
            }
            euler(m.q)
        };
        let t = m.thrust.clamp(0.0, 1.0);
        let tuning = flight.tuning();
        let climb = if t >= 0.5 {
            (t - 0.5) * 2.0 * tuning.climb
        } else {
            -(0.5 - t) * 2.0 * tuning.descent
        };
        Some(Setpoint::Attitude {
            roll,
            pitch,
            yaw,
            climb,
        })
    }

    /// The velocity the sticks ask for: forward and right up to the flavour's pilot speed,
    /// throttle around the middle (its dead zone holds the height), yaw stick a turn rate.
    fn stick_demand(&self, s: Sticks, flight: &Flight) -> Demand {
        let tuning = flight.tuning();
        // ArduPilot: LOIT_SPEED 12.5 m/s, THR_DZ 10 %, PILOT_SPEED_UP/DN 2.5 m/s,
        // PILOT_Y_RATE 202.5°/s. PX4: MPC_VEL_MANUAL 10 m/s, MPC_HOLD_DZ 10 %,
        // MPC_Z_VEL_MAX_UP/DN, MPC_MAN_Y_MAX 150°/s.
        let (speed, up, down, yaw_rate) = match self.autopilot {
            Autopilot::Ardupilot => (12.5, 2.5, 2.5, 202.5f32.to_radians()),
            Autopilot::Px4 => (10.0, tuning.climb, tuning.descent, 150f32.to_radians()),
        };
        let dz = 0.1;
        let forward = beyond(s.x, dz) * speed;
        let right = beyond(s.y, dz) * speed;
        let [north, east] = to_ned(forward, right, flight.heading());
        let throttle = beyond((s.z - 0.5) * 2.0, dz);
        let down_speed = if throttle >= 0.0 {
            -throttle * up
        } else {
            -throttle * down
        };
        Demand::Velocity {
            ned: [north, east, down_speed],
            yaw: None,
            yaw_rate: beyond(s.r, dz) * yaw_rate,
        }
    }

    /// Whether PX4 lets the craft into `mode` now (`Commander`'s "can run"): always while
    /// disarmed; armed, as the mode's [`Entry`] says. LAND is always allowed.
    pub(crate) fn px4_can_enter(&self, now: Instant, flight: &Flight, mode: Mode) -> bool {
        if !flight.is_armed() || mode.behaviour == Behaviour::Land {
            return true;
        }
        match mode.entry {
            Entry::Free | Entry::Refused(_) => true,
            Entry::NeedsSticks => self.sticks_fresh(now),
            Entry::NeedsSetpoints => self.setpoints_fresh(now),
            Entry::NeedsMission => flight.mission_len() > 0,
            Entry::Disarmed => false,
        }
    }

    /// Sets the craft's demand for the step at `now`, and runs the failsafes.
    pub(crate) fn step(&mut self, now: Instant, flight: &mut Flight) {
        if !flight.is_armed() {
            // Landed in a failsafe: PX4 takes the mode the user asked for back.
            if let Some(intended) = self.intended() {
                flight.set_mode(intended);
            }
            self.failsafe = None;
            flight.set_demand(None);
            return;
        }
        let age = |at: Instant| now.saturating_duration_since(at);
        let demand = match (self.autopilot, flight.mode().behaviour) {
            (Autopilot::Ardupilot, Behaviour::Guided) => match self.setpoint {
                Some((s, at)) if age(at) <= GUIDED_TIMEOUT => Some(demand_of(s)),
                _ => {
                    self.setpoint = None;
                    None
                }
            },
            (Autopilot::Ardupilot, Behaviour::Manual) => match self.sticks {
                Some((s, at)) if age(at) <= RC_OVERRIDE => Some(self.stick_demand(s, flight)),
                _ => None,
            },
            (Autopilot::Px4, Behaviour::Guided) => match self.setpoint {
                Some((s, at)) if age(at) <= OFFBOARD_LOSS => Some(demand_of(s)),
                _ => {
                    self.offboard_lost(flight);
                    None
                }
            },
            (Autopilot::Px4, Behaviour::Manual) => self.px4_manual(now, flight),
            (Autopilot::Px4, _) => {
                self.failsafe_action(now, flight);
                None
            }
            (Autopilot::Ardupilot, _) => None,
        };
        flight.set_demand(demand);
    }

    /// PX4 in a mode with manual control: the sticks; without them, the failsafes.
    fn px4_manual(&mut self, now: Instant, flight: &mut Flight) -> Option<Demand> {
        if let Some((s, _)) = self.sticks.filter(|_| self.sticks_fresh(now)) {
            return Some(self.stick_demand(s, flight));
        }
        let needs_sticks = flight.mode().entry == Entry::NeedsSticks;
        if needs_sticks && self.sticks_seen {
            let intended = self.intended().unwrap_or(flight.mode());
            self.failsafe = Some(Failsafe::SticksLost {
                intended,
                act_at: Some(now + FAILSAFE_HOLD),
            });
            flight.set_mode(modes::with_behaviour(self.autopilot, Behaviour::Hold));
            self.say("Failsafe activated: entering Hold for 5 seconds\t");
            return None;
        }
        // Never any manual control (the Position mode of an offboard loss): it sinks.
        needs_sticks.then(|| Demand::Velocity {
            ned: [0.0, 0.0, flight.tuning().land],
            yaw: None,
            yaw_rate: 0.0,
        })
    }

    /// PX4: OFFBOARD without setpoints falls back to Position mode.
    fn offboard_lost(&mut self, flight: &mut Flight) {
        let intended = self.intended().unwrap_or(flight.mode());
        self.failsafe = Some(Failsafe::OffboardLost { intended });
        flight.set_mode(modes::with_behaviour(self.autopilot, Behaviour::Manual));
        self.say("Failsafe activated\t");
    }

    /// PX4: the action after the failsafe's Hold.
    fn failsafe_action(&mut self, now: Instant, flight: &mut Flight) {
        if let Some(Failsafe::SticksLost {
            intended,
            act_at: Some(at),
        }) = self.failsafe
            && now >= at
        {
            self.failsafe = Some(Failsafe::SticksLost {
                intended,
                act_at: None,
            });
            flight.set_mode(modes::with_behaviour(
                self.autopilot,
                Behaviour::ReturnToLaunch,
            ));
            self.say("Failsafe activated\t");
        }
    }

    /// A line at PX4's failsafe severity (CRITICAL).
    fn say(&mut self, text: &str) {
        self.said.push((MavSeverity::CRITICAL, text.to_owned()));
    }
}

fn demand_of(s: Setpoint) -> Demand {
    match s {
        Setpoint::Velocity { ned, yaw, yaw_rate } => Demand::Velocity { ned, yaw, yaw_rate },
        Setpoint::Position { at, yaw } => Demand::Position { at, yaw },
        Setpoint::Attitude {
            roll,
            pitch,
            yaw,
            climb,
        } => Demand::Attitude {
            roll,
            pitch,
            yaw,
            climb,
        },
    }
}
