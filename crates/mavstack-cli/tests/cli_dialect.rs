//! `mavstack dialect` and `mavstack codegen` as a user runs them.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn mavstack(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(args)
        .output()
        .expect("mavstack runs")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("workspace root")
}

#[test]
fn list_names_every_builtin_dialect() {
    let o = mavstack(&["dialect", "list"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    for name in mavstack_xml::builtin::dialect_names() {
        assert!(
            out.lines()
                .any(|l| l.split_whitespace().next() == Some(name)),
            "{name} missing:\n{out}"
        );
    }
    let common = out
        .lines()
        .find(|l| l.starts_with("common "))
        .expect("common row");
    // The official files' 210 messages (common.xml and its includes), PROTOCOL_VERSION, the
    // events protocol's five and the standard modes' three (definitions/extras).
    assert_eq!(common.split_whitespace().nth(1), Some("219"), "{common}");
}

#[test]
fn show_json_follows_the_contract() {
    let o = mavstack(&["dialect", "show", "common", "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert_eq!(out.lines().count(), 1, "one object on one line");
    // Key order is part of the documented shape.
    assert!(out.starts_with(r#"{"name":"common","messages":[{"id":0,"name":"HEARTBEAT","crc_extra":50,"min_len":9,"max_len":9,"fields":[{"name":"custom_mode","type":"uint32_t","array_len":null,"enum":null,"extension":false}"#), "{}", &out[..200]);
    let v: serde_json::Value = serde_json::from_str(&out).expect("valid JSON");
    let messages = v["messages"].as_array().expect("messages");
    let ids: Vec<u64> = messages
        .iter()
        .map(|m| m["id"].as_u64().expect("id"))
        .collect();
    assert!(ids.windows(2).all(|w| w[0] < w[1]), "sorted by id");
    let hb = &messages[0];
    let version = hb["fields"]
        .as_array()
        .expect("fields")
        .iter()
        .find(|f| f["name"] == "mavlink_version")
        .expect("field");
    assert_eq!(
        version["type"], "uint8_t",
        "uint8_t_mavlink_version is reported as uint8_t"
    );
    let ack = messages
        .iter()
        .find(|m| m["name"] == "COMMAND_ACK")
        .expect("COMMAND_ACK");
    let fields = ack["fields"].as_array().expect("fields");
    assert_eq!(fields[0]["name"], "command");
    assert_eq!(fields[2]["extension"], true);
    let pv = messages
        .iter()
        .find(|m| m["id"] == 300)
        .expect("PROTOCOL_VERSION");
    assert_eq!(pv["crc_extra"], 217);
    let mav_type = v["enums"]
        .as_array()
        .expect("enums")
        .iter()
        .find(|e| e["name"] == "MAV_TYPE")
        .expect("MAV_TYPE");
    assert_eq!(
        mav_type["entries"][0],
        serde_json::json!({"name": "MAV_TYPE_GENERIC", "value": 0})
    );
}

#[test]
fn show_accepts_a_path_and_any_case() {
    let path = workspace().join("definitions/minimal.xml");
    let o = mavstack(&["dialect", "show", path.to_str().expect("utf-8 path")]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("HEARTBEAT  crc_extra=50 len=9..9"),
        "{}",
        stdout(&o)
    );
    let o = mavstack(&["dialect", "show", "UAVIONIX"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).starts_with("dialect uAvionix "));
}

#[test]
fn bad_input_is_one_error_line_and_exit_2() {
    let o = mavstack(&["dialect", "show", "nosuchdialect"]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with("error: ") && err.contains("unknown dialect \"nosuchdialect\""),
        "{err}"
    );

    let bad = workspace().join("crates/mavstack-xml/tests/fixtures/errors/unknown_type.xml");
    let o = mavstack(&["dialect", "show", bad.to_str().expect("utf-8 path")]);
    assert_eq!(o.status.code(), Some(2));
    let err = stderr(&o);
    assert!(
        err.starts_with(&format!("error: {}:", bad.display())) && err.contains("unknown type"),
        "{err}"
    );

    let o = mavstack(&["dialect", "frobnicate"]);
    assert_eq!(o.status.code(), Some(2), "usage errors exit 2");
}

/// `mavstack codegen` output compiles in a crate of its own, with only mavstack-core, and
/// works: a fixture with includes and a real dialect (common.xml with its includes).
#[test]
fn generated_code_compiles_and_round_trips() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let krate = tmp.path();
    let core = workspace().join("crates/mavstack-core");
    std::fs::create_dir_all(krate.join("src")).expect("mkdir");
    std::fs::write(
        krate.join("Cargo.toml"),
        format!(
            "[package]\nname = \"codegen-check\"\nversion = \"0.0.0\"\nedition = \"2024\"\n\n[dependencies]\nmavstack-core = {{ path = {:?} }}\n\n[workspace]\n",
            core.display().to_string()
        ),
    )
    .expect("write manifest");
    for (xml, module) in [
        (
            workspace().join("crates/mavstack-codegen/tests/fixtures/includes/child.xml"),
            "fixture",
        ),
        (workspace().join("definitions/common.xml"), "real"),
    ] {
        let out = krate.join("src").join(module);
        let o = mavstack(&[
            "codegen",
            xml.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(out.join("mod.rs").exists());
    }
    std::fs::write(
        krate.join("src/lib.rs"),
        r#"#![deny(warnings)]
pub mod fixture;
pub mod real;

#[test]
fn works() {
    use mavstack_core::{Message, MessageSet};
    let report = fixture::child::Report { last: fixture::base::Command::STOP };
    let mut out = [0u8; 255];
    let n = report.encode(&mut out);
    assert_eq!(&out[..n], &[2, 0]);
    assert_eq!(fixture::child::MavMessage::decode(11, &out[..n]), Ok(fixture::child::MavMessage::Report(report)));
    let hb = real::minimal::Heartbeat::decode(&[0, 0, 0, 0, 2, 12, 0x51, 4, 3]);
    assert_eq!(hb.r#type, real::common::MavType::QUADROTOR);
    assert_eq!(real::common::MavMessage::info(300).map(|i| i.crc_extra), Some(217));
}
"#,
    )
    .expect("write lib.rs");
    let o = Command::new(env!("CARGO"))
        .args(["test", "--offline", "--quiet", "--manifest-path"])
        .arg(krate.join("Cargo.toml"))
        .env("CARGO_TARGET_DIR", krate.join("target"))
        .output()
        .expect("cargo runs");
    assert!(
        o.status.success(),
        "generated crate failed:\n{}\n{}",
        stdout(&o),
        stderr(&o)
    );
}
