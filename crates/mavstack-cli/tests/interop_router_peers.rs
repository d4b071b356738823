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

/// `tests-interop/router_scale.py` in small (the full run, 1,000 peers, is by hand): 40 peers
/// with frames packed by pymavlink on one `udpin` link with `isolate_peers=true` and a ground
/// station on a `udpout` link; every frame reaches the ground station, no peer gets another's,
/// each gets the ground station's HEARTBEATs and its own command only, and `--stats` shows one
/// link, route and system per peer.
#[test]
fn peers_of_an_isolated_link_reach_the_ground_station_and_not_each_other() {
    require_pymavlink();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let args = [
        "--peers",
        "40",
        "--rate",
        "10",
        "--seconds",
        "4",
        "--procs",
        "2",
        "--mavstack",
        bin,
    ];
    let out = run_script(
        "router_scale.py",
        &args.iter().map(OsStr::new).collect::<Vec<_>>(),
    );
    assert!(out.trim_end().ends_with("ok"), "{out}");
}
