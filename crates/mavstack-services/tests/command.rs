//! The command protocol in both roles, unit by unit and through the simulated link.

mod util;

use core::time::Duration;
use std::collections::BTreeMap;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    CommandAck, CommandInt, CommandLong, MavCmd, MavFrame, MavMessage, MavResult,
};
use mavstack_services::command::{
    Command, CommandClient, CommandConfig, CommandError, CommandEvent, CommandHandle,
    CommandHandler, CommandServer, CommandServerEvent, Request, Response, SendError,
};
use mavstack_services::{Address, Service};
use util::{Knobs, Pair, T0};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);

/// Counts executions by param1; answers ACCEPTED, or IN_PROGRESS for NAV_TAKEOFF.
#[derive(Default)]
struct Counter {
    runs: BTreeMap<u32, u32>,
}

impl CommandHandler for Counter {
    fn handle_command(&mut self, _now: Instant, request: &Request) -> Response {
        let key = match &request.command {
            Command::Long(c) => c.param1 as u32,
            Command::Int(c) => c.param1 as u32,
        };
        *self.runs.entry(key).or_default() += 1;
        match request.command.id() {
            MavCmd::NAV_TAKEOFF => Response::in_progress(0),
            MavCmd::COMPONENT_ARM_DISARM | MavCmd::NAV_WAYPOINT => {
                Response::done(MavResult::ACCEPTED)
            }
            _ => Response::done(MavResult::UNSUPPORTED),
        }
    }
}

fn long(command: MavCmd, param1: f32) -> Command {
    Command::Long(CommandLong {
        command,
        param1,
        param5: f32::NAN,
        ..Default::default()
    })
}

fn sent(client: &mut CommandClient) -> Vec<MavMessage> {
    core::iter::from_fn(|| client.poll_transmit().map(|o| o.message)).collect()
}

fn finished(client: &mut CommandClient) -> Vec<(CommandHandle, Result<CommandAck, CommandError>)> {
    core::iter::from_fn(|| client.poll_event())
        .filter_map(|e| match e {
            CommandEvent::Finished { handle, result } => Some((handle, result)),
            _ => None,
        })
        .collect()
}

fn ack(command: MavCmd, result: MavResult, progress: u8) -> MavMessage {
    MavMessage::CommandAck(CommandAck {
        command,
        result,
        progress,
        ..Default::default()
    })
}

#[test]
fn retries_count_confirmation_up_then_ack_accepts() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    let h = c
        .send(T0, VEHICLE, long(MavCmd::COMPONENT_ARM_DISARM, 1.0))
        .unwrap();
    let mut confirmations = vec![];
    let mut now = T0;
    for _ in 0..3 {
        for m in sent(&mut c) {
            let MavMessage::CommandLong(m) = m else {
                panic!()
            };
            assert_eq!((m.target_system, m.target_component), (1, 1));
            confirmations.push(m.confirmation);
        }
        now = c.poll_timeout().unwrap();
        c.handle_timeout(now);
    }
    for m in sent(&mut c) {
        let MavMessage::CommandLong(m) = m else {
            panic!()
        };
        confirmations.push(m.confirmation);
    }
    assert_eq!(confirmations, [0, 1, 2, 3]);
    assert_eq!(now, T0 + Duration::from_millis(1500));
    assert!(c.handle_message(
        now,
        VEHICLE,
        &ack(MavCmd::COMPONENT_ARM_DISARM, MavResult::ACCEPTED, 0)
    ));
    let done = finished(&mut c);
    assert_eq!(done.len(), 1);
    assert_eq!(done[0].0, h);
    assert_eq!(done[0].1.unwrap().result, MavResult::ACCEPTED);
    assert_eq!(c.in_flight(), 0);
    assert_eq!(c.poll_timeout(), None);
}

#[test]
fn no_ack_times_out_after_every_retry() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    let h = c
        .send(T0, VEHICLE, long(MavCmd::COMPONENT_ARM_DISARM, 1.0))
        .unwrap();
    let mut sends = sent(&mut c).len();
    while let Some(t) = c.poll_timeout() {
        c.handle_timeout(t);
        sends += sent(&mut c).len();
        if t > T0 + Duration::from_secs(10) {
            panic!("never timed out");
        }
    }
    assert_eq!(sends, 4);
    assert_eq!(
        finished(&mut c),
        [(h, Err(CommandError::TimedOut { attempts: 4 }))]
    );
}

#[test]
fn in_progress_extends_the_timeout_until_the_final_ack() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    let h = c
        .send(T0, VEHICLE, long(MavCmd::NAV_TAKEOFF, 10.0))
        .unwrap();
    let _ = sent(&mut c);
    let t1 = T0 + Duration::from_millis(100);
    c.handle_message(
        t1,
        VEHICLE,
        &ack(MavCmd::NAV_TAKEOFF, MavResult::IN_PROGRESS, 10),
    );
    assert_eq!(
        c.poll_event(),
        Some(CommandEvent::Progress {
            handle: h,
            progress: 10
        })
    );
    assert_eq!(c.poll_timeout(), Some(t1 + Duration::from_secs(3)));
    // No resend while in progress, even past the normal timeout.
    c.handle_timeout(t1 + Duration::from_secs(2));
    assert!(sent(&mut c).is_empty());
    let t2 = t1 + Duration::from_millis(2900);
    c.handle_message(
        t2,
        VEHICLE,
        &ack(MavCmd::NAV_TAKEOFF, MavResult::IN_PROGRESS, 60),
    );
    c.handle_timeout(t1 + Duration::from_millis(3500)); // past the first deadline
    assert_eq!(
        c.poll_event(),
        Some(CommandEvent::Progress {
            handle: h,
            progress: 60
        })
    );
    assert_eq!(c.poll_event(), None);
    c.handle_message(
        t2 + Duration::from_secs(1),
        VEHICLE,
        &ack(MavCmd::NAV_TAKEOFF, MavResult::ACCEPTED, 100),
    );
    let done = finished(&mut c);
    assert_eq!(done[0].1.unwrap().progress, 100);
}

#[test]
fn in_progress_then_silence_gives_up() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    let h = c
        .send(T0, VEHICLE, long(MavCmd::NAV_TAKEOFF, 10.0))
        .unwrap();
    c.handle_message(
        T0,
        VEHICLE,
        &ack(MavCmd::NAV_TAKEOFF, MavResult::IN_PROGRESS, 42),
    );
    let _ = c.poll_event();
    c.handle_timeout(T0 + Duration::from_secs(3));
    assert_eq!(
        finished(&mut c),
        [(h, Err(CommandError::InProgressTimedOut { progress: 42 }))]
    );
}

#[test]
fn rejections_are_typed_errors() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    let h = c
        .send(T0, VEHICLE, long(MavCmd::COMPONENT_ARM_DISARM, 1.0))
        .unwrap();
    c.handle_message(
        T0,
        VEHICLE,
        &ack(MavCmd::COMPONENT_ARM_DISARM, MavResult::DENIED, 0),
    );
    assert_eq!(
        finished(&mut c),
        [(
            h,
            Err(CommandError::Rejected {
                result: MavResult::DENIED,
                result_param2: 0
            })
        )]
    );
}

#[test]
fn acks_match_by_command_source_and_requester() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    let arm = c
        .send(T0, VEHICLE, long(MavCmd::COMPONENT_ARM_DISARM, 1.0))
        .unwrap();
    let other = Address::new(2, 1);
    let arm2 = c
        .send(T0, other, long(MavCmd::COMPONENT_ARM_DISARM, 1.0))
        .unwrap();
    let wp = c
        .send(T0, VEHICLE, long(MavCmd::NAV_WAYPOINT, 1.0))
        .unwrap();
    assert_eq!(
        c.send(T0, VEHICLE, long(MavCmd::COMPONENT_ARM_DISARM, 0.0)),
        Err(SendError::AlreadyInFlight {
            target: VEHICLE,
            command: MavCmd::COMPONENT_ARM_DISARM
        })
    );
    assert_eq!(c.in_flight(), 3);
    // Wrong source, and an ACK for another GCS: ignored.
    assert!(!c.handle_message(
        T0,
        Address::new(3, 1),
        &ack(MavCmd::COMPONENT_ARM_DISARM, MavResult::ACCEPTED, 0)
    ));
    let mut for_other_gcs = CommandAck {
        command: MavCmd::COMPONENT_ARM_DISARM,
        target_system: 254,
        ..Default::default()
    };
    assert!(!c.handle_ack(T0, VEHICLE, &for_other_gcs));
    for_other_gcs.target_system = 255;
    assert!(c.handle_ack(T0, VEHICLE, &for_other_gcs));
    assert!(c.handle_message(
        T0,
        other,
        &ack(MavCmd::COMPONENT_ARM_DISARM, MavResult::FAILED, 0)
    ));
    let done = finished(&mut c);
    assert_eq!(done.len(), 2);
    assert_eq!(done[0].0, arm);
    assert!(done[0].1.is_ok());
    assert_eq!(done[1].0, arm2);
    assert!(done[1].1.is_err());
    assert!(c.cancel(wp));
    assert_eq!(finished(&mut c), [(wp, Err(CommandError::Cancelled))]);
}

#[test]
fn a_first_send_repeated_later_is_a_new_request() {
    let mut s = CommandServer::new(VEHICLE, Default::default(), Counter::default());
    let cmd = CommandLong {
        target_system: 1,
        target_component: 1,
        command: MavCmd::COMPONENT_ARM_DISARM,
        param1: 7.0,
        ..Default::default()
    };
    s.handle_message(T0, GCS, &MavMessage::CommandLong(cmd));
    s.handle_message(
        T0 + Duration::from_secs(1),
        GCS,
        &MavMessage::CommandLong(cmd),
    );
    assert_eq!(s.handler().runs[&7], 2);
}

#[test]
fn duplicate_command_is_executed_once_and_acked_each_time() {
    let mut s = CommandServer::new(VEHICLE, Default::default(), Counter::default());
    let cmd = CommandLong {
        target_system: 1,
        target_component: 1,
        command: MavCmd::COMPONENT_ARM_DISARM,
        param1: 7.0,
        param5: f32::NAN,
        ..Default::default()
    };
    // The first send, a copy of it the link duplicated, then two retries.
    for (ms, confirmation) in [(0u64, 0u8), (20, 0), (500, 1), (1000, 2)] {
        let t = T0 + Duration::from_millis(ms);
        assert!(s.handle_message(
            t,
            GCS,
            &MavMessage::CommandLong(CommandLong {
                confirmation,
                ..cmd
            })
        ));
    }
    assert_eq!(s.handler().runs[&7], 1);
    let acks: Vec<_> = core::iter::from_fn(|| s.poll_transmit()).collect();
    assert_eq!(acks.len(), 4);
    for a in &acks {
        let MavMessage::CommandAck(a) = &a.message else {
            panic!()
        };
        assert_eq!(a.result, MavResult::ACCEPTED);
        assert_eq!((a.target_system, a.target_component), (255, 190));
    }
    let events: Vec<_> = core::iter::from_fn(|| s.poll_event()).collect();
    assert_eq!(
        events
            .iter()
            .filter(|e| matches!(e, CommandServerEvent::Duplicate { .. }))
            .count(),
        3
    );
    // Another parameter is another request; the same one after the window runs again.
    s.handle_message(
        T0 + Duration::from_secs(2),
        GCS,
        &MavMessage::CommandLong(CommandLong { param1: 8.0, ..cmd }),
    );
    s.handle_message(
        T0 + Duration::from_secs(10),
        GCS,
        &MavMessage::CommandLong(cmd),
    );
    assert_eq!(s.handler().runs[&7], 2);
    assert_eq!(s.handler().runs[&8], 1);
    // Not for us: ignored.
    assert!(!s.handle_message(
        T0,
        GCS,
        &MavMessage::CommandLong(CommandLong {
            target_system: 9,
            ..cmd
        })
    ));
}

#[test]
fn unknown_commands_are_acked_unsupported_and_command_int_works() {
    let mut s = CommandServer::new(VEHICLE, Default::default(), Counter::default());
    s.handle_message(
        T0,
        GCS,
        &MavMessage::CommandLong(CommandLong {
            command: MavCmd(60_000),
            ..Default::default()
        }),
    );
    let ci = CommandInt {
        command: MavCmd::NAV_WAYPOINT,
        frame: MavFrame::GLOBAL_RELATIVE_ALT_INT,
        x: 473_977_418,
        y: 85_455_939,
        ..Default::default()
    };
    s.handle_message(T0, GCS, &MavMessage::CommandInt(ci));
    let results: Vec<_> = core::iter::from_fn(|| s.poll_transmit())
        .map(|o| match o.message {
            MavMessage::CommandAck(a) => a.result,
            _ => panic!(),
        })
        .collect();
    assert_eq!(results, [MavResult::UNSUPPORTED, MavResult::ACCEPTED]);
}

#[test]
fn running_command_retries_get_the_progress_ack() {
    let mut s = CommandServer::new(VEHICLE, Default::default(), Counter::default());
    let cmd = MavMessage::CommandLong(CommandLong {
        command: MavCmd::NAV_TAKEOFF,
        param1: 1.0,
        ..Default::default()
    });
    s.handle_message(T0, GCS, &cmd);
    assert!(s.progress(T0 + Duration::from_secs(1), GCS, MavCmd::NAV_TAKEOFF, 50));
    s.handle_message(T0 + Duration::from_secs(5), GCS, &cmd); // long after the window
    assert_eq!(s.handler().runs[&1], 1);
    assert!(s.finish(
        T0 + Duration::from_secs(6),
        GCS,
        MavCmd::NAV_TAKEOFF,
        Response::done(MavResult::ACCEPTED)
    ));
    assert!(!s.finish(
        T0 + Duration::from_secs(6),
        GCS,
        MavCmd::NAV_TAKEOFF,
        Response::done(MavResult::ACCEPTED)
    ));
    let acks: Vec<(MavResult, u8)> = core::iter::from_fn(|| s.poll_transmit())
        .map(|o| match o.message {
            MavMessage::CommandAck(a) => (a.result, a.progress),
            _ => panic!(),
        })
        .collect();
    assert_eq!(
        acks,
        [
            (MavResult::IN_PROGRESS, 0),
            (MavResult::IN_PROGRESS, 50),
            (MavResult::IN_PROGRESS, 50),
            (MavResult::ACCEPTED, 0)
        ]
    );
}

type Sim = Pair<CommandClient, CommandServer<Counter>>;

fn sim(knobs: Knobs, seed: u64) -> Sim {
    Pair::new(
        CommandClient::new(GCS, CommandConfig::default()),
        GCS,
        CommandServer::new(VEHICLE, Default::default(), Counter::default()),
        VEHICLE,
        knobs,
        seed,
    )
}

/// 300 commands one after another, under 20 % loss, 20 % duplication and reordering: every
/// command runs at most once, and every command the client saw accepted ran exactly once.
#[test]
fn sim_commands_under_loss_run_once() {
    for seed in [1, 2, 3] {
        let mut p = sim(Knobs::hostile(), seed);
        let mut ok = 0;
        let mut timed_out = 0;
        for i in 0..300u32 {
            let cmd = if i % 2 == 0 {
                long(MavCmd::COMPONENT_ARM_DISARM, i as f32)
            } else {
                Command::Int(CommandInt {
                    command: MavCmd::NAV_WAYPOINT,
                    param1: i as f32,
                    ..Default::default()
                })
            };
            let h = p.a.send(p.now, VEHICLE, cmd).unwrap();
            let mut result = None;
            assert!(p.drive_until(Duration::from_secs(5), |c, _, _| {
                for (hh, r) in finished(c) {
                    assert_eq!(hh, h);
                    result = Some(r);
                }
                result.is_some()
            }));
            match result.unwrap() {
                Ok(a) => {
                    assert_eq!(a.result, MavResult::ACCEPTED);
                    assert_eq!(p.b.handler().runs.get(&i), Some(&1), "command {i}");
                    ok += 1;
                }
                Err(CommandError::TimedOut { attempts: 4 }) => timed_out += 1,
                Err(e) => panic!("{e}"),
            }
            // Let late duplicates arrive before the next command.
            p.drive_for(Duration::from_millis(100));
        }
        assert!(p.b.handler().runs.values().all(|&n| n == 1));
        assert_eq!(ok + timed_out, 300);
        // One round trip succeeds with p = 0.64; four tries all fail with p ≈ 1.7 %.
        assert!(timed_out < 20, "seed {seed}: {timed_out} timed out");
    }
}

/// A long command under loss: IN_PROGRESS reports keep the client waiting well past the
/// normal retry span, and the final ACK (resent on retries) ends it.
#[test]
fn sim_long_command_in_progress_under_loss() {
    let mut p = sim(Knobs::hostile(), 7);
    let h =
        p.a.send(p.now, VEHICLE, long(MavCmd::NAV_TAKEOFF, 1.0))
            .unwrap();
    let start = p.now;
    let mut progress = vec![];
    let mut result = None;
    let mut pct = 0u8;
    let mut next_report = start + Duration::from_millis(400);
    while result.is_none() && p.now < start + Duration::from_secs(30) {
        p.drive_for(Duration::from_millis(100));
        let now = p.now;
        while let Some(e) = p.a.poll_event() {
            match e {
                CommandEvent::Progress { progress: x, .. } => progress.push(x),
                CommandEvent::Finished { handle, result: r } => {
                    assert_eq!(handle, h);
                    result = Some(r);
                }
                _ => {}
            }
        }
        if now >= next_report && p.b.handler().runs.contains_key(&1) {
            next_report = now + Duration::from_millis(400);
            pct = pct.saturating_add(10);
            if pct >= 100 {
                p.b.finish(
                    now,
                    GCS,
                    MavCmd::NAV_TAKEOFF,
                    Response::done(MavResult::ACCEPTED),
                );
            } else {
                p.b.progress(now, GCS, MavCmd::NAV_TAKEOFF, pct);
            }
        }
    }
    // (A lost final ACK would end in InProgressTimedOut, as the protocol has it; this seed
    // loses some progress reports but not the final ACK.)
    assert!(result.unwrap().is_ok(), "{progress:?}");
    assert_eq!(p.b.handler().runs[&1], 1);
    assert!(
        p.now - start > Duration::from_secs(3),
        "took {:?}",
        p.now - start
    );
    assert!(progress.len() >= 3);
}

/// PX4 1.16 acknowledges DO_SET_MODE twice, 4–8 ms apart. On a 200 ms link the second ACK
/// of one command arrives just after the next one went: it must not answer it (the next
/// command may be another mode, which the vehicle may refuse or never get). Its own ACK,
/// a round trip later, does.
#[test]
fn the_echo_of_the_last_ack_does_not_answer_the_next_command() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    let loiter = c.send(T0, VEHICLE, long(MavCmd::DO_SET_MODE, 4.0)).unwrap();
    let accepted = ack(MavCmd::DO_SET_MODE, MavResult::ACCEPTED, 0);
    let t1 = T0 + Duration::from_millis(200);
    assert!(c.handle_message(t1, VEHICLE, &accepted));
    assert_eq!(finished(&mut c).len(), 1);
    let rtl = c.send(t1, VEHICLE, long(MavCmd::DO_SET_MODE, 5.0)).unwrap();
    assert_ne!(loiter, rtl);
    // The echo of the first, 8 ms later: nothing is answered.
    let echo = t1 + Duration::from_millis(8);
    assert!(!c.handle_message(echo, VEHICLE, &accepted));
    assert!(finished(&mut c).is_empty());
    // The vehicle refuses the second: that is its answer.
    let refused = ack(MavCmd::DO_SET_MODE, MavResult::DENIED, 0);
    assert!(c.handle_message(t1 + Duration::from_millis(200), VEHICLE, &refused));
    let done = finished(&mut c);
    assert_eq!(done.len(), 1);
    assert_eq!(done[0].0, rtl);
    assert!(matches!(
        done[0].1,
        Err(CommandError::Rejected {
            result: MavResult::DENIED,
            ..
        })
    ));
}

/// On a fast link whose vehicle acknowledges once (ArduPilot SITL: 5.8 ms), a command sent
/// right after the last one is answered by its own ACK, which comes after the window (half
/// the last round trip); another command id, or the same id from another system, has no
/// window at all.
#[test]
fn the_echo_window_is_half_the_round_trip_and_per_source_and_id() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    let accepted = ack(MavCmd::DO_SET_MODE, MavResult::ACCEPTED, 0);
    c.send(T0, VEHICLE, long(MavCmd::DO_SET_MODE, 4.0)).unwrap();
    let t1 = T0 + Duration::from_micros(5_800);
    assert!(c.handle_message(t1, VEHICLE, &accepted));
    c.send(t1, VEHICLE, long(MavCmd::DO_SET_MODE, 5.0)).unwrap();
    let other = Address::new(2, 1);
    c.send(t1, other, long(MavCmd::DO_SET_MODE, 5.0)).unwrap();
    c.send(t1, VEHICLE, long(MavCmd::COMPONENT_ARM_DISARM, 1.0))
        .unwrap();
    let soon = t1 + Duration::from_millis(1);
    assert!(c.handle_message(soon, other, &accepted));
    assert!(c.handle_message(
        soon,
        VEHICLE,
        &ack(MavCmd::COMPONENT_ARM_DISARM, MavResult::ACCEPTED, 0)
    ));
    assert!(!c.handle_message(soon, VEHICLE, &accepted));
    assert!(c.handle_message(t1 + Duration::from_micros(5_800), VEHICLE, &accepted));
    assert_eq!(finished(&mut c).len(), 4);
}

/// A command answered after IN_PROGRESS ran for seconds: that is no round trip, and the next
/// command of that id is answered by the first ACK it gets.
#[test]
fn no_echo_window_after_in_progress() {
    let mut c = CommandClient::new(GCS, CommandConfig::default());
    c.send(T0, VEHICLE, long(MavCmd::NAV_TAKEOFF, 10.0))
        .unwrap();
    let t1 = T0 + Duration::from_millis(5);
    assert!(c.handle_message(
        t1,
        VEHICLE,
        &ack(MavCmd::NAV_TAKEOFF, MavResult::IN_PROGRESS, 0)
    ));
    let t2 = t1 + Duration::from_secs(2);
    let done = ack(MavCmd::NAV_TAKEOFF, MavResult::ACCEPTED, 0);
    assert!(c.handle_message(t2, VEHICLE, &done));
    c.send(t2, VEHICLE, long(MavCmd::NAV_TAKEOFF, 10.0))
        .unwrap();
    assert!(c.handle_message(t2 + Duration::from_millis(5), VEHICLE, &done));
    assert_eq!(finished(&mut c).len(), 2);
}

/// A caller that runs a client per command (`System` does) hands the echo windows on: the
/// echo of the last command's ACK comes after its client is gone.
#[test]
fn echo_windows_pass_from_one_client_to_the_next() {
    let accepted = ack(MavCmd::DO_SET_MODE, MavResult::ACCEPTED, 0);
    let mut first = CommandClient::new(GCS, CommandConfig::default());
    first
        .send(T0, VEHICLE, long(MavCmd::DO_SET_MODE, 4.0))
        .unwrap();
    let t1 = T0 + Duration::from_millis(200);
    assert!(first.handle_message(t1, VEHICLE, &accepted));
    let mut next =
        CommandClient::new(GCS, CommandConfig::default()).with_echoes(first.take_echoes());
    next.send(t1, VEHICLE, long(MavCmd::DO_SET_MODE, 5.0))
        .unwrap();
    assert!(!next.handle_message(t1 + Duration::from_millis(8), VEHICLE, &accepted));
    assert!(next.handle_message(t1 + Duration::from_millis(200), VEHICLE, &accepted));
    // Without them, the echo answers.
    let mut forgetful = CommandClient::new(GCS, CommandConfig::default());
    forgetful
        .send(t1, VEHICLE, long(MavCmd::DO_SET_MODE, 5.0))
        .unwrap();
    assert!(forgetful.handle_message(t1 + Duration::from_millis(8), VEHICLE, &accepted));
}
