//! `mavstack conform` against independent peers (issue 13, "How it is checked"): each
//! scenario of `tests-interop/conform_interop.py` starts conform and plays the other side.
//!
//! - Vehicle role: vehicles written with pymavlink alone, one per planted deviation, each
//!   breaking one rule (PROTOCOL_VERSION in MAVLink 1 framing, the capability flag set but
//!   never switching, a MAVLink 1 HEARTBEAT after the switch, untruncated payloads, silence
//!   instead of a NACK, skipped sequence numbers, unsigned first frames then signed): exit 1
//!   and that rule failed with evidence; a conforming one, a NACKing MAVLink 1-only one and a
//!   signing one pass. Behind `mavstack radio` the radio rule passes; behind a radio that
//!   keeps RADIO_STATUS in MAVLink 1 it fails.
//! - Ground-station role: pymavlink ground stations that do the handshake right and wrong
//!   (a MAVLink 1 request, mixing after the switch, falling back after a NACK or silence,
//!   giving up), MAVProxy and MAVSDK (native) as they are: their report cards are printed.
//!
//! The expectations come from the rule table and from what each peer does on the wire (the
//! script's self-tests check the peers themselves), never from conform's wording. Never
//! skipped: without pymavlink 2.4.50 (and MAVProxy, MAVSDK from the test venv) they fail.

#[path = "support/pymavlink_dialect.rs"]
mod pymavlink_dialect;
mod support;

use std::ffi::OsStr;

use support::{require_pymavlink, run_script};

fn scenario(name: &str) {
    require_pymavlink();
    pymavlink_dialect::dialect_ready();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "conform_interop.py",
        &[OsStr::new(name), OsStr::new("--mavstack"), OsStr::new(bin)],
    );
    // "<name>: ... ok", the report card (for real ground stations) on the lines between.
    assert!(
        out.lines().any(|l| l.starts_with(&format!("{name}: "))) && out.trim_end().ends_with(" ok"),
        "{name}: {out}"
    );
    // The report cards of real ground stations go to the test log (and the README).
    println!("{out}");
}

macro_rules! scenarios {
    ($($test:ident => $name:literal,)*) => {
        $(
            #[test]
            fn $test() {
                scenario($name);
            }
        )*
    };
}

scenarios! {
    a_conforming_pymavlink_vehicle_passes => "vehicle_good",
    protocol_version_in_mavlink1_framing_fails_handshake_v2_framing => "vehicle_v1_protocol_version",
    a_capability_flag_without_mavlink2_fails_capability_flag => "vehicle_flag_never_switches",
    a_mavlink1_heartbeat_after_the_switch_fails_no_mixing => "vehicle_v1_after_switch",
    untruncated_payloads_fail_truncation => "vehicle_untruncated",
    silence_instead_of_a_nack_fails_nack_without_v2 => "vehicle_silent_v1_only",
    a_nacking_mavlink1_only_vehicle_passes => "vehicle_nack_v1_only",
    skipped_sequence_numbers_fail_sequence => "vehicle_seq_gaps",
    unsigned_first_frames_fail_signed_from_start => "vehicle_signed_late",
    a_vehicle_signing_from_its_first_frame_passes => "vehicle_signed_good",
    a_radio_keeping_radio_status_in_mavlink1_fails_the_radio_rule => "radio_keeps_v1",
    mavstack_radio_passes_the_radio_rule => "radio_mavstack",
    a_right_pymavlink_ground_station_passes => "gcs_pymavlink_good",
    a_mavlink1_handshake_request_fails_gcs_handshake_v2_framing => "gcs_pymavlink_v1_request",
    mixing_after_the_switch_fails_gcs_no_mixing => "gcs_pymavlink_mixing",
    falling_back_after_a_nack_or_silence_passes_gcs_fallback => "gcs_pymavlink_fallback",
    giving_up_after_a_nack_fails_gcs_fallback => "gcs_pymavlink_gives_up",
    mavproxy_as_ground_station_gets_a_report_card => "gcs_mavproxy",
    mavsdk_as_ground_station_gets_a_report_card => "gcs_mavsdk",
}
