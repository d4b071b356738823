//! The simulated vehicle's gimbal: a gimbal manager in the autopilot's own component for
//! device 1 (a gimbal without a component of its own, as ArduPilot's mount and PX4's gimbal
//! driver are), in front of a model that turns toward its setpoints at [`SLEW_DPS`] and
//! reports where it looks. It is quiet until a ground station first asks it something
//! (GIMBAL_MANAGER_INFORMATION, a command): then GIMBAL_MANAGER_STATUS (5 Hz) and
//! GIMBAL_DEVICE_ATTITUDE_STATUS (10 Hz) go out, as a flight stack streams them once a
//! gimbal is configured.

use core::time::Duration;
use std::collections::VecDeque;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{GimbalDeviceErrorFlags, MavMessage};
use mavstack_services::gimbal::{
    DeviceAttitude, Euler, GimbalManager, ManagerConfig, ManagerEvent, Setpoint, VehicleState,
    YawFrame, wrap_deg,
};
use mavstack_services::{Address, Outgoing, Service};

/// How fast the model turns, degrees per second.
pub(crate) const SLEW_DPS: f32 = 60.0;

/// The simulated gimbal.
#[derive(Debug)]
pub(crate) struct SimGimbal {
    manager: GimbalManager,
    /// A ground station has talked to it.
    active: bool,
    pitch_deg: f32,
    /// Yaw from the vehicle's nose.
    yaw_deg: f32,
    setpoint: Setpoint,
    log: VecDeque<String>,
}

impl SimGimbal {
    /// The gimbal of the autopilot at `own`, level and looking forward.
    pub(crate) fn new(now: Instant, own: Address) -> Self {
        let mut config = ManagerConfig::new(own, 1);
        config.vendor = "mavstack".into();
        config.model = "simulated gimbal".into();
        Self {
            manager: GimbalManager::new(now, config),
            active: false,
            pitch_deg: 0.0,
            yaw_deg: 0.0,
            setpoint: Setpoint::NEUTRAL,
            log: VecDeque::new(),
        }
    }

    /// Feeds one message; whether it was the gimbal's (a command it answered, a setpoint).
    pub(crate) fn handle_message(
        &mut self,
        now: Instant,
        from: Address,
        message: &MavMessage,
    ) -> bool {
        let used = self.manager.handle_message(now, from, message);
        if used && !self.active {
            self.active = true;
            self.log.push_back(format!(
                "gimbal: first request from {from}, reporting from now on"
            ));
        }
        self.take_events();
        used
    }

    fn take_events(&mut self) {
        while let Some(e) = self.manager.poll_event() {
            match e {
                ManagerEvent::Setpoint { setpoint, from } => {
                    if from != self.manager.config().own {
                        let show = |v: Option<f32>, unit: &str| {
                            v.map_or_else(|| "-".to_owned(), |v| format!("{v:.1}{unit}"))
                        };
                        self.log.push_back(format!(
                            "gimbal: pitch {} yaw {} ({}), rates {} {} from {from}",
                            show(setpoint.pitch_deg, "°"),
                            show(setpoint.yaw_deg, "°"),
                            setpoint.frame.name(),
                            show(setpoint.pitch_rate_dps, "°/s"),
                            show(setpoint.yaw_rate_dps, "°/s"),
                        ));
                    }
                    self.setpoint = setpoint;
                }
                ManagerEvent::Control { primary, secondary } => {
                    let show = |a: Option<Address>| {
                        a.map_or_else(|| "nobody".to_owned(), |a| a.to_string())
                    };
                    self.log.push_back(format!(
                        "gimbal: primary control {}, secondary {}",
                        show(primary),
                        show(secondary)
                    ));
                }
                ManagerEvent::Roi(Some((lat, lon, alt))) => self.log.push_back(format!(
                    "gimbal: pointing at {lat:.7}, {lon:.7}, {alt:.1} m"
                )),
                ManagerEvent::Roi(None) => self
                    .log
                    .push_back("gimbal: pointing at a location ended".to_owned()),
                _ => {}
            }
        }
    }

    /// Moves the model by `dt` toward its setpoint, the vehicle being where `vehicle` says.
    pub(crate) fn step(
        &mut self,
        now: Instant,
        dt: Duration,
        vehicle: VehicleState,
        home_amsl: f64,
    ) {
        self.manager.set_vehicle(vehicle, Some(home_amsl));
        self.take_events();
        let dt = dt.as_secs_f32();
        let max = SLEW_DPS * dt;
        let limits = self.manager.config().clone();
        let toward = |now: f32, target: f32, max: f32| now + (target - now).clamp(-max, max);
        let s = self.setpoint;
        if let Some(p) = s.pitch_deg {
            self.pitch_deg = toward(self.pitch_deg, p, max);
        } else if let Some(r) = s.pitch_rate_dps {
            self.pitch_deg += r.clamp(-SLEW_DPS, SLEW_DPS) * dt;
        }
        self.pitch_deg = self.pitch_deg.clamp(limits.pitch.min, limits.pitch.max);
        if let Some(y) = s.yaw_deg {
            let target = match s.frame {
                YawFrame::Vehicle => y,
                YawFrame::Earth => wrap_deg(f64::from(y - vehicle.heading_deg)) as f32,
            };
            // The short way round.
            let diff = wrap_deg(f64::from(target - self.yaw_deg)) as f32;
            self.yaw_deg = wrap_deg(f64::from(self.yaw_deg + diff.clamp(-max, max))) as f32;
        } else if let Some(r) = s.yaw_rate_dps {
            self.yaw_deg =
                wrap_deg(f64::from(self.yaw_deg + r.clamp(-SLEW_DPS, SLEW_DPS) * dt)) as f32;
        }
        let rates = if s.pitch_deg.is_none() && s.yaw_deg.is_none() {
            [
                0.0,
                s.pitch_rate_dps.unwrap_or(0.0),
                s.yaw_rate_dps.unwrap_or(0.0),
            ]
        } else {
            [f32::NAN; 3]
        };
        self.manager.set_device_attitude(DeviceAttitude {
            euler: Euler {
                roll_deg: 0.0,
                pitch_deg: self.pitch_deg,
                yaw_deg: self.yaw_deg,
            },
            frame: YawFrame::Vehicle,
            rates_dps: rates,
            failure_flags: GimbalDeviceErrorFlags(0),
        });
        if self.active {
            self.manager.handle_timeout(now);
        }
    }

    /// Where it looks: pitch and yaw from the vehicle's nose, degrees.
    pub(crate) const fn angles(&self) -> (f32, f32) {
        (self.pitch_deg, self.yaw_deg)
    }

    pub(crate) fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.manager.poll_transmit()
    }

    pub(crate) fn poll_log(&mut self) -> Option<String> {
        self.log.pop_front()
    }
}
