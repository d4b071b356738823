//! The ArduPilot flavour paces a mission upload as ArduPilot does
//! (libraries/GCS_MAVLink/MissionItemProtocol.cpp, `update()`): it asks again for an item a
//! second after its last request, and gives the upload up 8 s after the last item with
//! MISSION_ACK OPERATION_CANCELLED. A ground station slowed down by a busy machine (MAVProxy
//! under CI load, through an MQTT broker) answered later than the round trip the simulator
//! had measured, so it asked again, MAVProxy answered both requests, and the copy got
//! INVALID_SEQUENCE: ArduPilot would have waited.

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    MavMessage, MavMissionResult, MavMissionType, MissionCount, MissionItemInt,
};
use mavstack_services::Address;
use mavstack_sim::{Autopilot, SimConfig, Vehicle, params};

const T0: Instant = Instant::from_secs(1_763_000_000);

const GCS: Address = Address {
    system: 255,
    component: 190,
};

fn vehicle(autopilot: Autopilot) -> Vehicle {
    let config = SimConfig {
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
    };
    Vehicle::new(config, T0)
}

fn item(seq: u16) -> MavMessage {
    MavMessage::MissionItemInt(MissionItemInt {
        target_system: 1,
        target_component: 1,
        seq,
        x: -353_632_610 + i32::from(seq) * 1000,
        y: 1_491_652_300,
        z: 20.0,
        mission_type: MavMissionType::MISSION,
        ..MissionItemInt::default()
    })
}

/// The mission protocol's part of what the vehicle sent: (when, seq) of its requests and
/// (when, result) of its MISSION_ACKs.
#[derive(Debug, Default)]
struct Seen {
    requests: Vec<(Duration, u16)>,
    acks: Vec<(Duration, MavMissionResult)>,
}

impl Seen {
    fn take(&mut self, v: &mut Vehicle, now: Instant) {
        let at = now.saturating_duration_since(T0);
        while let Some(out) = v.poll_transmit() {
            match out.message {
                MavMessage::MissionRequestInt(r) => self.requests.push((at, r.seq)),
                MavMessage::MissionAck(a) => self.acks.push((at, a.r#type)),
                _ => {}
            }
        }
    }
}

/// An upload of `n` items from a ground station that answers every request, a repeated one
/// too (as MAVProxy does), `delay(seq)` after it comes; stops at the first MISSION_ACK.
fn upload(v: &mut Vehicle, n: u16, delay: impl Fn(u16) -> Duration) -> Seen {
    let mut seen = Seen::default();
    let mut answers: Vec<(Instant, u16)> = Vec::new();
    let count = MavMessage::MissionCount(MissionCount {
        target_system: 1,
        target_component: 1,
        count: n,
        mission_type: MavMissionType::MISSION,
    });
    let mut now = T0;
    v.handle_message(now, GCS, &count);
    let end = T0 + Duration::from_secs(60);
    while now < end {
        let asked = seen.requests.len();
        seen.take(v, now);
        for &(_, seq) in &seen.requests[asked..] {
            answers.push((now + delay(seq), seq));
        }
        if !seen.acks.is_empty() {
            break;
        }
        answers.sort();
        let timer = v.poll_timeout();
        if answers.first().is_some_and(|a| a.0 <= timer) {
            let (at, seq) = answers.remove(0);
            now = at;
            v.handle_message(now, GCS, &item(seq));
        } else {
            now = timer;
            v.handle_timeout(now);
        }
    }
    seen
}

/// The first items answered at once (the round trip measured short), the rest after 600 ms
/// each: a ground station on a busy machine.
fn slowed_down(seq: u16) -> Duration {
    if seq < 5 {
        Duration::from_millis(2)
    } else {
        Duration::from_millis(600)
    }
}

#[test]
fn ardupilot_flavour_waits_a_second_for_a_slowed_down_ground_station() {
    let mut v = vehicle(Autopilot::Ardupilot);
    let seen = upload(&mut v, 12, slowed_down);
    let asked: Vec<u16> = seen.requests.iter().map(|r| r.1).collect();
    assert_eq!(asked, (0..12).collect::<Vec<u16>>(), "each item asked once");
    assert_eq!(
        seen.acks.iter().map(|a| a.1).collect::<Vec<_>>(),
        [MavMissionResult::MAV_MISSION_ACCEPTED]
    );
}

#[test]
fn ardupilot_flavour_asks_again_after_a_second_and_cancels_after_8_s() {
    let mut v = vehicle(Autopilot::Ardupilot);
    // Item 0 answered at once, then the ground station falls silent.
    let seen = upload(&mut v, 3, |seq| {
        if seq == 0 {
            Duration::from_millis(2)
        } else {
            Duration::from_secs(3600)
        }
    });
    let ms = Duration::from_millis;
    let mut want = vec![(ms(0), 0)];
    want.extend((0..8).map(|k| (ms(2 + 1000 * k), 1)));
    assert_eq!(seen.requests, want);
    assert_eq!(
        seen.acks,
        [(ms(8002), MavMissionResult::MAV_MISSION_OPERATION_CANCELLED)]
    );
    let log: Vec<String> = core::iter::from_fn(|| v.poll_log()).collect();
    assert!(
        log.iter().any(|l| l == "mission upload abandoned"),
        "{log:?}"
    );
}

/// The PX4 flavour keeps the round-trip pacing (PX4 asks again after 250 ms).
#[test]
fn px4_flavour_asks_a_slowed_down_ground_station_again() {
    let mut v = vehicle(Autopilot::Px4);
    let seen = upload(&mut v, 12, slowed_down);
    assert!(seen.requests.len() > 12, "{:?}", seen.requests);
    assert_eq!(
        seen.acks.last().map(|a| a.1),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
}
