//! Message intervals, one-shot requests and subscriptions: a ground station and a vehicle
//! through the simulated link.

mod util;

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    Attitude, AutopilotVersion, CommandLong, Heartbeat, MavCmd, MavMessage, MavResult,
    MessageInterval,
};
use mavstack_services::command::{
    CommandClient, CommandError, CommandEvent, CommandHandler, Request, Response,
};
use mavstack_services::stream::{
    Due, Interval, MessageSource, StreamServer, Subscriptions, request_message,
    set_message_interval,
};
use mavstack_services::{Address, Outgoing, Service};
use util::{Knobs, Pair};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);
const ATTITUDE: u32 = 30;
const AUTOPILOT_VERSION: u32 = 148;

/// What the vehicle streams, and a record of every message it built.
#[derive(Default)]
struct Telemetry {
    sent: Vec<u32>,
}

impl MessageSource for Telemetry {
    fn message(&mut self, now: Instant, due: &Due) -> Option<MavMessage> {
        self.sent.push(due.msg_id);
        Some(match due.msg_id {
            0 => MavMessage::Heartbeat(Heartbeat::default()),
            ATTITUDE => MavMessage::Attitude(Attitude {
                time_boot_ms: (now.as_micros() / 1000) as u32,
                ..Default::default()
            }),
            AUTOPILOT_VERSION => MavMessage::AutopilotVersion(AutopilotVersion {
                capabilities: mavstack_dialects::common::MavProtocolCapability(8192),
                ..Default::default()
            }),
            other => panic!("not supported: {other}"),
        })
    }
}

/// A vehicle: a stream server (scheduler, its commands, telemetry built when due).
type Vehicle = StreamServer<Telemetry>;

fn vehicle() -> Vehicle {
    let mut v = StreamServer::new(VEHICLE, Telemetry::default());
    v.support(0, Some(Duration::from_secs(1)));
    v.support(ATTITUDE, None);
    v.support(AUTOPILOT_VERSION, None);
    v
}

/// A ground station: a command client and subscriptions.
struct Gcs {
    commands: CommandClient,
    subs: Subscriptions,
}

impl Service for Gcs {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let a = self.commands.handle_message(now, from, message);
        self.subs.handle_message(now, from, message) || a
    }
    fn handle_timeout(&mut self, now: Instant) {
        self.commands.handle_timeout(now);
    }
    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.commands.poll_transmit()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        self.commands.poll_timeout()
    }
}

type Sim = Pair<Gcs, Vehicle>;

fn sim(knobs: Knobs, seed: u64) -> Sim {
    let gcs = Gcs {
        commands: CommandClient::new(GCS, Default::default()),
        subs: Subscriptions::new(),
    };
    Pair::new(gcs, GCS, vehicle(), VEHICLE, knobs, seed)
}

fn command(p: &mut Sim, cmd: mavstack_services::command::Command) -> Result<(), CommandError> {
    p.a.commands.send(p.now, VEHICLE, cmd).unwrap();
    let mut result = None;
    assert!(p.drive_until(Duration::from_secs(10), |g, _, _| {
        while let Some(e) = g.commands.poll_event() {
            if let CommandEvent::Finished { result: r, .. } = e {
                result = Some(r.map(|_| ()));
            }
        }
        result.is_some()
    }));
    result.unwrap()
}

fn count(p: &mut Sim, sub: mavstack_services::stream::SubscriptionId) -> usize {
    core::iter::from_fn(|| p.a.subs.poll_delivery())
        .filter(|d| d.subscription == sub)
        .count()
}

#[test]
fn sim_set_interval_request_message_and_query_on_a_clean_link() {
    let mut p = sim(Knobs::clean(), 1);
    let att = p.a.subs.subscribe(ATTITUDE, Some(VEHICLE));
    let hb = p.a.subs.subscribe(0, None);
    command(
        &mut p,
        set_message_interval(ATTITUDE, Interval::Every(Duration::from_millis(100))),
    )
    .unwrap();
    let _ = count(&mut p, att);
    p.drive_for(Duration::from_secs(5));
    let all: Vec<_> = core::iter::from_fn(|| p.a.subs.poll_delivery()).collect();
    let n = all.iter().filter(|d| d.subscription == att).count();
    assert!((49..=51).contains(&n), "{n}");
    let rate = p.a.subs.rate_hz(VEHICLE, ATTITUDE).unwrap();
    assert!((rate - 10.0).abs() < 0.1, "{rate}");
    let heartbeats = all.iter().filter(|d| d.subscription == hb).count();
    assert!((4..=6).contains(&heartbeats), "{heartbeats}");
    // The rate, queried with REQUEST_MESSAGE(MESSAGE_INTERVAL).
    let mi = p.a.subs.subscribe(244, None);
    command(
        &mut p,
        request_message(244, [ATTITUDE as f32, 0.0, 0.0, 0.0, 0.0]),
    )
    .unwrap();
    p.drive_for(Duration::from_millis(50));
    let got: Vec<_> = core::iter::from_fn(|| p.a.subs.poll_delivery())
        .filter(|d| d.subscription == mi)
        .collect();
    assert_eq!(got.len(), 1);
    assert_eq!(
        got[0].message,
        MavMessage::MessageInterval(MessageInterval {
            message_id: 30,
            interval_us: 100_000
        })
    );
    // The same by the older MAV_CMD_GET_MESSAGE_INTERVAL (510, what PX4 answers).
    command(
        &mut p,
        mavstack_services::command::Command::Long(CommandLong {
            command: MavCmd::GET_MESSAGE_INTERVAL,
            param1: ATTITUDE as f32,
            ..CommandLong::default()
        }),
    )
    .unwrap();
    p.drive_for(Duration::from_millis(50));
    let got: Vec<_> = core::iter::from_fn(|| p.a.subs.poll_delivery())
        .filter(|d| d.subscription == mi)
        .map(|d| d.message)
        .collect();
    assert_eq!(
        got,
        [MavMessage::MessageInterval(MessageInterval {
            message_id: 30,
            interval_us: 100_000
        })]
    );
    // A one-shot request: exactly one message.
    let av = p.a.subs.subscribe(AUTOPILOT_VERSION, None);
    command(&mut p, request_message(AUTOPILOT_VERSION, [0.0; 5])).unwrap();
    p.drive_for(Duration::from_secs(1));
    assert_eq!(count(&mut p, av), 1);
    // Stop the stream; unsupported messages are denied.
    command(&mut p, set_message_interval(ATTITUDE, Interval::Disabled)).unwrap();
    let _ = count(&mut p, att);
    p.drive_for(Duration::from_secs(2));
    assert_eq!(count(&mut p, att), 0);
    assert_eq!(p.b.scheduler().interval(ATTITUDE), None);
    assert!(matches!(
        command(
            &mut p,
            set_message_interval(33, Interval::Every(Duration::from_millis(100)))
        ),
        Err(CommandError::Rejected {
            result: MavResult::DENIED,
            ..
        })
    ));
    // Back to the default (off for ATTITUDE, 1 Hz for HEARTBEAT).
    command(&mut p, set_message_interval(0, Interval::Default)).unwrap();
    assert_eq!(p.b.scheduler().interval(0), Some(Duration::from_secs(1)));
}

#[test]
fn sim_rates_and_one_shots_under_loss() {
    for seed in [1, 2, 3] {
        let mut p = sim(Knobs::hostile(), seed);
        let att = p.a.subs.subscribe(ATTITUDE, None);
        command(
            &mut p,
            set_message_interval(ATTITUDE, Interval::Every(Duration::from_millis(50))),
        )
        .unwrap();
        assert_eq!(
            p.b.scheduler().interval(ATTITUDE),
            Some(Duration::from_millis(50))
        );
        let _ = count(&mut p, att);
        p.drive_for(Duration::from_secs(10));
        // 200 sent; 80 % arrive, 20 % of those twice: about 192.
        let n = count(&mut p, att);
        assert!((150..=230).contains(&n), "seed {seed}: {n}");
        // A one-shot request whose command is retried is still answered once.
        let before =
            p.b.source()
                .sent
                .iter()
                .filter(|&&m| m == AUTOPILOT_VERSION)
                .count();
        if command(&mut p, request_message(AUTOPILOT_VERSION, [0.0; 5])).is_ok() {
            p.drive_for(Duration::from_millis(200));
            let after =
                p.b.source()
                    .sent
                    .iter()
                    .filter(|&&m| m == AUTOPILOT_VERSION)
                    .count();
            assert_eq!(after - before, 1, "seed {seed}");
        }
    }
}

/// The vehicle's other commands: it arms, and knows nothing else.
#[derive(Default)]
struct Arming {
    armed: bool,
}

impl CommandHandler for Arming {
    fn handle_command(&mut self, _now: Instant, request: &Request) -> Response {
        if request.command.id() == MavCmd::COMPONENT_ARM_DISARM {
            self.armed = true;
            Response::done(MavResult::ACCEPTED)
        } else {
            Response::done(MavResult::UNSUPPORTED)
        }
    }
}

#[test]
fn a_stream_server_hands_its_other_commands_to_the_handler_and_answers_each_once() {
    use mavstack_dialects::common::{CommandLong, MavCmd};
    let mut v = StreamServer::with_commands(VEHICLE, Telemetry::default(), Arming::default());
    v.support(ATTITUDE, None);
    let from = GCS;
    let ask = |command: MavCmd, param1: f32| {
        MavMessage::CommandLong(CommandLong {
            target_system: 1,
            target_component: 1,
            command,
            param1,
            param7: 1.0,
            ..Default::default()
        })
    };
    let acks = |v: &mut StreamServer<Telemetry, Arming>| {
        core::iter::from_fn(|| v.poll_transmit())
            .map(|o| match o.message {
                MavMessage::CommandAck(a) => (a.command, a.result),
                other => panic!("not an ACK: {other:?}"),
            })
            .collect::<Vec<_>>()
    };
    assert!(v.handle_message(util::T0, from, &ask(MavCmd::COMPONENT_ARM_DISARM, 1.0)));
    assert_eq!(
        acks(&mut v),
        [(MavCmd::COMPONENT_ARM_DISARM, MavResult::ACCEPTED)]
    );
    assert!(v.commands_mut().armed);
    assert!(v.handle_message(util::T0, from, &ask(MavCmd::DO_SET_MODE, 1.0)));
    assert_eq!(
        acks(&mut v),
        [(MavCmd::DO_SET_MODE, MavResult::UNSUPPORTED)]
    );
    // A one-shot for a message the vehicle does not produce: DENIED, nothing built.
    assert!(v.handle_message(util::T0, from, &ask(MavCmd::REQUEST_MESSAGE, 148.0)));
    assert_eq!(acks(&mut v), [(MavCmd::REQUEST_MESSAGE, MavResult::DENIED)]);
    // One it does produce: the ACK, then the message, to the requester (param7 = 1).
    assert!(v.handle_message(
        util::T0,
        from,
        &ask(MavCmd::REQUEST_MESSAGE, ATTITUDE as f32)
    ));
    let out: Vec<_> = core::iter::from_fn(|| v.poll_transmit()).collect();
    assert!(matches!(out[0].message, MavMessage::CommandAck(a) if a.result == MavResult::ACCEPTED));
    assert!(matches!(out[1].message, MavMessage::Attitude(_)));
    assert_eq!((out.len(), out[1].target), (2, GCS));
    assert_eq!(v.source().sent, [ATTITUDE]);
    // Nothing streams: no timer.
    assert_eq!(v.poll_timeout(), None);
    // Messages that are not commands are not the server's.
    assert!(!v.handle_message(util::T0, from, &MavMessage::Heartbeat(Heartbeat::default())));
}
