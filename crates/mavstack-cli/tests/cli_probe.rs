//! `mavstack probe --key` against `mavstack vehicle --sign-key`: with the key the probe runs
//! the handshake over the signed link; with another key it finds no system (every frame it
//! gets fails verification). pymavlink's side of signing is in `interop_versions.rs`.

use crate::vehicle;

use std::process::{Command, Output};

use vehicle::Vehicle;

const KEY: &str = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";
const OTHER: &str = "1111111111111111111111111111111111111111111111111111111111111111";

fn probe(port: u16, key: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args([
            "probe",
            &format!("udpout:127.0.0.1:{port}"),
            "--timeout",
            "3",
        ])
        .args(["--key", key])
        .output()
        .expect("probe runs")
}

#[test]
fn probe_with_the_key_handshakes_with_a_signing_vehicle_and_without_it_finds_nothing() {
    let vehicle = Vehicle::start(&["--sign-key", KEY]);
    let port = vehicle.port;
    let out = probe(port, KEY);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "probe failed: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_str(text.trim()).expect("one JSON line");
    assert_eq!(
        report["handshake"]["result"], "protocol_version",
        "{report}"
    );
    assert_eq!(report["signed"], true, "{report}");
    assert_eq!(report["mavlink2_capability"], true, "{report}");
    assert_eq!(
        (
            report["version_before"].as_u64(),
            report["version_after"].as_u64()
        ),
        (Some(2), Some(2))
    );

    let out = probe(port, OTHER);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("no system found"));
}
