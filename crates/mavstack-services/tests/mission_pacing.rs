//! When the mission server asks again for an item and when it gives an upload up
//! ([`UploadPacing`]): by the measured round trip (the default), or at fixed times as
//! ArduPilot (a second after its last request, given up after 8 s without an item).

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    MavMessage, MavMissionResult, MavMissionType, MissionCount, MissionItemInt,
};
use mavstack_services::mission::{
    MissionConfig, MissionServer, MissionServerEvent, StrayItems, UploadPacing,
};
use mavstack_services::{Address, Service};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);
const T0: Instant = Instant::from_secs(1_000);

/// ArduPilot's pacing (libraries/GCS_MAVLink/MissionItemProtocol.cpp, `update()`).
const ARDUPILOT: UploadPacing = UploadPacing::Fixed {
    every: Duration::from_secs(1),
    give_up_after: Duration::from_secs(8),
};

fn server(pacing: UploadPacing) -> MissionServer {
    MissionServer::new(
        VEHICLE,
        MissionConfig {
            stray_items: StrayItems::ArduPilot,
            pacing,
            ..MissionConfig::default()
        },
    )
}

fn count(n: u16) -> MavMessage {
    MavMessage::MissionCount(MissionCount {
        target_system: VEHICLE.system,
        target_component: VEHICLE.component,
        count: n,
        mission_type: MavMissionType::MISSION,
    })
}

fn item(seq: u16) -> MavMessage {
    MavMessage::MissionItemInt(MissionItemInt {
        target_system: VEHICLE.system,
        target_component: VEHICLE.component,
        seq,
        x: i32::from(seq),
        mission_type: MavMissionType::MISSION,
        ..MissionItemInt::default()
    })
}

/// What the server sent during an upload.
#[derive(Debug, Default)]
struct Seen {
    /// (when, seq) of every MISSION_REQUEST_INT.
    requests: Vec<(Instant, u16)>,
    /// (when, result) of every MISSION_ACK.
    acks: Vec<(Instant, MavMissionResult)>,
}

impl Seen {
    fn take(&mut self, s: &mut MissionServer, now: Instant) {
        while let Some(out) = s.poll_transmit() {
            match out.message {
                MavMessage::MissionRequestInt(r) => self.requests.push((now, r.seq)),
                MavMessage::MissionAck(a) => self.acks.push((now, a.r#type)),
                other => panic!("unexpected {other:?}"),
            }
        }
    }

    fn final_ack(&self) -> Option<MavMissionResult> {
        self.acks
            .iter()
            .map(|a| a.1)
            .find(|&r| r != MavMissionResult::MAV_MISSION_INVALID_SEQUENCE)
    }

    fn invalid_sequence_acks(&self) -> usize {
        self.acks
            .iter()
            .filter(|a| a.1 == MavMissionResult::MAV_MISSION_INVALID_SEQUENCE)
            .count()
    }

    /// How many requests asked for an item already asked for.
    fn repeated_requests(&self) -> usize {
        let mut seqs: Vec<u16> = self.requests.iter().map(|r| r.1).collect();
        let all = seqs.len();
        seqs.dedup();
        all - seqs.len()
    }
}

/// An upload of `n` items from a ground station that answers every request, a repeated one
/// too (as MAVProxy does), `delay(seq)` after it comes, on a link that loses nothing.
fn upload(s: &mut MissionServer, n: u16, delay: impl Fn(u16) -> Duration) -> Seen {
    let mut seen = Seen::default();
    let mut answers: Vec<(Instant, u16)> = Vec::new();
    s.handle_message(T0, GCS, &count(n));
    let mut now = T0;
    loop {
        let asked = seen.requests.len();
        seen.take(s, now);
        for &(_, seq) in &seen.requests[asked..] {
            answers.push((now + delay(seq), seq));
        }
        if seen.final_ack().is_some() {
            return seen;
        }
        answers.sort();
        let next_answer = answers.first().map(|a| a.0);
        let timer = s.poll_timeout();
        if let Some(at) = next_answer.filter(|&a| timer.is_none_or(|t| a <= t)) {
            let (_, seq) = answers.remove(0);
            now = at;
            s.handle_message(now, GCS, &item(seq));
        } else if let Some(t) = timer {
            now = t;
            s.handle_timeout(now);
        } else {
            return seen;
        }
    }
}

/// The first items answered at once (the round trip measured short), the rest after 600 ms
/// each: a ground station slowed down by a busy machine.
fn slowed_down(seq: u16) -> Duration {
    if seq < 5 {
        Duration::from_millis(2)
    } else {
        Duration::from_millis(600)
    }
}

#[test]
fn fixed_pacing_asks_again_a_second_after_the_last_request_and_cancels_after_8_s() {
    let mut s = server(ARDUPILOT);
    assert_eq!(s.patience(), Duration::from_secs(8));
    let mut seen = Seen::default();
    s.handle_message(T0, GCS, &count(3));
    seen.take(&mut s, T0);
    // Item 0 comes after 2.5 s: from then on the clock runs from its request for 1.
    let item_at = T0 + Duration::from_millis(2500);
    while let Some(t) = s.poll_timeout().filter(|&t| t < item_at) {
        s.handle_timeout(t);
        seen.take(&mut s, t);
    }
    s.handle_message(item_at, GCS, &item(0));
    seen.take(&mut s, item_at);
    while let Some(t) = s.poll_timeout() {
        s.handle_timeout(t);
        seen.take(&mut s, t);
    }
    let secs = |ms: u64| T0 + Duration::from_millis(ms);
    let mut want = vec![(secs(0), 0), (secs(1000), 0), (secs(2000), 0)];
    want.extend((0..8).map(|k| (secs(2500 + 1000 * k), 1)));
    assert_eq!(seen.requests, want);
    assert_eq!(
        seen.acks,
        [(
            secs(10_500),
            MavMissionResult::MAV_MISSION_OPERATION_CANCELLED
        )]
    );
    assert_eq!(
        s.poll_event(),
        Some(MissionServerEvent::UploadAbandoned {
            mission_type: MavMissionType::MISSION
        })
    );
    assert!(!s.is_receiving());
    assert!(s.plan(MavMissionType::MISSION).is_empty());
}

/// A ground station slower than the measured round trip but quicker than a second: with
/// ArduPilot's pacing every item is asked for once and nothing is refused.
#[test]
fn fixed_pacing_waits_for_a_slowed_down_ground_station() {
    let mut s = server(ARDUPILOT);
    let seen = upload(&mut s, 12, slowed_down);
    assert_eq!(
        seen.final_ack(),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
    assert_eq!(seen.repeated_requests(), 0, "{:?}", seen.requests);
    assert_eq!(seen.invalid_sequence_acks(), 0);
    assert_eq!(s.plan(MavMissionType::MISSION).len(), 12);
}

/// The default pacing, unchanged: it asks again once the slowed-down answer is later than
/// the round trip it measured, and the copies that answer its repeats are refused.
#[test]
fn adaptive_pacing_asks_a_slowed_down_ground_station_again() {
    let mut s = server(UploadPacing::Adaptive);
    let seen = upload(&mut s, 12, slowed_down);
    assert_eq!(
        seen.final_ack(),
        Some(MavMissionResult::MAV_MISSION_ACCEPTED)
    );
    assert!(seen.repeated_requests() > 0, "{:?}", seen.requests);
    assert!(seen.invalid_sequence_acks() > 0, "{:?}", seen.acks);
    assert_eq!(s.plan(MavMissionType::MISSION).len(), 12);
}

/// The default gives an upload up silently, after `timeout × (retries + 1)`.
#[test]
fn adaptive_pacing_gives_up_without_an_ack() {
    let mut s = server(UploadPacing::Adaptive);
    let mut seen = Seen::default();
    s.handle_message(T0, GCS, &count(3));
    let mut last = T0;
    while let Some(t) = s.poll_timeout() {
        seen.take(&mut s, t);
        s.handle_timeout(t);
        last = t;
    }
    seen.take(&mut s, last);
    assert_eq!(last, T0 + Duration::from_secs(9));
    assert!(seen.acks.is_empty(), "{:?}", seen.acks);
    assert!(!s.is_receiving());
}
