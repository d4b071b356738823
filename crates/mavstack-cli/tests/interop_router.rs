//! `mavstack router` between pymavlink 2.4.50 peers over loopback UDP: learned routes,
//! version conversion per link, signing boundaries, stats and exit
//! (`docs/contracts/router.md`, `docs/contracts/link-options.md`).
//!
//! Each test runs one scenario of `tests-interop/router_interop.py`, which starts the router
//! with its own links on free ports and plays every peer with pymavlink: MAVLink 2 peers speak
//! the dialect mavgen generates from our definitions (`mavstack_dialect.py`, PROTOCOL_VERSION
//! included), MAVLink 1-only peers pymavlink's v1.0 module. Every expectation is pymavlink's:
//!
//! - `v1_peer`: a `version=1` link gets only MAVLink 1, each frame pymavlink's MAVLink 1 packing
//!   of the MAVLink 2 sender's base fields with its sysid/compid/seq; ids > 255 never
//!   (`cannot_convert`); the MAVLink 1 peer's frames reach a MAVLink 2 peer's auto link as
//!   MAVLink 2 and a silent auto link byte for byte;
//! - `v2_link`: a `version=2` link gets MAVLink 1 frames as pymavlink's truncated MAVLink 2;
//! - `signing`: `key=` links get only frames pymavlink verifies with the key (the trusted
//!   link's signed by the router, never the untrusted one's); signatures are stripped towards
//!   links without a key; unsigned, forged and replayed frames are dropped;
//! - `targeting`: targeted frames only where the target was seen, unknown targets dropped,
//!   broadcasts everywhere but back, and the mavlink-router #452 echo case;
//! - `handshake`: `mavstack vehicle` behind the router: the MAVLink 2 handshake works through a
//!   plain link (pymavlink and `mavstack probe`) and cannot through a `version=1` link;
//! - `stats_and_exit`: `--stats 1` JSON lines (names, versions, counts), exit 0 on SIGTERM;
//! - `tlog`: `--log DIR` writes every accepted frame, bytes as sent, read back by pymavlink's
//!   own tlog reader with the link number in `msg._link` (MAVProxy's timestamp bits);
//! - `own_heartbeat`: `--heartbeat`: the router's own HEARTBEAT in each link's version and
//!   signing (MAVLink 1 on `version=1`, 1 then 2 on `auto`, signed on `key=`), as pymavlink
//!   reads and verifies it.
//!
//! Never skipped: without pymavlink 2.4.50 they fail.

use crate::pymavlink_dialect;
use crate::support;

fn scenario(name: &str) {
    pymavlink_dialect::dialect_ready();
    support::scenario("router_interop.py", name, env!("CARGO_BIN_EXE_mavstack"));
}

#[test]
fn router_converts_mavlink2_to_a_mavlink1_only_peer() {
    scenario("v1_peer");
}

#[test]
fn router_converts_mavlink1_for_a_version2_link() {
    scenario("v2_link");
}

#[test]
fn router_keeps_signed_links_signed_and_strips_signatures_elsewhere() {
    scenario("signing");
}

#[test]
fn router_routes_by_target_and_survives_an_echo() {
    scenario("targeting");
}

#[test]
fn router_carries_the_mavlink2_handshake_only_where_it_can() {
    scenario("handshake");
}

#[test]
fn router_prints_stats_and_exits_on_sigterm() {
    scenario("stats_and_exit");
}

#[test]
fn router_logs_all_traffic_in_a_tlog_pymavlink_reads() {
    scenario("tlog");
}

#[test]
fn router_sends_its_own_heartbeat_in_each_links_version_and_signing() {
    scenario("own_heartbeat");
}
