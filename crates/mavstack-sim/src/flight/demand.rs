//! [`Demand`]: what a pilot's sticks or a companion computer's setpoints ask of the craft
//! at each step, and how the kinematic craft follows it.

use core::f32::consts::TAU;

use super::{Flight, Position};

/// Gravity, m/s², for attitude setpoints: a tilt of θ accelerates the craft by g·tan θ.
const G: f32 = 9.81;

/// How quickly a leaning craft's speed settles (1/s): with this drag a steady 10° tilt
/// gives about 5.8 m/s, close to what a multicopter reaches.
const DRAG: f32 = 0.3;

/// The fastest the craft flies on any demand, m/s.
const MAX_SPEED: f32 = 30.0;

/// The steepest tilt an attitude setpoint is taken at (ArduPilot's ANGLE_MAX, 30°).
const MAX_TILT: f32 = 0.524;

/// What a pilot or a companion computer asks for now; the vehicle sets it at each step from
/// what it last received ([`Flight::set_demand`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Demand {
    /// Fly at `ned` (north, east, down, m/s), facing `yaw` (radians from north) when given,
    /// else turning at `yaw_rate` (rad/s, clockwise).
    Velocity {
        /// North, east, down, m/s.
        ned: [f32; 3],
        /// Heading to face, radians from north.
        yaw: Option<f32>,
        /// Turn rate, rad/s.
        yaw_rate: f32,
    },
    /// Fly to `at` and hold there, facing `yaw` when given.
    Position {
        /// The point.
        at: Position,
        /// Heading to face, radians from north.
        yaw: Option<f32>,
    },
    /// Lean by `roll` and `pitch` (radians; nose down is negative pitch and flies forward),
    /// facing `yaw`, climbing at `climb` (m/s, down negative): the tilt accelerates the craft
    /// (g·tan θ, less drag), which is how a multicopter flies on attitude alone.
    Attitude {
        /// Roll, radians (right wing down positive).
        roll: f32,
        /// Pitch, radians (nose up positive).
        pitch: f32,
        /// Heading, radians from north.
        yaw: f32,
        /// Climb rate, m/s.
        climb: f32,
    },
}

impl Flight {
    /// Takes what the pilot or a companion asks for from now on (`None`: nothing, the mode
    /// does what it does by itself). The craft follows it in pilot modes (velocities only)
    /// and in guided ones.
    pub fn set_demand(&mut self, demand: Option<Demand>) {
        if !matches!(demand, Some(Demand::Attitude { .. })) {
            self.drift = [0.0; 2];
        }
        self.demand = demand;
    }

    /// One step of a demand.
    pub(super) fn follow(&mut self, demand: Demand, dt: f64) {
        match demand {
            Demand::Velocity { ned, yaw, yaw_rate } => {
                self.turn(yaw, yaw_rate, dt);
                self.fly_velocity(ned, dt);
            }
            Demand::Position { at, yaw } => {
                // Setpoints turn the craft only when they say so.
                self.turn(yaw, 0.0, dt);
                let keep = self.heading;
                self.fly_to(at, dt);
                self.heading = keep;
            }
            Demand::Attitude {
                roll,
                pitch,
                yaw,
                climb,
            } => {
                self.heading = yaw.rem_euclid(TAU);
                let dt32 = dt as f32;
                let forward = G * (-pitch.clamp(-MAX_TILT, MAX_TILT)).tan();
                let right = G * roll.clamp(-MAX_TILT, MAX_TILT).tan();
                let (sin, cos) = self.heading.sin_cos();
                let accel = [forward * cos - right * sin, forward * sin + right * cos];
                for (v, a) in self.drift.iter_mut().zip(accel) {
                    *v += (a - DRAG * *v) * dt32;
                }
                let [n, e] = self.drift;
                self.fly_velocity([n, e, -climb], dt);
            }
        }
    }

    fn turn(&mut self, yaw: Option<f32>, yaw_rate: f32, dt: f64) {
        let heading = match yaw {
            Some(y) if y.is_finite() => y,
            _ if yaw_rate.is_finite() => self.heading + yaw_rate * dt as f32,
            _ => self.heading,
        };
        self.heading = heading.rem_euclid(TAU);
    }

    /// One step at velocity `ned` (limited to [`MAX_SPEED`]); touching the ground while
    /// descending lands and disarms.
    fn fly_velocity(&mut self, ned: [f32; 3], dt: f64) {
        let clamp = |v: f32| {
            if v.is_finite() {
                v.clamp(-MAX_SPEED, MAX_SPEED)
            } else {
                0.0
            }
        };
        let [n, e, d] = ned.map(clamp);
        if !self.airborne && d >= 0.0 {
            self.hold();
            return;
        }
        let alt = self.position.alt;
        self.position = self.position.moved(f64::from(n) * dt, f64::from(e) * dt);
        self.position.alt = (f64::from(alt) - f64::from(d) * dt).max(0.0) as f32;
        self.velocity = [n, e, d];
        if self.position.alt > 0.05 {
            self.airborne = true;
        } else if d > 0.0 && self.airborne {
            self.touch_down();
        }
    }

    /// On the ground after a descent of its own: landed and disarmed, as a flight stack's
    /// land detector does.
    pub(super) fn touch_down(&mut self) {
        self.position.alt = 0.0;
        self.airborne = false;
        self.velocity = [0.0; 3];
        self.drift = [0.0; 2];
        self.say("Landed");
        let _ = self.arm(false, true);
        self.after_landing();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Autopilot;
    use crate::flight::Tuning;
    use crate::modes::{self, Behaviour};

    fn airborne(autopilot: Autopilot, behaviour: Behaviour) -> Flight {
        let mut f = Flight::new(autopilot, Tuning::default());
        f.arm(true, false).expect("arms");
        f.set_mode(modes::with_behaviour(autopilot, Behaviour::Guided));
        f.go_to(None, None, Some(10.0));
        for _ in 0..200 {
            f.step(0.05);
        }
        f.set_mode(modes::with_behaviour(autopilot, behaviour));
        f
    }

    #[test]
    fn a_velocity_demand_moves_the_craft_at_that_velocity() {
        let mut f = airborne(Autopilot::Px4, Behaviour::Guided);
        f.set_demand(Some(Demand::Velocity {
            ned: [3.0, 0.0, 0.0],
            yaw: None,
            yaw_rate: 0.0,
        }));
        for _ in 0..100 {
            f.step(0.05);
        }
        let [n, e, d] = f.local_position();
        assert!((n - 15.0).abs() < 0.1 && e.abs() < 0.1, "{n} {e}");
        assert!((d + 10.0).abs() < 0.1, "{d}");
    }

    #[test]
    fn leaning_forward_accelerates_and_thrust_climbs() {
        let mut f = airborne(Autopilot::Ardupilot, Behaviour::Guided);
        f.set_demand(Some(Demand::Attitude {
            roll: 0.0,
            pitch: -10f32.to_radians(),
            yaw: 0.0,
            climb: 1.0,
        }));
        for _ in 0..60 {
            f.step(0.05);
        }
        let [n, _, d] = f.local_position();
        let [vn, _, _] = f.velocity();
        assert!(n > 2.0 && vn > 1.0 && vn < 6.0, "{n} {vn}");
        assert!((d + 13.0).abs() < 0.1, "{d}");
    }

    #[test]
    fn descending_onto_the_ground_lands_and_disarms() {
        let mut f = airborne(Autopilot::Px4, Behaviour::Manual);
        f.set_demand(Some(Demand::Velocity {
            ned: [0.0, 0.0, 2.0],
            yaw: None,
            yaw_rate: 0.0,
        }));
        for _ in 0..200 {
            f.step(0.05);
        }
        assert!(!f.is_armed() && !f.is_airborne());
        assert_eq!(f.position().alt, 0.0);
    }
}
