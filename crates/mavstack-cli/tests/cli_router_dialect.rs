//! `mavstack router --dialect`: every built-in name and a user's XML file (includes resolved
//! relative to it) give the router its message table, and message names in link options
//! resolve in that dialect (`docs/contracts/router.md`, "Dialect"). The oracle for a custom
//! message is pymavlink with a module generated from the same XML.

use crate::router;

use router::Router;

use std::ffi::OsStr;
use std::net::UdpSocket;
use std::path::Path;
use std::process::Command;

use crate::support;

use support::{require_pymavlink, run_script, text};

/// A message id ardupilotmega also uses (GIMBAL_REPORT there): only the XML's CRC_EXTRA
/// checks a CUSTOM_SAMPLE frame.
const CUSTOM_XML: &str = r#"<?xml version="1.0"?>
<mavlink>
  <include>base.xml</include>
  <messages>
    <message id="200" name="CUSTOM_SAMPLE">
      <description>Only in custom.xml.</description>
      <field type="uint32_t" name="counter">A counter.</field>
      <field type="float" name="value">A value.</field>
      <field type="char[8]" name="label">A label.</field>
      <extensions/>
      <field type="uint8_t" name="extra">An extension (MAVLink 1 leaves it out).</field>
    </message>
  </messages>
</mavlink>
"#;

/// Included by `custom.xml`, from the same folder.
const BASE_XML: &str = r#"<?xml version="1.0"?>
<mavlink>
  <version>3</version>
  <messages>
    <message id="201" name="CUSTOM_OTHER">
      <description>Only in base.xml.</description>
      <field type="uint16_t" name="code">A code.</field>
    </message>
  </messages>
</mavlink>
"#;

fn mavstack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
}

/// `custom.xml` and the `base.xml` it includes, in a folder of their own.
fn custom_dialect(dir: &Path) -> std::path::PathBuf {
    std::fs::write(dir.join("base.xml"), BASE_XML).unwrap();
    let path = dir.join("custom.xml");
    std::fs::write(&path, CUSTOM_XML).unwrap();
    path
}

fn free_udp() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn a_custom_xml_dialect_forwards_converts_and_filters_by_its_own_names() {
    require_pymavlink();
    let dir = tempfile::tempdir().unwrap();
    let xml = custom_dialect(dir.path());
    let (input, output) = (free_udp(), free_udp());
    let router = Router::start(&[
        "--dialect".into(),
        xml.display().to_string(),
        format!("udpin:127.0.0.1:{input}"),
        format!("udpout:127.0.0.1:{output}?version=1&block_msg_out=CUSTOM_OTHER"),
    ]);
    let out = run_script(
        "router_custom_dialect.py",
        &[
            OsStr::new("--xml"),
            xml.as_os_str(),
            OsStr::new("--to"),
            OsStr::new(&input.to_string()),
            OsStr::new("--listen"),
            OsStr::new(&output.to_string()),
        ],
    );
    router.stop();
    let frames: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}")))
        .collect();
    // CUSTOM_OTHER went first and is blocked by its name; CUSTOM_SAMPLE arrives as MAVLink 1
    // (0xFE) with a checksum pymavlink accepts under the XML's CRC_EXTRA, without its
    // extension field.
    assert_eq!(frames.len(), 1, "{out}");
    assert_eq!(frames[0]["type"], "CUSTOM_SAMPLE", "{out}");
    assert_eq!(frames[0]["stx"], 0xFE, "{out}");
    assert_eq!(
        frames[0]["fields"],
        serde_json::json!({"counter": 123_456, "value": 1.5, "label": "hello", "extra": 0}),
        "{out}"
    );
}

#[test]
fn a_message_name_the_dialect_lacks_is_a_usage_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let xml = custom_dialect(dir.path());
    let port = free_udp();
    // HEARTBEAT is in every built-in dialect, not in custom.xml.
    let out = mavstack()
        .args(["router", "--dialect"])
        .arg(&xml)
        .arg(format!("udpin:127.0.0.1:{port}?block_msg_out=HEARTBEAT"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(err.contains("\"HEARTBEAT\""), "{err}");
    // An unknown dialect is a usage error listing the built-in names.
    let out = mavstack()
        .args(["router", "--dialect", "no-such-dialect"])
        .arg(format!("udpin:127.0.0.1:{port}"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(
        err.contains("no-such-dialect") && err.contains("uAvionix"),
        "{err}"
    );
}

#[test]
fn every_built_in_dialect_name_is_accepted_with_its_own_message_names() {
    // ASLUAV is not compiled into the router: its table comes from the run-time model (the
    // name matched in any case), and its own messages are known by name.
    let port = free_udp();
    let router = Router::start(&[
        "--dialect".into(),
        "asluav".into(),
        format!("udpin:127.0.0.1:{port}?block_msg_out=ASLCTRL_DATA,HEARTBEAT"),
    ]);
    router.stop();
}
