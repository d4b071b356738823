//! Real ground-station software from PyPI against `mavstack vehicle` over loopback UDP.
//!
//! Each test runs one script of `tests-interop/` with the Python that `scripts/setup-peers.sh`
//! prepares (`$MAVSTACK_PYTHON`, else `.venv/bin/python`), which starts the mavstack binary
//! as the vehicle and drives the client through a whole exchange:
//!
//! - `gcs_mavproxy.py`: MAVProxy 1.8.75, headless in a pseudo-terminal: parameter fetch
//!   (count = the vehicle's param_count, the `--params` file's values), set and read back,
//!   mission download, upload of a QGC WPL 110 file and download again (compared), arm, and
//!   `signing setup` on a `--secure` vehicle followed by a fetch that only signed frames can
//!   complete (and every vehicle frame in MAVProxy's log signed with its key);
//! - `gcs_mavproxy.py --bench 1000 500 --loss 0`: MAVProxy fetches the 1,000 parameters of a
//!   generated `--params` file (every value compared) and uploads and downloads a 500-item
//!   mission (compared), with timings;
//! - `gcs_mavsdk.py --api native`: MAVSDK's native Python binding `mavsdk` 4.1.0 (ctypes over
//!   libcmavsdk);
//! - `gcs_mavsdk.py --api grpc`: `mavsdk-grpc` 4.0.5 with its bundled `mavsdk_server`;
//!   both against `--autopilot px4`: connect, telemetry (position at home, battery, armed,
//!   flight mode), parameters (all / get / set), mission upload and download, arm, takeoff
//!   and land, inside a network namespace of their own (`unshare -n`) because mavsdk_server
//!   listens for gRPC on every interface.
//!
//! Never skipped: a client that is not installed fails the test. The scenarios run one at a
//! time (they time a flying vehicle against the wall clock).
//!
//! The same ground stations against `mavstack vehicle` THROUGH `mavstack router`
//! (`docs/contracts/router.md`, `link-options.md`): the scenarios above, each script run
//! with `--via-router`, which starts the router between the two (the vehicle on the router's
//! `udpin:...?name=vehicle` link, the ground station on its `udpout:...?name=gcs` link),
//! SIGTERMs it at the end (exit 0 required) and checks its stats (both links carried frames,
//! nothing dropped for lack of a route or conversion):
//!
//! - `gcs_mavproxy.py --via-router`: MAVProxy 1.8.75: parameter fetch, set and read back,
//!   mission download, upload of a QGC WPL 110 file and download again (compared), arm and
//!   disarm; then a second MAVProxy on the router's signed link (`key=`, the vehicle link
//!   `trusted=true`): its unsigned frames dropped before it has the key, then a full fetch
//!   with `allow_unsigned 0` and every vehicle frame in its log signed by the router with the
//!   key; then a MAVLink 1 hop: a `--mavlink1-only` vehicle on a `version=1` router link,
//!   MAVProxy on a plain one: fetch, set, mission and arm/disarm through the conversion;
//! - `gcs_mavsdk.py --api native --via-router` and `--api grpc --via-router`: MAVSDK's native
//!   binding `mavsdk` 4.1.0 and `mavsdk-grpc` 4.0.5 with `mavsdk_server`, `--autopilot px4`:
//!   connect, telemetry, parameters, mission upload and download, arm, takeoff and land, with
//!   the router inside the script's own network namespace (`unshare -n`) next to the vehicle
//!   and mavsdk_server.
//!
//! And across an MQTT broker: `gcs_mavproxy.py --via-broker` (see its test).

use crate::support;

use std::ffi::OsStr;
use std::process::Command;
use std::sync::{Mutex, OnceLock};

use support::{python, require_pymavlink, run_script, text};

/// The ground stations and their pinned releases (scripts/setup-peers.sh installs them).
const CLIENTS: [(&str, &str); 3] = [
    ("MAVProxy", "1.8.75"),
    ("mavsdk", "4.1.0"),
    ("mavsdk-grpc", "4.0.5"),
];

/// Fails (never skips) unless every client is installed at its pinned version; checked once.
fn require_clients() {
    static CHECKED: OnceLock<Result<(), String>> = OnceLock::new();
    let checked = CHECKED.get_or_init(|| {
        let probe = "import sys; from importlib.metadata import version; \
                     import pexpect, mavsdk, mavsdk_grpc; \
                     print(' '.join(n + '==' + version(n) for n in sys.argv[1:]))";
        let names: Vec<&str> = CLIENTS.iter().map(|(n, _)| *n).collect();
        let py = python();
        let out = Command::new(&py)
            .args(["-c", probe])
            .args(&names)
            .output()
            .map_err(|e| format!("cannot run python {}: {e}", py.display()))?;
        if !out.status.success() {
            return Err(format!(
                "python {} lacks a ground station: {}",
                py.display(),
                text(&out.stderr).trim()
            ));
        }
        let want: Vec<String> = CLIENTS.iter().map(|(n, v)| format!("{n}=={v}")).collect();
        let have = text(&out.stdout).trim().to_owned();
        if have != want.join(" ") {
            return Err(format!(
                "python {} has {have}, want {}",
                py.display(),
                want.join(" ")
            ));
        }
        Ok(())
    });
    if let Err(e) = checked {
        panic!("ground-station interop needs the clients (run scripts/setup-peers.sh): {e}");
    }
}

fn run(name: &str, args: &[&str]) -> String {
    run_with(name, args, false)
}

/// Runs a scenario with `--via-router` when `via_router`: the summary must then carry the
/// router's stats too.
fn run_with(name: &str, args: &[&str], via_router: bool) -> String {
    static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    require_pymavlink();
    require_clients();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let mut all: Vec<&OsStr> = args.iter().map(OsStr::new).collect();
    if via_router {
        all.push(OsStr::new("--via-router"));
    }
    all.extend([OsStr::new("--mavstack"), OsStr::new(bin)]);
    let out = run_script(name, &all);
    let last = out.lines().last().unwrap_or_default();
    assert!(
        last.starts_with('{')
            && last.contains("\"ok\": true")
            && (!via_router || last.contains("\"router\"")),
        "{name} {args:?} (via router: {via_router}): no success summary:\n{out}"
    );
    println!("{last}");
    out
}

#[test]
fn mavproxy_params_missions_arm_and_signing() {
    run("gcs_mavproxy.py", &[]);
}

#[test]
fn mavproxy_fetches_1000_parameters_from_a_file_and_moves_a_500_item_mission() {
    run(
        "gcs_mavproxy.py",
        &["--bench", "1000", "500", "--loss", "0"],
    );
}

#[test]
fn mavsdk_native_binding_flies_a_session() {
    run("gcs_mavsdk.py", &["--api", "native"]);
}

#[test]
fn mavsdk_grpc_with_mavsdk_server_flies_a_session() {
    run("gcs_mavsdk.py", &["--api", "grpc"]);
}

#[test]
fn mavproxy_params_mission_arm_signed_link_and_mavlink1_hop_through_the_router() {
    run_with("gcs_mavproxy.py", &[], true);
}

/// Across an MQTT broker (mosquitto): the vehicle's router bridges its network onto
/// `mqtt://...?fleet=interop&vid=truck-1`, a ground router subscribed to the fleet (`vid=*`)
/// serves MAVProxy on UDP: parameter fetch, set and read back, mission download, upload and
/// download again, arm and disarm (`docs/contracts/fleet-keys.md`).
#[test]
fn mavproxy_params_mission_and_arm_across_an_mqtt_broker() {
    let out = run("gcs_mavproxy.py", &["--via-broker"]);
    let last = out.lines().last().unwrap_or_default();
    assert!(
        last.contains("\"ground_router\"") && last.contains("\"vehicle_router\""),
        "no router stats in the summary: {last}"
    );
}

#[test]
fn mavsdk_native_binding_flies_a_session_through_the_router() {
    run_with("gcs_mavsdk.py", &["--api", "native"], true);
}

#[test]
fn mavsdk_grpc_with_mavsdk_server_flies_a_session_through_the_router() {
    run_with("gcs_mavsdk.py", &["--api", "grpc"], true);
}

/// MAVSDK's Action and Offboard (native binding) fly the simulator's PX4 flavour as they fly
/// PX4 1.16 SITL: the same answers and flight modes, step by step, as the transcript recorded
/// from PX4 SITL (`tests-interop/fixtures/mavsdk_flying_px4.json`; `mavsdk_flying.py`).
#[test]
fn mavsdk_action_and_offboard_fly_the_px4_flavour_as_px4_sitl() {
    static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());
    let _turn = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    require_pymavlink();
    require_clients();
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port();
    let mut vehicle = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args([
            "vehicle",
            &format!("udpout:127.0.0.1:{port}"),
            "--autopilot",
            "px4",
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("the vehicle starts");
    let fixture = support::script("fixtures/mavsdk_flying_px4.json");
    let url = format!("udpin://127.0.0.1:{port}");
    let out = std::panic::catch_unwind(|| {
        run_script(
            "mavsdk_flying.py",
            &[
                OsStr::new(&url),
                OsStr::new("--expect"),
                fixture.as_os_str(),
            ],
        )
    });
    let _ = vehicle.kill();
    let _ = vehicle.wait();
    let out = out.unwrap_or_else(|e| std::panic::resume_unwind(e));
    println!("{}", out.lines().last().unwrap_or_default());
}
