//! The version rules of the protocol digest (§5, with the framing rules of §1–2 that a link
//! depends on), one named test per rule, over the simulation harness. This file has the
//! configurations and helpers the parts share; the rules are in `versions/`: `vehicle.rs`,
//! `ground_station.rs`, `handshake.rs` and its `fallback.rs`, `golden.rs` (the digest's
//! vectors), `framing.rs`.

mod util;

#[path = "versions/fallback.rs"]
mod fallback;
#[path = "versions/framing.rs"]
mod framing;
#[path = "versions/golden.rs"]
mod golden;
#[path = "versions/ground_station.rs"]
mod ground_station;
#[path = "versions/handshake.rs"]
mod handshake;
#[path = "versions/vehicle.rs"]
mod vehicle;

use mavstack_channel::{
    CommandEncoding, Config, Event, GroundPolicy, HandshakeMethod, HandshakeResult, LinkVersion,
    Role, SwitchCause, Target, VehicleVersion,
};
use util::Pair;

fn vehicle(version: VehicleVersion) -> Config {
    let mut c = Config::vehicle(1, 1);
    c.vehicle_policy_mut().unwrap().version = version;
    c
}

fn silent_vehicle(version: VehicleVersion) -> Config {
    let mut c = vehicle(version);
    c.vehicle_policy_mut().unwrap().protocol_version = None;
    c
}

fn gcs(policy: GroundPolicy) -> Config {
    let mut c = Config::ground_station(255, 190);
    c.role = Role::GroundStation(policy);
    c
}

/// A ground station that takes a refusal or silence as the outcome (no fallback request for
/// AUTOPILOT_VERSION): what the first phase does on its own.
fn gcs_without_fallback(policy: GroundPolicy) -> Config {
    let mut c = gcs(policy);
    c.handshake.fallback = None;
    c
}

fn start(p: &mut Pair, method: HandshakeMethod, encoding: CommandEncoding) {
    p.gcs
        .start_handshake(p.now, Target::new(1, 1), method, encoding)
        .unwrap();
}

fn version_changes(events: &[Event]) -> Vec<(LinkVersion, LinkVersion, SwitchCause)> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::VersionChanged { from, to, cause } => Some((*from, *to, *cause)),
            _ => None,
        })
        .collect()
}

fn only_outcome(p: &Pair) -> HandshakeResult {
    let outcomes = p.handshake_outcomes();
    assert_eq!(outcomes.len(), 1, "{outcomes:?}");
    outcomes[0].result
}
