//! The ground station's side: when it switches to MAVLink 2 (a MAVLink 2 frame, the
//! capability bit; never the HEARTBEAT's `mavlink_version`), one version per link.

use mavstack_channel::{Channel, GroundPolicy, LinkVersion, SwitchCause, VehicleVersion};
use mavstack_core::wire::Version;
use mavstack_dialects::common::{AutopilotVersion, Heartbeat, MavProtocolCapability};

use super::util::{Origin, Pair, T0, feed, frame};
use super::{gcs, vehicle, version_changes};

#[test]
fn gcs_switches_on_first_mavlink2_frame() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::Mavlink2),
        gcs(GroundPolicy::Automatic),
    );
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink1);
    p.vehicle_send(&Heartbeat::default());
    p.drive();
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
    assert_eq!(
        version_changes(&p.gcs_events),
        [(
            LinkVersion::Mavlink1,
            LinkVersion::Mavlink2,
            SwitchCause::Mavlink2Received
        )]
    );
}

#[test]
fn gcs_switches_on_autopilot_version_capability_flag() {
    let mut p = Pair::default_pair();
    let caps = p.vehicle.capabilities() | MavProtocolCapability::MISSION_INT;
    p.vehicle_send(&AutopilotVersion {
        capabilities: caps,
        ..AutopilotVersion::default()
    });
    p.drive();
    assert!(!p.sent_by(Origin::Vehicle)[0].is_v2(), "sent in MAVLink 1");
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
    assert_eq!(
        version_changes(&p.gcs_events),
        [(
            LinkVersion::Mavlink1,
            LinkVersion::Mavlink2,
            SwitchCause::CapabilityFlag
        )]
    );
}

#[test]
fn gcs_ignores_autopilot_version_without_capability_flag() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::Mavlink1Only),
        gcs(GroundPolicy::Automatic),
    );
    p.vehicle_send(&AutopilotVersion {
        capabilities: p.vehicle.capabilities() | MavProtocolCapability(32768),
        ..AutopilotVersion::default()
    });
    p.drive();
    assert_eq!(
        p.gcs.version(),
        LinkVersion::Mavlink1,
        "32768 is MISSION_RALLY, not MAVLINK2"
    );
}

#[test]
fn heartbeat_mavlink_version_field_does_not_decide_the_version() {
    // HEARTBEAT.mavlink_version is the XML minor version (3), not "1 or 2".
    let mut g = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    let hb = Heartbeat {
        mavlink_version: 3,
        ..Heartbeat::default()
    };
    let _ = feed(&mut g, T0, &frame(Version::V1, 0, 1, 1, &hb));
    assert_eq!(g.version(), LinkVersion::Mavlink1);
}

#[test]
fn gcs_configured_mavlink2_sends_mavlink2_from_the_start() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::StartMavlink1),
        gcs(GroundPolicy::Mavlink2),
    );
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
    p.gcs_send(&Heartbeat::default());
    assert!(p.sent_by(Origin::Gcs)[0].is_v2());
}

#[test]
fn version_is_per_link_not_global() {
    let mut a = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    let b = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    let _ = feed(
        &mut a,
        T0,
        &frame(Version::V2, 0, 1, 1, &Heartbeat::default()),
    );
    assert_eq!(
        (a.version(), b.version()),
        (LinkVersion::Mavlink2, LinkVersion::Mavlink1)
    );
}
