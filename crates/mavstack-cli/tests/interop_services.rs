//! `mavstack vehicle` as pymavlink 2.4.50's mavutil ground station sees it (issue 6, "How it
//! is checked"): parameters, waypoints, commands, message intervals and a flown mission, over
//! loopback UDP.
//!
//! Each test runs one scenario of `tests-interop/gcs_pymavlink.py`, which starts the vehicle
//! and plays the ground station with pymavlink's own ardupilotmega dialect in MAVLink 2:
//!
//! - `params`, `params_px4`: a 60-parameter file served whole (count, index, name, type and
//!   value as pymavlink decodes them: C-cast for ArduPilot, bytewise for PX4), read by name
//!   and index, set and read back;
//! - `waypoints`: a 12-item mission through pymavlink's `MAVWPLoader`, a 4-item fence, both
//!   downloaded field by field, MISSION_SET_CURRENT, MISSION_CLEAR_ALL;
//! - `commands`: arm, DO_SET_MODE, take-off with a deduplicated retry, disarm refused in the
//!   air, an unsupported command, land and disarm;
//! - `intervals`: SET_MESSAGE_INTERVAL with the rate measured, MESSAGE_INTERVAL, turning a
//!   stream off, REQUEST_MESSAGE(HOME_POSITION), REQUEST_DATA_STREAM;
//! - `clock`: the time fields count from the vehicle's start (ATTITUDE and
//!   GLOBAL_POSITION_INT `time_boot_ms` below the milliseconds it has run and rising,
//!   GPS_RAW_INT `time_usec`, the TIMESYNC answer's `tc1`), both flavours;
//! - `mission`: a PX4-flavoured vehicle flies an uploaded mission (items reached in order,
//!   lands at the last waypoint, disarms, battery drained);
//! - `cli_*`: our ground-station commands against a pymavlink vehicle, clean and lossy.
//!
//! Never skipped: without pymavlink 2.4.50 they fail.

use crate::support;

use std::ffi::OsStr;

use support::{require_pymavlink, run_script};

fn scenario(name: &str) {
    require_pymavlink();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "gcs_pymavlink.py",
        &[OsStr::new(name), OsStr::new("--mavstack"), OsStr::new(bin)],
    );
    assert!(
        out.lines()
            .any(|l| l.starts_with(name) && l.ends_with(" ok")),
        "{out}"
    );
}

#[test]
fn params_ardupilot() {
    scenario("params");
}

#[test]
fn params_px4() {
    scenario("params_px4");
}

#[test]
fn waypoints() {
    scenario("waypoints");
}

#[test]
fn commands() {
    scenario("commands");
}

#[test]
fn intervals() {
    scenario("intervals");
}

/// Issue 39: the vehicle sent `time_boot_ms` 4294967295 in every frame (it read the
/// transport's Unix-epoch clock as its time since boot).
#[test]
fn time_fields_count_from_the_vehicles_start() {
    scenario("clock");
}

#[test]
fn mission_flight() {
    scenario("mission");
}

// The other way round: `mavstack param|mission|command` against a vehicle written with
// pymavlink alone (tests-interop/gcs_pymavlink.py, PymavlinkVehicle), plans written and read
// back by pymavlink's MAVWPLoader; then with that vehicle losing 20 % each way.

#[test]
fn cli_params_against_a_pymavlink_vehicle() {
    scenario("cli_params");
}

#[test]
fn cli_mission_and_command_against_a_pymavlink_vehicle() {
    scenario("cli_mission");
}

#[test]
fn cli_params_against_a_lossy_pymavlink_vehicle() {
    scenario("cli_params_lossy");
}

#[test]
fn cli_mission_against_a_lossy_pymavlink_vehicle() {
    scenario("cli_mission_lossy");
}
