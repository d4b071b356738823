//! A simple kinematic multicopter: position, altitude, heading and battery that change
//! believably with the mode, the commands and the mission.
//!
//! No dynamics: the craft moves toward its target at the configured horizontal speed,
//! climbs and descends at its vertical speeds, lands at its landing speed and disarms on
//! touchdown. The battery drains with a current that depends on what the craft is doing.
//! Everything advances in [`Flight::step`] by a time step the caller chooses.

use std::collections::VecDeque;

use mavstack_dialects::common::{MavCmd, MavFrame, MavLandedState, MissionItemInt};

use super::modes::{self, Behaviour, Mode};
use crate::Autopilot;

mod demand;

pub use demand::Demand;

/// Metres per degree of latitude (spherical Earth, as every GCS map does at this scale).
const METRES_PER_DEGREE: f64 = 111_319.49;

/// Where the craft starts, and returns to: ArduPilot SITL's default home (CMAC, Canberra).
pub const HOME: Position = Position {
    lat: -35.363_261,
    lon: 149.165_230,
    alt: 0.0,
};

/// The home altitude above mean sea level, metres.
pub const HOME_AMSL: f32 = 584.0;

/// A point: degrees and metres above home.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Position {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Altitude above home, metres.
    pub alt: f32,
}

impl Position {
    /// North and east offsets (metres) from `self` to `to`.
    fn offset_to(&self, to: &Self) -> (f64, f64) {
        let north = (to.lat - self.lat) * METRES_PER_DEGREE;
        let east = (to.lon - self.lon) * METRES_PER_DEGREE * self.lat.to_radians().cos();
        (north, east)
    }

    fn moved(&self, north: f64, east: f64) -> Self {
        let cos = self.lat.to_radians().cos().max(1e-6);
        Self {
            lat: self.lat + north / METRES_PER_DEGREE,
            lon: self.lon + east / (METRES_PER_DEGREE * cos),
            alt: self.alt,
        }
    }
}

/// Speeds, altitudes and the battery, from the parameter table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tuning {
    /// Horizontal cruise speed, m/s.
    pub cruise: f32,
    /// Climb rate, m/s.
    pub climb: f32,
    /// Descent rate above 10 m, m/s.
    pub descent: f32,
    /// Final landing speed, m/s.
    pub land: f32,
    /// Take-off altitude when a command gives none, m.
    pub takeoff_alt: f32,
    /// Return altitude, m.
    pub rtl_alt: f32,
    /// Battery capacity, mAh.
    pub capacity_mah: f32,
}

impl Default for Tuning {
    fn default() -> Self {
        Self {
            cruise: 5.0,
            climb: 2.5,
            descent: 1.5,
            land: 0.5,
            takeoff_alt: 10.0,
            rtl_alt: 15.0,
            capacity_mah: 5000.0,
        }
    }
}

/// Something the vehicle should tell its ground stations.
#[derive(Clone, Debug, PartialEq)]
pub enum FlightEvent {
    /// Mission item `seq` was reached (MISSION_ITEM_REACHED).
    ItemReached(u16),
    /// The current mission item is now `seq`.
    CurrentChanged(u16),
    /// A line for STATUSTEXT and the log.
    Text(String),
    /// A warning for STATUSTEXT (severity CRITICAL) and the log: why something was refused.
    Warning(String),
}

/// Why a command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// Not now (e.g. take-off while disarmed): MAV_RESULT_DENIED or FAILED.
    NotNow,
}

/// The craft.
#[derive(Debug)]
pub struct Flight {
    autopilot: Autopilot,
    mode: Mode,
    armed: bool,
    airborne: bool,
    position: Position,
    /// North, east, down velocity, m/s.
    velocity: [f32; 3],
    /// Radians, 0 = north.
    heading: f32,
    home: Position,
    tuning: Tuning,
    speed_override: Option<f32>,
    /// Where GUIDED (or PX4 TAKEOFF, or a PX4 reposition in Hold) is going.
    target: Option<Position>,
    /// What the pilot's sticks or a companion's setpoints ask for now (see [`Demand`]).
    demand: Option<Demand>,
    /// Horizontal velocity (north, east, m/s) built up under an [`Demand::Attitude`].
    drift: [f32; 2],
    rtl_climbed: bool,
    mission: Vec<MissionItemInt>,
    current: u16,
    /// When the current item's hold time ends (seconds of flight time).
    hold_until: Option<f64>,
    mission_done: bool,
    consumed_mah: f64,
    flight_time: f64,
    events: VecDeque<FlightEvent>,
}

impl Flight {
    /// A disarmed craft on the ground at home, in the flavour's first mode.
    pub fn new(autopilot: Autopilot, tuning: Tuning) -> Self {
        let mode = match autopilot {
            Autopilot::Ardupilot => modes::with_behaviour(autopilot, Behaviour::Manual),
            Autopilot::Px4 => modes::with_behaviour(autopilot, Behaviour::Hold),
        };
        Self {
            autopilot,
            mode,
            armed: false,
            airborne: false,
            position: HOME,
            velocity: [0.0; 3],
            heading: 0.0,
            home: HOME,
            tuning,
            speed_override: None,
            target: None,
            demand: None,
            drift: [0.0; 2],
            rtl_climbed: false,
            mission: Vec::new(),
            current: 0,
            hold_until: None,
            mission_done: false,
            consumed_mah: 0.0,
            flight_time: 0.0,
            events: VecDeque::new(),
        }
    }

    /// Takes new speeds, altitudes and battery size.
    pub fn set_tuning(&mut self, tuning: Tuning) {
        self.tuning = tuning;
    }

    /// Its speeds, altitudes and battery size.
    pub fn tuning(&self) -> Tuning {
        self.tuning
    }

    /// The flight mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Whether the motors are armed.
    pub fn is_armed(&self) -> bool {
        self.armed
    }

    /// Whether the craft is off the ground.
    pub fn is_airborne(&self) -> bool {
        self.airborne
    }

    /// Where the craft is.
    pub fn position(&self) -> Position {
        self.position
    }

    /// Where it started, and returns to.
    pub fn home(&self) -> Position {
        self.home
    }

    /// The origin of the local frame (LOCAL_POSITION_NED, offboard positions): where the
    /// craft started, as a flight stack's estimator origin stays where it was set at boot
    /// whatever becomes of home.
    pub fn origin(&self) -> Position {
        HOME
    }

    /// Where the craft is in the local frame: north, east, down of [`origin`](Self::origin),
    /// metres.
    pub fn local_position(&self) -> [f32; 3] {
        let (north, east) = self.origin().offset_to(&self.position);
        [north as f32, east as f32, -self.position.alt]
    }

    /// The point `north`, `east` metres from the origin, `up` metres above home.
    pub fn local_point(&self, north: f32, east: f32, up: f32) -> Position {
        Position {
            alt: up,
            ..self.origin().moved(f64::from(north), f64::from(east))
        }
    }

    /// Velocity north, east, down, m/s.
    pub fn velocity(&self) -> [f32; 3] {
        self.velocity
    }

    /// Heading, radians from north (0 to 2π).
    pub fn heading(&self) -> f32 {
        self.heading
    }

    /// Battery: fraction left (0–1), voltage (4 cells), current (A), consumed (mAh).
    pub fn battery(&self) -> (f32, f32, f32, f32) {
        let left = (1.0 - self.consumed_mah / f64::from(self.tuning.capacity_mah.max(1.0)))
            .clamp(0.0, 1.0) as f32;
        (
            left,
            14.0 + 2.8 * left,
            self.current_draw(),
            self.consumed_mah as f32,
        )
    }

    /// On the ground, taking off, in the air or landing.
    pub fn landed_state(&self) -> MavLandedState {
        if !self.airborne {
            MavLandedState::ON_GROUND
        } else if self.velocity[2] > 0.2 && self.is_landing() {
            MavLandedState::LANDING
        } else if self.velocity[2] < -0.2 && self.position.alt < 5.0 {
            MavLandedState::TAKEOFF
        } else {
            MavLandedState::IN_AIR
        }
    }

    fn is_landing(&self) -> bool {
        matches!(
            self.mode.behaviour,
            Behaviour::Land | Behaviour::ReturnToLaunch
        ) || (self.mode.behaviour == Behaviour::Mission
            && self
                .mission
                .get(usize::from(self.current))
                .is_some_and(|i| i.command == MavCmd::NAV_LAND))
    }

    /// The mission the craft flies in mission mode (replaces the old one).
    pub fn set_mission(&mut self, items: &[MissionItemInt]) {
        self.mission = items.to_vec();
        self.current = self.first_item();
        self.mission_done = false;
        self.hold_until = None;
    }

    /// Items in the mission it flies.
    pub fn mission_len(&self) -> usize {
        self.mission.len()
    }

    /// ArduPilot's item 0 is home, never flown.
    fn first_item(&self) -> u16 {
        match self.autopilot {
            Autopilot::Ardupilot if !self.mission.is_empty() => 1,
            _ => 0,
        }
    }

    /// The mission item it flies to.
    pub fn current_item(&self) -> u16 {
        self.current
    }

    /// Whether the mission has been flown to its end.
    pub fn mission_done(&self) -> bool {
        self.mission_done
    }

    /// Makes item `seq` current (MISSION_SET_CURRENT, DO_SET_MISSION_CURRENT).
    pub fn set_current(&mut self, seq: u16) {
        self.current = seq;
        self.mission_done = false;
        self.hold_until = None;
    }

    /// The next event (an item reached, the current item changed, a message to say).
    pub fn poll_event(&mut self) -> Option<FlightEvent> {
        self.events.pop_front()
    }

    fn say(&mut self, text: impl Into<String>) {
        self.events.push_back(FlightEvent::Text(text.into()));
    }

    /// Says why something was refused (STATUSTEXT, severity CRITICAL).
    pub fn warn(&mut self, text: impl Into<String>) {
        self.events.push_back(FlightEvent::Warning(text.into()));
    }

    /// Changes the mode.
    pub fn set_mode(&mut self, mode: Mode) {
        if mode == self.mode {
            return;
        }
        self.mode = mode;
        self.rtl_climbed = false;
        self.hold_until = None;
        self.demand = None;
        self.drift = [0.0; 2];
        match mode.behaviour {
            Behaviour::Takeoff => {
                self.target = Some(Position {
                    alt: self.tuning.takeoff_alt,
                    ..self.position
                });
            }
            Behaviour::Guided | Behaviour::Hold | Behaviour::Manual => {
                self.target = None;
            }
            Behaviour::Mission
                if self.mission_done || usize::from(self.current) >= self.mission.len() =>
            {
                self.current = self.first_item();
                self.mission_done = false;
            }
            _ => {}
        }
        self.say(format!("Mode {}", mode.name));
    }

    /// Arms or disarms. Disarming in the air needs `force`.
    pub fn arm(&mut self, arm: bool, force: bool) -> Result<(), Refusal> {
        if arm == self.armed {
            return Ok(());
        }
        if !arm && self.airborne && !force {
            return Err(Refusal::NotNow);
        }
        self.armed = arm;
        if arm {
            self.say("Arming motors");
            if self.mode.behaviour == Behaviour::Mission {
                self.current = self.first_item();
                self.mission_done = false;
            }
        } else {
            self.say("Disarming motors");
            self.airborne = false;
            self.position.alt = self.position.alt.max(0.0);
            self.velocity = [0.0; 3];
        }
        Ok(())
    }

    /// MAV_CMD_NAV_TAKEOFF to `alt` metres above home (`None`: the configured height).
    pub fn takeoff(&mut self, alt: Option<f32>) -> Result<(), Refusal> {
        if !self.armed {
            return Err(Refusal::NotNow);
        }
        let alt = alt
            .filter(|a| a.is_finite() && *a > 0.0)
            .unwrap_or(self.tuning.takeoff_alt);
        match self.autopilot {
            Autopilot::Ardupilot => {
                if self.mode.behaviour != Behaviour::Guided {
                    return Err(Refusal::NotNow);
                }
            }
            Autopilot::Px4 => {
                self.set_mode(modes::with_behaviour(self.autopilot, Behaviour::Takeoff));
            }
        }
        self.target = Some(Position {
            alt,
            ..self.position
        });
        self.say(format!("Takeoff to {alt:.1} m"));
        Ok(())
    }

    /// Sets the guided target (DO_REPOSITION, guided waypoints); `None` parts keep ours.
    /// ArduPilot flies it in GUIDED, PX4 in Hold: the craft switches unless it is in that
    /// mode already.
    pub fn go_to(&mut self, lat: Option<f64>, lon: Option<f64>, alt: Option<f32>) {
        let flies_in = match self.autopilot {
            Autopilot::Ardupilot => Behaviour::Guided,
            Autopilot::Px4 => Behaviour::Hold,
        };
        if self.mode.behaviour != flies_in {
            self.set_mode(modes::with_behaviour(self.autopilot, flies_in));
        }
        let here = self.position;
        self.target = Some(Position {
            lat: lat.unwrap_or(here.lat),
            lon: lon.unwrap_or(here.lon),
            alt: alt.unwrap_or(here.alt),
        });
    }

    /// Forgets the guided target: the craft holds where it is (a velocity target replaces a
    /// position one, as in ArduPilot's GUIDED).
    pub fn clear_target(&mut self) {
        self.target = None;
    }

    /// Sets the ground speed, m/s (DO_CHANGE_SPEED).
    pub fn set_speed(&mut self, speed: f32) {
        if speed.is_finite() && speed > 0.0 {
            self.speed_override = Some(speed);
        }
    }

    /// Moves home to `at` (altitude above the old home).
    pub fn set_home(&mut self, at: Position) {
        self.home = at;
    }

    /// Advances the craft by `dt` seconds.
    pub fn step(&mut self, dt: f64) {
        self.flight_time += dt;
        self.consumed_mah += f64::from(self.current_draw()) * dt / 3.6;
        if !self.armed {
            self.velocity = [0.0; 3];
            return;
        }
        match self.mode.behaviour {
            Behaviour::Manual => match self.demand {
                Some(d @ Demand::Velocity { .. }) => self.follow(d, dt),
                _ => self.hold(),
            },
            Behaviour::Guided if self.demand.is_some() => {
                if let Some(d) = self.demand {
                    self.follow(d, dt);
                }
            }
            Behaviour::Hold | Behaviour::Guided => match self.target {
                Some(t) if self.airborne || t.alt > 0.0 => {
                    self.fly_to(t, dt);
                }
                _ => self.hold(),
            },
            Behaviour::Takeoff => {
                let t = self.target.unwrap_or(Position {
                    alt: self.tuning.takeoff_alt,
                    ..self.position
                });
                if self.fly_to(t, dt) {
                    let hold = modes::with_behaviour(self.autopilot, Behaviour::Hold);
                    self.set_mode(hold);
                }
            }
            Behaviour::Land => self.descend(dt),
            Behaviour::ReturnToLaunch => self.return_home(dt),
            Behaviour::Mission => self.run_mission(dt),
        }
    }

    fn current_draw(&self) -> f32 {
        if !self.armed {
            0.4
        } else if !self.airborne {
            2.0
        } else {
            let [n, e, d] = self.velocity;
            14.0 + 0.8 * (n * n + e * e).sqrt() + 2.0 * (-d).max(0.0)
        }
    }

    fn hold(&mut self) {
        self.velocity = [0.0; 3];
    }

    fn cruise(&self) -> f32 {
        self.speed_override.unwrap_or(self.tuning.cruise).max(0.1)
    }

    /// One step toward `to`; whether it is reached.
    fn fly_to(&mut self, to: Position, dt: f64) -> bool {
        let (north, east) = self.position.offset_to(&to);
        let distance = north.hypot(east);
        let dz = f64::from(to.alt - self.position.alt);
        let step = (f64::from(self.cruise()) * dt).min(distance);
        let (dn, de) = if distance > 1e-6 {
            (north / distance * step, east / distance * step)
        } else {
            (0.0, 0.0)
        };
        let up = (f64::from(self.tuning.climb) * dt).min(dz.max(0.0));
        let down = (f64::from(self.tuning.descent) * dt).min((-dz).max(0.0));
        let climb = up - down;
        let alt = self.position.alt;
        self.position = self.position.moved(dn, de);
        self.position.alt = (f64::from(alt) + climb) as f32;
        if self.position.alt > 0.05 {
            self.airborne = true;
        }
        self.velocity = [(dn / dt) as f32, (de / dt) as f32, (-climb / dt) as f32];
        if step > 0.2 {
            self.heading = east.atan2(north) as f32;
        }
        distance - step < 0.5 && (dz - climb).abs() < 0.2
    }

    /// One step of a descent; lands and disarms on touchdown.
    fn descend(&mut self, dt: f64) {
        if !self.airborne {
            self.hold();
            return;
        }
        let rate = if self.position.alt > 10.0 {
            self.tuning.descent
        } else {
            self.tuning.land
        };
        let drop = f64::from(rate) * dt;
        self.position.alt = (f64::from(self.position.alt) - drop).max(0.0) as f32;
        self.velocity = [0.0, 0.0, rate];
        if self.position.alt <= 0.0 {
            self.airborne = false;
            self.velocity = [0.0; 3];
            self.say("Landed");
            let _ = self.arm(false, true);
            self.after_landing();
        }
    }

    /// PX4 leaves its landing mode (Land, Return) for Hold once it has landed and disarmed
    /// (MAVSDK saw HOLD after `land` on PX4 1.16 SITL; tests-interop/fixtures); ArduPilot
    /// stays in it.
    fn after_landing(&mut self) {
        let landing = matches!(
            self.mode().behaviour,
            Behaviour::Land | Behaviour::ReturnToLaunch
        );
        if self.autopilot == Autopilot::Px4 && landing {
            self.set_mode(modes::with_behaviour(Autopilot::Px4, Behaviour::Hold));
        }
    }

    fn return_home(&mut self, dt: f64) {
        if !self.airborne {
            self.hold();
            return;
        }
        let alt = self.position.alt.max(self.tuning.rtl_alt);
        if !self.rtl_climbed {
            let above = Position {
                alt,
                ..self.position
            };
            self.rtl_climbed = self.fly_to(above, dt);
            return;
        }
        let (north, east) = self.position.offset_to(&self.home);
        if north.hypot(east) > 0.5 {
            let over_home = Position {
                alt: self.position.alt,
                ..self.home
            };
            self.fly_to(over_home, dt);
        } else {
            self.descend(dt);
        }
    }

    /// Where an item's coordinates point (its own where given, else here).
    fn item_position(&self, item: &MissionItemInt) -> Position {
        let here = self.position;
        let global = mavstack_services::mission::is_global(item.frame);
        let (lat, lon) = if global && (item.x != 0 || item.y != 0) {
            (f64::from(item.x) / 1e7, f64::from(item.y) / 1e7)
        } else {
            (here.lat, here.lon)
        };
        let alt = match item.frame {
            MavFrame::GLOBAL | MavFrame::GLOBAL_INT => item.z - HOME_AMSL,
            _ if item.z.is_finite() => item.z,
            _ => here.alt,
        };
        Position { lat, lon, alt }
    }

    fn advance(&mut self) {
        let next = self.current.saturating_add(1);
        if usize::from(next) >= self.mission.len() {
            self.mission_done = true;
            self.say("Mission complete");
            if self.autopilot == Autopilot::Px4 {
                let hold = modes::with_behaviour(self.autopilot, Behaviour::Hold);
                self.set_mode(hold);
            }
            return;
        }
        self.current = next;
        self.hold_until = None;
        self.events.push_back(FlightEvent::CurrentChanged(next));
    }

    fn reached(&mut self) {
        self.events
            .push_back(FlightEvent::ItemReached(self.current));
        self.advance();
    }

    fn run_mission(&mut self, dt: f64) {
        if self.mission_done {
            self.hold();
            return;
        }
        let Some(item) = self.mission.get(usize::from(self.current)).copied() else {
            self.hold();
            return;
        };
        let at = self.item_position(&item);
        match item.command {
            MavCmd::NAV_TAKEOFF => {
                let up = Position {
                    alt: at.alt.max(1.0),
                    ..self.position
                };
                if self.fly_to(up, dt) {
                    self.reached();
                }
            }
            MavCmd::NAV_WAYPOINT
            | MavCmd::NAV_LOITER_TIME
            | MavCmd::NAV_LOITER_TURNS
            | MavCmd::NAV_LOITER_UNLIM
            | MavCmd::NAV_SPLINE_WAYPOINT => {
                if self.hold_until.is_none() {
                    if !self.fly_to(at, dt) {
                        return;
                    }
                    if item.command == MavCmd::NAV_LOITER_UNLIM {
                        self.hold_until = Some(f64::INFINITY);
                    } else {
                        let hold = match item.command {
                            MavCmd::NAV_LOITER_TIME | MavCmd::NAV_WAYPOINT => item.param1,
                            _ => 0.0,
                        };
                        self.hold_until = Some(self.flight_time + f64::from(hold_time(hold)));
                    }
                }
                self.hold();
                if self.hold_until.is_some_and(|t| self.flight_time >= t) {
                    self.reached();
                }
            }
            MavCmd::NAV_LAND => {
                let (north, east) = self.position.offset_to(&at);
                if self.airborne && north.hypot(east) > 0.5 {
                    let above = Position {
                        alt: self.position.alt,
                        ..at
                    };
                    self.fly_to(above, dt);
                } else {
                    self.descend(dt);
                    if !self.airborne {
                        self.events
                            .push_back(FlightEvent::ItemReached(self.current));
                        self.mission_done = true;
                        self.say("Mission complete");
                    }
                }
            }
            MavCmd::NAV_RETURN_TO_LAUNCH => {
                self.reached();
                let rtl = modes::with_behaviour(self.autopilot, Behaviour::ReturnToLaunch);
                self.set_mode(rtl);
            }
            MavCmd::DO_CHANGE_SPEED => {
                self.set_speed(item.param2);
                self.advance();
            }
            _ => self.advance(),
        }
    }
}

/// A hold time from an item's param1: seconds, at most an hour; NaN or negative is none.
fn hold_time(param1: f32) -> f32 {
    if param1.is_finite() {
        param1.clamp(0.0, 3600.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(f: &mut Flight, seconds: f64) {
        for _ in 0..(seconds * 20.0) as usize {
            f.step(0.05);
        }
    }

    #[test]
    fn takes_off_flies_a_mission_and_lands() {
        let mut f = Flight::new(Autopilot::Px4, Tuning::default());
        let wp = |seq: u16, command: MavCmd, north: f64, alt: f32| MissionItemInt {
            seq,
            command,
            frame: MavFrame::GLOBAL_RELATIVE_ALT_INT,
            x: ((HOME.lat + north / METRES_PER_DEGREE) * 1e7) as i32,
            y: (HOME.lon * 1e7) as i32,
            z: alt,
            ..MissionItemInt::default()
        };
        f.set_mission(&[
            wp(0, MavCmd::NAV_TAKEOFF, 0.0, 10.0),
            wp(1, MavCmd::NAV_WAYPOINT, 50.0, 20.0),
            wp(2, MavCmd::NAV_LAND, 50.0, 0.0),
        ]);
        f.arm(true, false).expect("arms");
        f.set_mode(modes::with_behaviour(Autopilot::Px4, Behaviour::Mission));
        run(&mut f, 5.0);
        assert!(f.is_airborne());
        assert!(f.position().alt > 9.0, "{:?}", f.position());
        run(&mut f, 60.0);
        assert!(!f.is_armed(), "disarmed after landing");
        assert!(f.mission_done());
        let (north, _) = HOME.offset_to(&f.position());
        assert!(
            (north - 50.0).abs() < 1.0,
            "landed at the last item: {north}"
        );
        let reached: Vec<u16> = core::iter::from_fn(|| f.poll_event())
            .filter_map(|e| match e {
                FlightEvent::ItemReached(s) => Some(s),
                _ => None,
            })
            .collect();
        assert_eq!(reached, [0, 1, 2]);
        let (left, volts, _, used) = f.battery();
        assert!(left < 1.0 && used > 0.0 && volts < 16.8);
    }

    #[test]
    fn ardupilot_takes_off_in_guided_only_and_refuses_disarm_in_the_air() {
        let mut f = Flight::new(Autopilot::Ardupilot, Tuning::default());
        f.arm(true, false).expect("arms");
        assert_eq!(f.takeoff(Some(10.0)), Err(Refusal::NotNow));
        f.set_mode(modes::with_behaviour(
            Autopilot::Ardupilot,
            Behaviour::Guided,
        ));
        f.takeoff(Some(10.0)).expect("takes off");
        run(&mut f, 6.0);
        assert!((f.position().alt - 10.0).abs() < 0.3, "{:?}", f.position());
        assert_eq!(f.arm(false, false), Err(Refusal::NotNow));
        f.set_mode(modes::with_behaviour(
            Autopilot::Ardupilot,
            Behaviour::ReturnToLaunch,
        ));
        run(&mut f, 60.0);
        assert!(!f.is_armed());
        assert_eq!(f.position().alt, 0.0);
    }
}
