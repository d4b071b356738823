//! A ground station's view of a simulated vehicle on a virtual clock: messages in, time
//! advanced in small steps, everything the vehicle sends kept in order.

#![allow(dead_code, reason = "each test file uses part of it")]

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_core::{Message as _, MessageSet as _};
use mavstack_dialects::common::{
    CommandAck, CommandInt, CommandLong, GlobalPositionInt, Heartbeat, LocalPositionNed,
    ManualControl, MavCmd, MavFrame, MavMessage, MavModeFlag, MavResult, Statustext,
};
use mavstack_services::statustext::Lines;
use mavstack_services::{Address, Outgoing};
use mavstack_sim::{Autopilot, SimConfig, Vehicle, params};

/// The ground station: MAV_COMP_ID_MISSIONPLANNER, to whom PX4 says why it refuses a mode.
pub(crate) const GCS: Address = Address {
    system: 255,
    component: 190,
};

/// The time steps of the driver.
const TICK: Duration = Duration::from_millis(10);

/// Metres per degree of latitude, as the simulator counts.
pub(crate) const M_PER_DEG: f64 = 111_319.49;

pub(crate) struct Sim {
    pub(crate) vehicle: Vehicle,
    pub(crate) now: Instant,
    /// Everything sent, with when.
    pub(crate) sent: Vec<(Instant, Outgoing)>,
    lines: Lines,
    asked: u32,
}

pub(crate) fn config(autopilot: Autopilot) -> SimConfig {
    SimConfig {
        own: Address {
            system: 1,
            component: 1,
        },
        autopilot,
        mavlink2: true,
        params: params::defaults(autopilot),
        estimator_settle: Duration::ZERO,
        data_streams_only: false,
        streams_on_request: false,
        ftp: false,
        ftp_files: None,
        log_dir: None,
    }
}

impl Sim {
    pub(crate) fn new(autopilot: Autopilot) -> Self {
        Self::with(config(autopilot))
    }

    pub(crate) fn with(config: SimConfig) -> Self {
        let now = Instant::from_secs(100);
        let mut sim = Self {
            vehicle: Vehicle::new(config, now),
            now,
            sent: Vec::new(),
            lines: Lines::default(),
            asked: 0,
        };
        sim.drain();
        sim
    }

    fn drain(&mut self) {
        while let Some(o) = self.vehicle.poll_transmit() {
            self.sent.push((self.now, o));
        }
    }

    /// A message from the ground station, at the current time.
    pub(crate) fn send(&mut self, message: MavMessage) {
        self.vehicle.handle_message(self.now, GCS, &message);
        self.drain();
    }

    /// Advances the clock by `d`.
    pub(crate) fn run(&mut self, d: Duration) {
        let end = self.now + d;
        while self.now < end {
            self.now += TICK;
            self.vehicle.handle_timeout(self.now);
            self.drain();
        }
    }

    /// Advances the clock by `d`, calling `each` before every step (a stream of setpoints).
    pub(crate) fn run_with(
        &mut self,
        d: Duration,
        every: Duration,
        mut each: impl FnMut(&mut Self),
    ) {
        let end = self.now + d;
        let mut next = self.now;
        while self.now < end {
            if self.now >= next {
                each(self);
                next += every;
            }
            self.now += TICK;
            self.vehicle.handle_timeout(self.now);
            self.drain();
        }
    }

    /// How many messages were sent so far (a mark for [`Self::since`]).
    pub(crate) fn mark(&self) -> usize {
        self.sent.len()
    }

    /// The messages sent since `mark`.
    pub(crate) fn since(&self, mark: usize) -> Vec<MavMessage> {
        self.sent[mark..]
            .iter()
            .map(|(_, o)| o.message.clone())
            .collect()
    }

    /// COMMAND_LONG `command` with `p`; the ACKs it got at once.
    pub(crate) fn command(&mut self, command: MavCmd, p: [f32; 7]) -> Vec<MavResult> {
        let mark = self.mark();
        self.send(MavMessage::CommandLong(CommandLong {
            target_system: 1,
            target_component: 1,
            command,
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            confirmation: 0,
        }));
        acks(&self.since(mark), command)
    }

    /// COMMAND_INT `command`; the ACKs it got at once.
    pub(crate) fn command_int(&mut self, c: CommandInt) -> Vec<MavResult> {
        let mark = self.mark();
        let command = c.command;
        self.send(MavMessage::CommandInt(CommandInt {
            target_system: 1,
            target_component: 1,
            ..c
        }));
        acks(&self.since(mark), command)
    }

    /// DO_SET_MODE to `custom_mode` in the flavour's encoding; the ACKs.
    pub(crate) fn set_mode(&mut self, autopilot: Autopilot, custom_mode: u32) -> Vec<MavResult> {
        let (p2, p3) = match autopilot {
            Autopilot::Ardupilot => (custom_mode as f32, 0.0),
            Autopilot::Px4 => (
                ((custom_mode >> 16) & 0xff) as f32,
                ((custom_mode >> 24) & 0xff) as f32,
            ),
        };
        self.command(MavCmd::DO_SET_MODE, [1.0, p2, p3, 0.0, 0.0, 0.0, 0.0])
    }

    /// Message `msg_id` as the vehicle is now (asked for with REQUEST_MESSAGE; the clock
    /// does not move).
    pub(crate) fn now_message(&mut self, msg_id: u32) -> MavMessage {
        let mark = self.mark();
        // Each request differs in an unused parameter: the same one again at the same time
        // would be taken for a copy made by the link.
        self.asked += 1;
        let acked = self.command(
            MavCmd::REQUEST_MESSAGE,
            [msg_id as f32, 0., 0., 0., 0., self.asked as f32, 0.],
        );
        assert_eq!(acked, [MavResult::ACCEPTED], "REQUEST_MESSAGE({msg_id})");
        self.since(mark)
            .into_iter()
            .find(|m| m.id() == msg_id)
            .expect("the message asked for")
    }

    pub(crate) fn heartbeat(&mut self) -> Heartbeat {
        match self.now_message(Heartbeat::ID) {
            MavMessage::Heartbeat(h) => h,
            _ => unreachable!("asked for HEARTBEAT"),
        }
    }

    pub(crate) fn mode(&mut self) -> u32 {
        self.heartbeat().custom_mode
    }

    pub(crate) fn armed(&mut self) -> bool {
        self.heartbeat()
            .base_mode
            .contains(MavModeFlag::SAFETY_ARMED)
    }

    /// LOCAL_POSITION_NED now: north, east, down.
    pub(crate) fn local(&mut self) -> [f32; 3] {
        match self.now_message(LocalPositionNed::ID) {
            MavMessage::LocalPositionNed(p) => [p.x, p.y, p.z],
            _ => unreachable!("asked for LOCAL_POSITION_NED"),
        }
    }

    /// GLOBAL_POSITION_INT now.
    pub(crate) fn global(&mut self) -> GlobalPositionInt {
        match self.now_message(GlobalPositionInt::ID) {
            MavMessage::GlobalPositionInt(p) => p,
            _ => unreachable!("asked for GLOBAL_POSITION_INT"),
        }
    }

    /// The STATUSTEXT lines (chunks put together) sent since `mark` with their severity,
    /// but the INFO ones (the simulator's own "Mode X", "Arming motors"...).
    pub(crate) fn texts(&mut self, mark: usize) -> Vec<(u8, String)> {
        let mut out = Vec::new();
        for m in self.since(mark) {
            if let MavMessage::Statustext(t) = m
                && let Some(line) = self.lines.push((1, 1), &t)
                && line.severity.0 < 6
            {
                out.push((line.severity.0, line.text));
            }
        }
        out
    }

    /// Arms, switches to a mode that takes off and climbs to `height` metres.
    pub(crate) fn take_off(&mut self, autopilot: Autopilot, height: f32) {
        assert_eq!(
            self.command(MavCmd::COMPONENT_ARM_DISARM, [1.0, 0., 0., 0., 0., 0., 0.]),
            [MavResult::ACCEPTED]
        );
        let z = match autopilot {
            Autopilot::Ardupilot => {
                let guided = self.set_mode(autopilot, 4);
                assert_eq!(guided, [MavResult::ACCEPTED]);
                height
            }
            Autopilot::Px4 => mavstack_sim::flight::HOME_AMSL + height,
        };
        let nan = f32::NAN;
        assert_eq!(
            self.command(MavCmd::NAV_TAKEOFF, [0., 0., 0., nan, nan, nan, z]),
            [MavResult::ACCEPTED]
        );
        self.run(Duration::from_secs(15));
        let [_, _, down] = self.local();
        assert!((down + height).abs() < 0.3, "at {} m", -down);
    }

    /// MANUAL_CONTROL with `x`, `y`, `r` in ±1000 and `z` in 0..1000.
    pub(crate) fn sticks(&mut self, x: i16, y: i16, z: i16, r: i16) {
        self.send(MavMessage::ManualControl(ManualControl {
            target: 1,
            x,
            y,
            z,
            r,
            ..ManualControl::default()
        }));
    }
}

/// The results of the COMMAND_ACKs of `command` among `messages`, in order.
pub(crate) fn acks(messages: &[MavMessage], command: MavCmd) -> Vec<MavResult> {
    messages
        .iter()
        .filter_map(|m| match m {
            MavMessage::CommandAck(CommandAck {
                command: c, result, ..
            }) if *c == command => Some(*result),
            _ => None,
        })
        .collect()
}

/// A COMMAND_INT with a point.
pub(crate) fn command_int(
    command: MavCmd,
    frame: MavFrame,
    p: [f32; 4],
    x: i32,
    y: i32,
    z: f32,
) -> CommandInt {
    CommandInt {
        command,
        frame,
        param1: p[0],
        param2: p[1],
        param3: p[2],
        param4: p[3],
        x,
        y,
        z,
        ..CommandInt::default()
    }
}

/// A STATUSTEXT's text.
pub(crate) fn text(t: &Statustext) -> String {
    mavstack_services::statustext::text_of(&t.text)
}
