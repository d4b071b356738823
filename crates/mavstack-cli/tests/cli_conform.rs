//! `mavstack conform` against `mavstack vehicle` in every mode: our vehicle conforms (no
//! must or should rule fails, exit 0), `--no-protocol-version` is graded as what it is (the
//! handshake unanswered: exit 1), and on a vehicle with three links each link is graded by
//! its own version and signing. The planted deviations, MAVProxy and MAVSDK as ground
//! stations and the radios are in `interop_conform.rs` (pymavlink peers).

use crate::ends;
use crate::vehicle;

use std::net::UdpSocket;
use std::process::{Command, Output};

use serde_json::Value;
use vehicle::Vehicle;

const KEY: &str = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";

/// Runs conform against `port`; it must end by itself (its waits are bounded by its own
/// deadlines: a run that hangs fails here).
fn conform(port: u16, extra: &[&str]) -> (Output, Value) {
    let out = ends::output_ending_by_itself(
        Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args([
                "conform",
                &format!("udpout:127.0.0.1:{port}"),
                "--json",
                "--timeout",
                "8",
            ])
            .args(extra),
    );
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let report = serde_json::from_str(text.trim()).unwrap_or_else(|e| {
        panic!(
            "conform printed no JSON object ({e}): {text}{}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (out, report)
}

fn status<'a>(report: &'a Value, id: &str) -> &'a str {
    report["rules"]
        .as_array()
        .and_then(|rules| rules.iter().find(|r| r["id"] == id))
        .and_then(|r| r["status"].as_str())
        .unwrap_or_else(|| panic!("no rule {id} in {report}"))
}

/// The `must` and `should` rules that failed, with their evidence (`info` rules are
/// reported, never graded).
fn failed(report: &Value) -> Vec<String> {
    report["rules"]
        .as_array()
        .map(|rules| {
            rules
                .iter()
                .filter(|r| r["status"] == "fail" && r["level"] != "info")
                .map(|r| format!("{}: {}", r["id"], r["evidence"]))
                .collect()
        })
        .unwrap_or_default()
}

fn assert_conforms(mode: &[&str], conform_extra: &[&str], passes: &[&str], na: &[&str]) {
    let vehicle = Vehicle::start(mode);
    let (out, report) = conform(vehicle.port, conform_extra);
    assert!(
        out.status.success() && failed(&report).is_empty(),
        "vehicle {mode:?}: exit {}, failed {:?}",
        out.status,
        failed(&report)
    );
    assert_eq!(report["role"], "vehicle");
    assert_eq!(report["target"]["sysid"], 1);
    assert_eq!(report["rules"].as_array().map(Vec::len), Some(16));
    for id in passes {
        assert_eq!(
            status(&report, id),
            "pass",
            "vehicle {mode:?}, {id}: {report}"
        );
    }
    for id in na {
        assert_eq!(
            status(&report, id),
            "n/a",
            "vehicle {mode:?}, {id}: {report}"
        );
    }
    // The run ended by itself (`conform` above) and says how long it took.
    assert!(
        report["seconds"].as_f64().is_some_and(f64::is_finite),
        "vehicle {mode:?}: {report}"
    );
}

#[test]
fn the_default_vehicle_conforms() {
    assert_conforms(
        &[],
        &[],
        &[
            "heartbeat",
            "crc",
            "sequence",
            "truncation",
            "capability_flag",
            "switch_on_v2",
            "handshake_answer",
            "protocol_version_supported",
            "handshake_v2_framing",
            "handshake_519",
            "handshake_command_int",
            "protocol_version_values",
            "no_mixing",
        ],
        &[
            "nack_without_v2",
            "signed_from_start",
            "radio_v2_after_first_v2",
        ],
    );
}

#[test]
fn a_vehicle_that_starts_in_mavlink2_conforms() {
    assert_conforms(
        &["--start-mavlink2"],
        &[],
        &[
            "handshake_answer",
            "handshake_v2_framing",
            "no_mixing",
            "capability_flag",
        ],
        &["switch_on_v2", "nack_without_v2"],
    );
}

#[test]
fn a_mavlink1_only_vehicle_conforms_by_nacking() {
    assert_conforms(
        &["--mavlink1-only"],
        &[],
        &[
            "nack_without_v2",
            "capability_flag",
            "handshake_519",
            "handshake_command_int",
        ],
        &["handshake_answer", "switch_on_v2", "truncation"],
    );
}

#[test]
fn a_signing_vehicle_conforms_with_the_key() {
    assert_conforms(
        &["--sign-key", KEY],
        &["--key", KEY],
        &["signed_from_start", "handshake_answer", "no_mixing"],
        &["switch_on_v2"],
    );
}

#[test]
fn a_vehicle_that_refuses_protocol_version_like_ardupilot_conforms_by_the_fallback() {
    assert_conforms(
        &["--protocol-version", "refuse", "--start-mavlink2"],
        &[],
        &[
            "handshake_answer",
            "handshake_519",
            "handshake_command_int",
            "capability_flag",
            "no_mixing",
        ],
        &[
            "handshake_v2_framing",
            "protocol_version_values",
            "nack_without_v2",
        ],
    );
    let vehicle = Vehicle::start(&["--protocol-version", "refuse", "--start-mavlink2"]);
    let (_, report) = conform(vehicle.port, &[]);
    let rule = |id: &str| {
        report["rules"]
            .as_array()
            .and_then(|r| r.iter().find(|r| r["id"] == id))
            .cloned()
            .unwrap_or_default()
    };
    let answer = rule("handshake_answer");
    let evidence = answer["evidence"].as_str().unwrap_or_default();
    assert!(
        evidence.contains("COMMAND_ACK FAILED") && evidence.contains("the documents' fallback"),
        "{evidence}"
    );
    let supported = rule("protocol_version_supported");
    assert_eq!(
        (&supported["level"], &supported["status"]),
        (&"info".into(), &"fail".into())
    );
    assert_eq!(rule("handshake_519")["level"], "info");
}

#[test]
fn no_protocol_version_is_graded_as_an_unanswered_handshake() {
    let vehicle = Vehicle::start(&["--no-protocol-version"]);
    let (out, report) = conform(vehicle.port, &[]);
    assert_eq!(out.status.code(), Some(1), "{report}");
    assert_eq!(status(&report, "handshake_answer"), "fail");
    assert_eq!(
        status(&report, "capability_flag"),
        "pass",
        "it does switch: {report}"
    );
    assert_eq!(status(&report, "switch_on_v2"), "pass");
    let evidence = report["rules"]
        .as_array()
        .and_then(|r| r.iter().find(|r| r["id"] == "handshake_answer"))
        .and_then(|r| r["evidence"].as_str())
        .unwrap_or_default()
        .to_owned();
    assert!(evidence.contains("REQUEST_MESSAGE(300)"), "{evidence}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("handshake_answer"));
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port()
}

#[test]
fn each_link_of_a_multilink_vehicle_is_graded_by_its_own_version_and_signing() {
    let (v1, signed) = (free_port(), free_port());
    let vehicle = Vehicle::start(&[
        &format!("udpin:127.0.0.1:{v1}?version=1"),
        &format!("udpin:127.0.0.1:{signed}?key={KEY}"),
    ]);
    let auto = vehicle.port;
    let runs = [
        (auto, Vec::<&str>::new()),
        (v1, Vec::new()),
        (signed, vec!["--key", KEY]),
    ]
    .map(|(port, extra)| std::thread::spawn(move || conform(port, &extra)));
    let [auto, v1, signed] = runs.map(|r| r.join().expect("conform ran"));
    for (what, (out, report)) in [("auto", &auto), ("version=1", &v1), ("key", &signed)] {
        assert!(
            out.status.success(),
            "{what} link: failed {:?}",
            failed(report)
        );
    }
    assert_eq!(status(&auto.1, "switch_on_v2"), "pass");
    assert_eq!(status(&auto.1, "handshake_answer"), "pass");
    assert_eq!(status(&v1.1, "nack_without_v2"), "pass");
    assert_eq!(status(&v1.1, "handshake_answer"), "n/a");
    assert_eq!(status(&signed.1, "signed_from_start"), "pass");
}

#[test]
fn bad_usage_exits_2_naming_what() {
    for (args, what) in [
        (vec!["udpin:127.0.0.1:0", "--key", "zz"], "--key"),
        (vec!["nonsense:1", "--json"], "nonsense"),
        (vec!["udpin:127.0.0.1:0", "--role", "pilot"], "pilot"),
        (
            vec!["udpin:127.0.0.1:0", "--role", "gcs", "--key", KEY],
            "--role gcs",
        ),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .arg("conform")
            .args(&args)
            .output()
            .expect("conform runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(what), "{args:?}: {err}");
    }
}

#[test]
fn nobody_heard_exits_1_with_heartbeat_failed() {
    let port = free_port();
    let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args([
            "conform",
            &format!("udpin:127.0.0.1:{port}"),
            "--timeout",
            "0.5",
            "--json",
        ])
        .output()
        .expect("conform runs");
    assert_eq!(out.status.code(), Some(1));
    let report: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(report["target"], Value::Null);
    assert_eq!(status(&report, "heartbeat"), "fail");
    assert_eq!(report["summary"]["fail"], 1);
    assert_eq!(report["summary"]["n/a"], 15);
}
