//! The seed corpora of the `router_conf`, `link_options`, `link_spec`, `conform_wire`,
//! `events` and `web_json` fuzz targets, replayed on stable.

use std::path::Path;

fn replay(target: &str, f: fn(&[u8])) {
    for seed in mavstack_core::fuzz_seeds(target, 3) {
        f(&seed);
    }
}

#[test]
fn router_conf_seeds() {
    replay("router_conf", mavstack::router_conf::fuzz_router_conf);
}

#[test]
fn link_options_seeds() {
    replay("link_options", mavstack::router::fuzz_link_options);
}

#[test]
fn link_spec_seeds() {
    replay("link_spec", mavstack::link_spec::fuzz_link_spec);
}

#[cfg(feature = "sim")]
#[test]
fn conform_wire_seeds() {
    replay("conform_wire", mavstack::conform::fuzz_wire);
}

#[cfg(feature = "services")]
#[test]
fn events_seeds() {
    replay("events", mavstack::events::fuzz_events);
    // The seeds reach past the parsers: a catalog of three events, the same one packed.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/events");
    let json = std::fs::read(dir.join("events_json")).unwrap();
    assert_eq!(
        mavstack::events::Catalog::from_json(&json).unwrap().len(),
        3
    );
    for packed in ["events_xz", "events_xz_crc64"] {
        let xz = std::fs::read(dir.join(packed)).unwrap();
        assert_eq!(
            mavstack::events::unpack(&xz).unwrap(),
            json.trim_ascii_end(),
            "{packed}"
        );
    }
}

/// The MAVLink 1 PROTOCOL_VERSION seed (msgid 44, CRC_EXTRA 217, built with pymavlink's
/// x25crc) is read as that bogus frame and graded as a framing failure.
#[cfg(feature = "sim")]
#[test]
fn the_fake_protocol_version_seed_fails_the_framing_rule() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/conform_wire");
    let seed = std::fs::read(dir.join("fake_protocol_version")).unwrap();
    let verdicts = mavstack::conform::fuzz_grade_for_tests(&seed);
    let framing = verdicts
        .iter()
        .find(|v| v.rule == mavstack::conform::Rule::HandshakeV2Framing)
        .unwrap();
    assert_eq!(
        framing.status,
        mavstack::conform::Status::Fail,
        "{framing:?}"
    );
    assert!(
        framing.evidence.contains("msgid 44"),
        "{}",
        framing.evidence
    );
}

#[cfg(feature = "http")]
#[test]
fn web_json_seeds() {
    replay("web_json", mavstack::web::json::fuzz_web_json);
}
