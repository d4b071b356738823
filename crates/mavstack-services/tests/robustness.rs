//! Input from outside never panics a service: seeded random sequences of the messages the
//! services handle, with random fields, random senders and random timer calls, fed to
//! every client and server.

mod util;

use core::time::Duration;

use mavstack_core::testing::Rng;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    CommandAck, CommandInt, CommandLong, Heartbeat, MavAutopilot, MavCmd, MavMessage,
    MavMissionResult, MavMissionType, MavParamType, MavResult, MissionAck, MissionClearAll,
    MissionCount, MissionCurrent, MissionItemInt, MissionRequest, MissionRequestInt,
    MissionRequestList, MissionSetCurrent, ParamRequestList, ParamRequestRead, ParamSet,
    ParamValue, Timesync as TimesyncMsg,
};
use mavstack_services::command::{CommandClient, CommandHandler, CommandServer, Request, Response};
use mavstack_services::heartbeat::{HeartbeatConfig, Heartbeats};
use mavstack_services::mission::{MissionClient, MissionServer};
use mavstack_services::param::{Encoding, Name, ParamClient, ParamRef, ParamServer, Value};
use mavstack_services::stream::{StreamScheduler, Subscriptions};
use mavstack_services::timesync::Timesync;
use mavstack_services::{Address, Service};
use util::T0;

struct Anything(StreamScheduler);

impl CommandHandler for Anything {
    fn handle_command(&mut self, now: Instant, request: &Request) -> Response {
        self.0
            .handle_command(now, request)
            .unwrap_or(Response::in_progress(7))
    }
}

fn float(rng: &mut Rng) -> f32 {
    match rng.below(6) {
        0 => f32::NAN,
        1 => f32::INFINITY,
        2 => -1.0,
        3 => f32::from_bits(rng.next_u64() as u32),
        _ => rng.below(600) as f32,
    }
}

fn small(rng: &mut Rng) -> u16 {
    match rng.below(4) {
        0 => u16::MAX,
        1 => rng.next_u64() as u16,
        _ => rng.below(6) as u16,
    }
}

fn message(rng: &mut Rng) -> MavMessage {
    let ts = if rng.chance(0.5) {
        1
    } else {
        rng.next_u64() as u8
    };
    let tc = if rng.chance(0.5) {
        1
    } else {
        rng.next_u64() as u8
    };
    let ty = MavMissionType([0, 1, 2, 255, 7][rng.below(5) as usize]);
    let id = {
        let mut f = [0u8; 16];
        for b in f.iter_mut().take(rng.below(17) as usize) {
            *b = b'A' + rng.below(3) as u8;
        }
        f
    };
    let cmd = MavCmd([511, 512, 400, 22, 16, 60_000][rng.below(6) as usize]);
    match rng.below(20) {
        0 => MavMessage::Heartbeat(Heartbeat {
            autopilot: MavAutopilot(rng.next_u64() as u8),
            ..Default::default()
        }),
        1 => MavMessage::CommandLong(CommandLong {
            target_system: ts,
            target_component: tc,
            command: cmd,
            confirmation: rng.next_u64() as u8,
            param1: float(rng),
            param2: float(rng),
            param7: float(rng),
            ..Default::default()
        }),
        2 => MavMessage::CommandInt(CommandInt {
            target_system: ts,
            target_component: tc,
            command: cmd,
            param1: float(rng),
            param2: float(rng),
            x: rng.next_u64() as i32,
            ..Default::default()
        }),
        3 => MavMessage::CommandAck(CommandAck {
            command: cmd,
            result: MavResult(rng.below(12) as u8),
            progress: rng.next_u64() as u8,
            target_system: ts,
            target_component: tc,
            ..Default::default()
        }),
        4 => MavMessage::ParamRequestList(ParamRequestList {
            target_system: ts,
            target_component: tc,
        }),
        5 => MavMessage::ParamRequestRead(ParamRequestRead {
            target_system: ts,
            target_component: tc,
            param_id: id,
            param_index: rng.next_u64() as i16 % 8,
        }),
        6 => MavMessage::ParamSet(ParamSet {
            target_system: ts,
            target_component: tc,
            param_id: id,
            param_value: float(rng),
            param_type: MavParamType(rng.below(12) as u8),
        }),
        7 => MavMessage::ParamValue(ParamValue {
            param_id: id,
            param_value: float(rng),
            param_type: MavParamType(rng.below(12) as u8),
            param_count: small(rng),
            param_index: small(rng),
        }),
        8 => MavMessage::MissionCount(MissionCount {
            target_system: ts,
            target_component: tc,
            count: small(rng),
            mission_type: ty,
        }),
        9 => MavMessage::MissionRequestInt(MissionRequestInt {
            target_system: ts,
            target_component: tc,
            seq: small(rng),
            mission_type: ty,
        }),
        10 => MavMessage::MissionRequest(MissionRequest {
            target_system: ts,
            target_component: tc,
            seq: small(rng),
            mission_type: ty,
        }),
        11 => MavMessage::MissionItemInt(MissionItemInt {
            target_system: ts,
            target_component: tc,
            seq: small(rng),
            mission_type: ty,
            ..Default::default()
        }),
        12 => MavMessage::MissionAck(MissionAck {
            target_system: ts,
            target_component: tc,
            r#type: MavMissionResult(rng.below(16) as u8),
            mission_type: ty,
        }),
        13 => MavMessage::MissionClearAll(MissionClearAll {
            target_system: ts,
            target_component: tc,
            mission_type: ty,
        }),
        14 => MavMessage::MissionRequestList(MissionRequestList {
            target_system: ts,
            target_component: tc,
            mission_type: ty,
        }),
        15 => MavMessage::MissionSetCurrent(MissionSetCurrent {
            target_system: ts,
            target_component: tc,
            seq: small(rng),
        }),
        16 => MavMessage::MissionCurrent(MissionCurrent {
            seq: small(rng),
            ..Default::default()
        }),
        17 => MavMessage::Timesync(TimesyncMsg {
            tc1: if rng.chance(0.5) {
                0
            } else {
                rng.next_u64() as i64
            },
            ts1: rng.next_u64() as i64,
        }),
        _ => MavMessage::Heartbeat(Heartbeat::default()),
    }
}

#[test]
fn random_input_never_panics_any_service() {
    let me = Address::new(1, 1);
    for seed in 0..40u64 {
        let mut rng = Rng::new(seed);
        let mut scheduler = StreamScheduler::new();
        scheduler.support(30, Some(Duration::from_millis(100)));
        let mut param_server = ParamServer::new(me, Encoding::Bytewise);
        for (n, v) in [
            ("A", Value::U8(1)),
            ("AA", Value::F32(2.0)),
            ("B", Value::I16(-3)),
        ] {
            param_server.insert(Name::new(n).unwrap(), v).unwrap();
        }
        let mut services: Vec<Box<dyn Service>> = vec![
            Box::new(Heartbeats::new(HeartbeatConfig::ground_station())),
            Box::new(CommandClient::new(me, Default::default())),
            Box::new(CommandServer::new(
                me,
                Default::default(),
                Anything(scheduler),
            )),
            Box::new(param_server),
            Box::new(MissionServer::new(me, Default::default())),
            Box::new(Timesync::new(Default::default())),
        ];
        let mut commands = CommandClient::new(me, Default::default());
        let mut params = ParamClient::new(Default::default(), Encoding::CCast);
        let mut missions = MissionClient::new(me, Default::default());
        let mut subs = Subscriptions::new();
        subs.subscribe(0, None);
        let peer = Address::new(1, 1);
        let _ = commands.send(
            T0,
            peer,
            mavstack_services::stream::request_message(30, [0.0; 5]),
        );
        let _ = params.fetch_all(T0, peer);
        let _ = params.read(T0, peer, ParamRef::Index(2));
        let _ = params.set(T0, peer, Name::new("AA").unwrap(), Value::F32(1.0));
        let _ = missions.download(T0, peer, MavMissionType::MISSION);
        let mut now = T0;
        for _ in 0..3_000 {
            now += Duration::from_micros(rng.below(300_000));
            let from = Address::new(
                if rng.chance(0.8) {
                    1
                } else {
                    rng.next_u64() as u8
                },
                rng.below(3) as u8,
            );
            let m = message(&mut rng);
            for s in services.iter_mut() {
                let _ = s.handle_message(now, from, &m);
                if rng.chance(0.3) {
                    s.handle_timeout(now);
                }
                while s.poll_transmit().is_some() {}
                let _ = s.poll_timeout();
            }
            let _ = commands.handle_message(now, from, &m);
            let _ = params.handle_message(now, from, &m);
            let _ = missions.handle_message(now, from, &m);
            let _ = subs.handle_message(now, from, &m);
            for c in [
                &mut commands as &mut dyn Service,
                &mut params,
                &mut missions,
            ] {
                if rng.chance(0.3) {
                    c.handle_timeout(now);
                }
                while c.poll_transmit().is_some() {}
            }
            while commands.poll_event().is_some() {}
            while params.poll_event().is_some() {}
            if missions.poll_event().is_some() && rng.chance(0.5) {
                let _ = missions.upload(
                    now,
                    peer,
                    MavMissionType::FENCE,
                    vec![MissionItemInt::default(); 3],
                );
            }
            while subs.poll_delivery().is_some() {}
        }
    }
}
