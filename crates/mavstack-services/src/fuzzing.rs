//! The services' fuzzing entry point: every service of the crate, in both roles, fed
//! decoded messages in any order from any sender.

use core::time::Duration;

use mavstack_core::MessageSet as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    Attitude, CommandLong, MavCmd, MavMessage, MavMissionType, MavResult, MissionItemInt,
};

use crate::command::{Command, CommandClient, CommandHandler, CommandServer, Request, Response};
use crate::heartbeat::{HeartbeatConfig, Heartbeats};
use crate::mission::{MissionClient, MissionConfig, MissionServer};
use crate::param::{Encoding, Name, ParamClient, ParamServer, Value};
use crate::stream::{Due, StreamServer, Subscriptions};
use crate::timesync::Timesync;
use crate::{Address, Service};

/// The messages the services act on; a record's id byte picks one.
const IDS: [u32; 24] = [
    0, 20, 21, 22, 23, 39, 40, 41, 42, 43, 44, 45, 46, 47, 51, 73, 75, 76, 77, 111, 148, 244, 300,
    30,
];

/// How much more heap the services may ever hold than after they were set up: enough for
/// the largest tables a peer can make them keep (65,535 parameters or mission items, 65,536
/// peers), whatever it sends and however long.
pub const HEAP_BOUND: usize = 16 << 20;

struct Answer;

impl CommandHandler for Answer {
    fn handle_command(&mut self, _now: Instant, request: &Request) -> Response {
        match request.command.id().0 % 3 {
            0 => Response::done(MavResult::ACCEPTED),
            1 => Response::in_progress(10),
            _ => Response::done(MavResult::UNSUPPORTED),
        }
    }
}

/// Feeds `data` to every service: records of `[control, sysid, compid, id, len,
/// payload...]` decoded into messages from `sysid/compid`, with time moving by the control
/// byte, and now and then a new request of each client. After every step, everything each
/// service emits is drained, and `heap()` (the bytes allocated, if the caller can count
/// them; `None` otherwise) may not grow by more than [`HEAP_BOUND`].
pub fn fuzz_services(data: &[u8], heap: &dyn Fn() -> Option<usize>) {
    let vehicle = Address::new(1, 1);
    let gcs = Address::new(255, 190);
    let mut params = ParamServer::new(vehicle, Encoding::Bytewise);
    for (i, name) in ["RTL_ALT", "SYSID_THISMAV", "WPNAV_SPEED"]
        .iter()
        .enumerate()
    {
        if let Ok(name) = Name::new(name) {
            let _ = params.insert(name, Value::F32(i as f32));
        }
    }
    let mut missions = MissionServer::new(vehicle, Default::default());
    let mut commands = CommandServer::new(vehicle, Default::default(), Answer);
    let mut streams = StreamServer::new(vehicle, |_now: Instant, due: &Due| {
        (due.msg_id == 30).then(|| MavMessage::Attitude(Attitude::default()))
    });
    streams.support(30, Some(Duration::from_millis(100)));
    let mut heartbeats = Heartbeats::new(HeartbeatConfig::ground_station());
    let mut timesync = Timesync::new(Default::default());
    let mut param_client = ParamClient::new(Default::default(), Encoding::CCast);
    // Windowed transfers (as with ArduPilot): the items kept ahead are bounded too.
    let mission_config = MissionConfig {
        download_window: 8,
        upload_window: 8,
        ..MissionConfig::default()
    };
    let mut mission_client = MissionClient::new(gcs, mission_config);
    let mut command_client = CommandClient::new(gcs, Default::default());
    let mut subscriptions = Subscriptions::new();
    subscriptions.subscribe(30, None);

    let mut now = Instant::from_secs(1000);
    let base = heap();
    let mut rest = data;
    while let [control, sysid, compid, id, len, tail @ ..] = rest {
        let (payload, after) = tail.split_at(usize::from(*len).min(tail.len()));
        rest = after;
        now += Duration::from_millis(u64::from(control & 0x0f) * 97);
        let from = Address::new(*sysid, *compid);
        let msg_id = IDS[usize::from(*id) % IDS.len()];
        if control & 0x10 != 0 {
            let _ = param_client.fetch_all(now, vehicle);
        }
        if control & 0x20 != 0 && !mission_client.is_busy() {
            let _ = match control >> 6 {
                0 => mission_client.download(now, vehicle, MavMissionType::MISSION),
                1 => mission_client.upload(
                    now,
                    vehicle,
                    MavMissionType::FENCE,
                    alloc::vec![MissionItemInt::default(); usize::from(*len % 8)],
                ),
                _ => mission_client.clear(now, vehicle, MavMissionType::ALL),
            };
        }
        if control & 0x40 != 0 {
            let cmd = CommandLong {
                command: MavCmd(u16::from(*id)),
                ..CommandLong::default()
            };
            let _ = command_client.send(now, vehicle, Command::Long(cmd));
        }
        let message = MavMessage::decode(msg_id, payload).ok();
        let mut services: [&mut dyn Service; 9] = [
            &mut params,
            &mut missions,
            &mut commands,
            &mut streams,
            &mut heartbeats,
            &mut timesync,
            &mut param_client,
            &mut mission_client,
            &mut command_client,
        ];
        for service in &mut services {
            if let Some(m) = &message {
                service.handle_message(now, from, m);
            }
            service.handle_timeout(now);
            while service.poll_transmit().is_some() {}
            let _ = service.poll_timeout();
        }
        if let Some(m) = &message {
            subscriptions.handle_message(now, from, m);
        }
        while params.poll_event().is_some() {}
        while missions.poll_event().is_some() {}
        while commands.poll_event().is_some() {}
        while streams.poll_event().is_some() {}
        while heartbeats.poll_event().is_some() {}
        while timesync.poll_event().is_some() {}
        while param_client.poll_event().is_some() {}
        while mission_client.poll_event().is_some() {}
        while command_client.poll_event().is_some() {}
        while subscriptions.poll_delivery().is_some() {}
        if let (Some(base), Some(used)) = (base, heap()) {
            assert!(
                used.saturating_sub(base) <= HEAP_BOUND,
                "the services hold {} bytes more than at the start",
                used - base
            );
        }
    }
}

/// `len` pseudo-random bytes (xorshift64 from `state`, which it advances): sample inputs for
/// the fuzz targets' tests on stable.
#[cfg(test)]
pub(crate) fn sample_bytes(state: &mut u64, len: usize) -> alloc::vec::Vec<u8> {
    (0..len)
        .map(|_| {
            *state ^= *state << 13;
            *state ^= *state >> 7;
            *state ^= *state << 17;
            *state as u8
        })
        .collect()
}
