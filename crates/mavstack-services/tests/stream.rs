//! Message intervals, one-shot requests and subscriptions: a ground station and a vehicle
//! through the simulated link.

mod util;

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    Attitude, AutopilotVersion, Heartbeat, MavMessage, MavResult, MessageInterval,
};
use mavstack_services::command::{
    CommandClient, CommandError, CommandEvent, CommandHandler, CommandServer, Request, Response,
};
use mavstack_services::stream::{
    Interval, StreamScheduler, Subscriptions, request_message, set_message_interval,
};
use mavstack_services::{Address, Outgoing, Service};
use util::{Knobs, Pair};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);
const ATTITUDE: u32 = 30;
const AUTOPILOT_VERSION: u32 = 148;

struct Streams(StreamScheduler);

impl CommandHandler for Streams {
    fn handle_command(&mut self, now: Instant, request: &Request) -> Response {
        self.0
            .handle_command(now, request)
            .unwrap_or(Response::done(MavResult::UNSUPPORTED))
    }
}

/// A vehicle: a command server whose handler is the stream scheduler, and telemetry built
/// when due.
struct Vehicle {
    commands: CommandServer<Streams>,
    now: Instant,
    sent: Vec<u32>,
}

impl Vehicle {
    fn new() -> Self {
        let mut s = StreamScheduler::new();
        s.support(0, Some(Duration::from_secs(1)));
        s.support(ATTITUDE, None);
        s.support(AUTOPILOT_VERSION, None);
        Self {
            commands: CommandServer::new(VEHICLE, Default::default(), Streams(s)),
            now: util::T0,
            sent: vec![],
        }
    }

    fn streams(&mut self) -> &mut StreamScheduler {
        &mut self.commands.handler_mut().0
    }
}

impl Service for Vehicle {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        self.now = now;
        self.commands.handle_message(now, from, message)
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.now = now;
        self.commands.handle_timeout(now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        if let Some(o) = self.commands.poll_transmit() {
            return Some(o);
        }
        if let Some(o) = self.streams().poll_transmit() {
            return Some(o);
        }
        let now = self.now;
        let due = self.streams().poll_due(now)?;
        self.sent.push(due.msg_id);
        let message = match due.msg_id {
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
        };
        Some(Outgoing {
            target: due.target,
            message,
        })
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let s = self
            .commands
            .handler()
            .0
            .poll_timeout()
            .map(|t| t.max(self.now));
        [self.commands.poll_timeout(), s]
            .into_iter()
            .flatten()
            .min()
    }
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
    Pair::new(gcs, GCS, Vehicle::new(), VEHICLE, knobs, seed)
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
    assert_eq!(p.b.commands.handler().0.interval(ATTITUDE), None);
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
    assert_eq!(
        p.b.commands.handler().0.interval(0),
        Some(Duration::from_secs(1))
    );
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
            p.b.commands.handler().0.interval(ATTITUDE),
            Some(Duration::from_millis(50))
        );
        let _ = count(&mut p, att);
        p.drive_for(Duration::from_secs(10));
        // 200 sent; 80 % arrive, 20 % of those twice: about 192.
        let n = count(&mut p, att);
        assert!((150..=230).contains(&n), "seed {seed}: {n}");
        // A one-shot request whose command is retried is still answered once.
        let before = p.b.sent.iter().filter(|&&m| m == AUTOPILOT_VERSION).count();
        if command(&mut p, request_message(AUTOPILOT_VERSION, [0.0; 5])).is_ok() {
            p.drive_for(Duration::from_millis(200));
            let after = p.b.sent.iter().filter(|&&m| m == AUTOPILOT_VERSION).count();
            assert_eq!(after - before, 1, "seed {seed}");
        }
    }
}
