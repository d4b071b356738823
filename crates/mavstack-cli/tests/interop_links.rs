//! `mavstack listen`, `record` and `replay` over real sockets on 127.0.0.1, with pymavlink
//! 2.4.50's `mavutil` (the peer every MAVLink user knows) on the other end.
//!
//! Each test runs one scenario of `tests-interop/link_interop.py`, which starts the mavstack
//! command, drives mavutil against it and compares with what pymavlink sent or decoded itself:
//! frames byte for byte, decoded fields as `compare_decode.py` does, tlog timestamps to the
//! microsecond (also through pymavlink's `mavlogdump.py`). Never skipped: without pymavlink
//! 2.4.50 they fail.

use crate::support;

use std::ffi::OsStr;

use support::{require_pymavlink, run_script};

fn scenario(name: &str) {
    require_pymavlink();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "link_interop.py",
        &[OsStr::new(name), OsStr::new("--mavstack"), OsStr::new(bin)],
    );
    assert!(out.contains("all equal"), "{name}: {out}");
}

#[test]
fn pymavlink_udpout_to_listen_udpin() {
    scenario("udp_listen");
}

#[test]
fn replay_udpout_to_pymavlink_udpin() {
    scenario("udp_replay");
}

#[test]
fn udpin_answers_pymavlink_at_its_own_address() {
    scenario("udpin_reply");
}

#[test]
fn pymavlink_tcpin_to_listen_tcp() {
    scenario("tcp_listen");
}

#[test]
fn replay_tcpin_to_pymavlink_tcp() {
    scenario("tcp_replay");
}

#[test]
fn record_is_read_by_pymavlink_and_mavlogdump() {
    scenario("record_tlog");
}

#[test]
fn pymavlink_tlog_decodes_and_replays() {
    scenario("pymavlink_tlog");
}
