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

use crate::pymavlink_dialect;
use crate::support;

use std::ffi::OsStr;

use support::{require_pymavlink, run_script};

/// Runs one scenario (panics with its output if the script fails); its output, or why it
/// did not end in "ok".
fn scenario(name: &str) -> Result<String, String> {
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "conform_interop.py",
        &[OsStr::new(name), OsStr::new("--mavstack"), OsStr::new(bin)],
    );
    // "<name>: ... ok", the report card (for real ground stations) on the lines between.
    if out.lines().any(|l| l.starts_with(&format!("{name}: "))) && out.trim_end().ends_with(" ok") {
        Ok(out)
    } else {
        Err(format!("{name}: {out}"))
    }
}

/// Runs `names`, `at_once` at a time (each mostly waits on its peers' timers), and fails
/// with every failing scenario's output.
fn scenarios(names: &[&'static str], at_once: usize) {
    require_pymavlink();
    pymavlink_dialect::dialect_ready();
    let mut failures = Vec::new();
    for batch in names.chunks(at_once) {
        let runs: Vec<_> = batch
            .iter()
            .map(|&name| (name, std::thread::spawn(move || scenario(name))))
            .collect();
        for (name, run) in runs {
            match run.join() {
                // The report cards of real ground stations go to the test log (and the README).
                Ok(Ok(out)) => println!("{out}"),
                Ok(Err(e)) => failures.push(e),
                Err(panic) => failures.push(
                    panic
                        .downcast_ref::<String>()
                        .cloned()
                        .unwrap_or_else(|| format!("{name}: the scenario failed")),
                ),
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn planted_deviations_each_fail_their_rule_and_conforming_vehicles_pass() {
    scenarios(
        &[
            "vehicle_good",
            "vehicle_v1_protocol_version",
            "vehicle_flag_never_switches",
            "vehicle_v1_after_switch",
            "vehicle_untruncated",
            "vehicle_silent_v1_only",
            "vehicle_nack_v1_only",
            "vehicle_refuses_like_ardupilot",
            "vehicle_seq_gaps",
            "vehicle_signed_late",
            "vehicle_signed_good",
        ],
        4,
    );
}

#[test]
fn a_radio_keeping_mavlink1_fails_the_radio_rule_and_mavstack_radio_passes() {
    scenarios(&["radio_keeps_v1", "radio_mavstack"], 2);
}

#[test]
fn pymavlink_ground_stations_right_and_wrong() {
    scenarios(
        &[
            "gcs_pymavlink_good",
            "gcs_pymavlink_v1_request",
            "gcs_pymavlink_mixing",
            "gcs_pymavlink_fallback",
            "gcs_pymavlink_gives_up",
        ],
        5,
    );
}

#[test]
fn mavproxy_and_mavsdk_as_ground_stations_get_report_cards() {
    scenarios(&["gcs_mavproxy", "gcs_mavsdk"], 2);
}
