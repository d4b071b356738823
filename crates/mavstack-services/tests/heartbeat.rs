//! Heartbeat emitter and peer table, both sides through the simulated link.

mod util;

use core::time::Duration;

use mavstack_dialects::common::{
    AutopilotVersion, Heartbeat, MavAutopilot, MavMessage, MavModeFlag, MavProtocolCapability,
    MavState, MavType,
};
use mavstack_services::heartbeat::{HeartbeatConfig, HeartbeatEvent, Heartbeats};
use mavstack_services::{Address, Service};
use util::{Knobs, Pair};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);

fn quad() -> Heartbeat {
    Heartbeat {
        r#type: MavType::QUADROTOR,
        autopilot: MavAutopilot::PX4,
        base_mode: MavModeFlag::CUSTOM_MODE_ENABLED,
        custom_mode: 0x0004_0000,
        system_status: MavState::STANDBY,
        mavlink_version: 3,
    }
}

fn vehicle() -> Heartbeats {
    Heartbeats::new(HeartbeatConfig {
        own: Some(quad()),
        ..HeartbeatConfig::default()
    })
}

fn events(h: &mut Heartbeats) -> Vec<HeartbeatEvent> {
    core::iter::from_fn(|| h.poll_event()).collect()
}

#[test]
fn sim_peers_are_found_changed_and_lost_under_loss() {
    // On a lossy radio link, a 5 s timeout ("4–5 missed at 1 Hz"): with 20 % loss the
    // default 3 s would drop the peer whenever two heartbeats in a row are lost.
    let gcs = HeartbeatConfig {
        timeout: Duration::from_secs(5),
        ..HeartbeatConfig::ground_station()
    };
    let mut p = Pair::new(
        Heartbeats::new(gcs),
        GCS,
        vehicle(),
        VEHICLE,
        Knobs::hostile(),
        3,
    );
    p.drive_for(Duration::from_secs(20));
    let gcs_saw = events(&mut p.a);
    let HeartbeatEvent::New(peer) = gcs_saw[0] else {
        panic!("{gcs_saw:?}")
    };
    assert_eq!(gcs_saw.len(), 1, "{gcs_saw:?}");
    assert_eq!(peer.address, VEHICLE);
    assert!(peer.is_autopilot() && !peer.is_armed());
    assert_eq!(
        (peer.mav_type, peer.custom_mode, peer.mavlink_version),
        (MavType::QUADROTOR, 0x0004_0000, 3)
    );
    // The vehicle sees the ground station, which is no autopilot.
    let vehicle_saw = events(&mut p.b);
    assert!(
        matches!(vehicle_saw[0], HeartbeatEvent::New(gcs) if gcs.address == GCS && !gcs.is_autopilot())
    );
    // It arms: a change.
    p.b.set_own(Some(Heartbeat {
        base_mode: MavModeFlag(MavModeFlag::CUSTOM_MODE_ENABLED.0 | MavModeFlag::SAFETY_ARMED.0),
        system_status: MavState::ACTIVE,
        ..quad()
    }));
    p.drive_for(Duration::from_secs(5));
    let changed = events(&mut p.a);
    assert!(
        matches!(changed.as_slice(), [HeartbeatEvent::Changed(x)] if x.is_armed() && x.system_status == MavState::ACTIVE),
        "{changed:?}"
    );
    // It goes silent: lost after the 5 s timeout.
    p.b.set_own(None);
    let silent_from = p.now;
    let mut lost_at = None;
    p.drive_until(Duration::from_secs(10), |a, _, now| {
        if events(a).contains(&HeartbeatEvent::Lost(VEHICLE)) {
            lost_at = Some(now);
        }
        lost_at.is_some()
    });
    let after = lost_at.unwrap() - silent_from;
    assert!(
        after > Duration::from_secs(3) && after <= Duration::from_millis(5_030),
        "{after:?}"
    );
    assert_eq!(p.a.peers().count(), 0);
}

#[test]
fn own_heartbeat_keeps_a_1_hz_cadence() {
    let mut v = vehicle();
    let t0 = util::T0;
    let mut sent = vec![];
    let mut now = t0;
    while now < t0 + Duration::from_millis(9_999) {
        v.handle_timeout(now);
        while let Some(o) = v.poll_transmit() {
            assert_eq!(o.target, Address::BROADCAST);
            sent.push(now);
        }
        now = v.poll_timeout().unwrap();
    }
    assert_eq!(sent.len(), 10);
    assert!(
        sent.windows(2)
            .all(|w| w[1] - w[0] == Duration::from_secs(1))
    );
}

#[test]
fn frame_version_is_recorded_when_given() {
    let mut g = Heartbeats::new(HeartbeatConfig::default());
    g.handle_heartbeat(util::T0, VEHICLE, &quad(), Some(1));
    g.handle_heartbeat(util::T0, VEHICLE, &quad(), Some(2));
    let e = events(&mut g);
    assert!(
        matches!(e.as_slice(), [HeartbeatEvent::New(a), HeartbeatEvent::Changed(b)] if a.frame_version == Some(1) && b.frame_version == Some(2))
    );
    assert_eq!(g.peer(VEHICLE).unwrap().frame_version, Some(2));
    // AUTOPILOT_VERSION adds capabilities; they survive later heartbeats.
    assert_eq!(g.peer(VEHICLE).unwrap().supports_mavlink2(), None);
    let version = AutopilotVersion {
        capabilities: MavProtocolCapability(
            MavProtocolCapability::MAVLINK2.0 | MavProtocolCapability::PARAM_ENCODE_BYTEWISE.0,
        ),
        flight_sw_version: 0x010E_0300,
        ..Default::default()
    };
    assert!(g.handle_message(util::T0, VEHICLE, &MavMessage::AutopilotVersion(version)));
    assert!(!g.handle_message(
        util::T0,
        Address::new(9, 1),
        &MavMessage::AutopilotVersion(version)
    ));
    g.handle_heartbeat(util::T0, VEHICLE, &quad(), Some(2));
    let p = g.peer(VEHICLE).unwrap();
    assert_eq!(
        (p.supports_mavlink2(), p.flight_sw_version),
        (Some(true), Some(0x010E_0300))
    );
    assert_eq!(
        mavstack_services::param::Encoding::from_capabilities(p.capabilities.unwrap().0),
        Some(mavstack_services::param::Encoding::Bytewise)
    );
    assert!(matches!(
        events(&mut g).as_slice(),
        [HeartbeatEvent::Changed(_)]
    ));
    // No own heartbeat configured: only the peer's timeout is a deadline.
    assert_eq!(g.poll_timeout(), Some(util::T0 + Duration::from_secs(3)));
}
