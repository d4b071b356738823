//! A udpin link of `mavstack router` under a flood of new sources (`docs/contracts/link-options.md`,
//! `max_peers`): `tests-interop/router_flood.py` sends 5,000 datagrams, each from a source
//! port of its own, half garbage and half HEARTBEATs packed by pymavlink, to a link with
//! `max_peers=16`; the router's stats must show at most 16 peers on it, the garbage counted as
//! `not_mavlink` and the refused sources as `peer_refused`; then a pymavlink ground station
//! from a new port fetches every parameter of `mavstack vehicle` through the router, and the
//! router exits 0 on SIGTERM. Never skipped: without pymavlink the test fails.

use crate::support;

use std::ffi::OsStr;

use support::{require_pymavlink, run_script};

#[test]
fn a_flood_of_new_sources_leaves_at_most_max_peers_and_a_ground_station_still_gets_in() {
    require_pymavlink();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "router_flood.py",
        &[
            OsStr::new("--max-peers"),
            OsStr::new("16"),
            OsStr::new("--datagrams"),
            OsStr::new("5000"),
            OsStr::new("--mavstack"),
            OsStr::new(bin),
        ],
    );
    assert!(
        out.starts_with("router_flood: ") && out.trim_end().ends_with(" ok"),
        "{out}"
    );
}
