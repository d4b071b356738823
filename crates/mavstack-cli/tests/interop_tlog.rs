//! `mavstack decode` on a tlog that pymavlink 2.4.50 writes (`tests-interop/short_v1_tlog.py`:
//! its `mavlogfile`, 500 records of MAVLink 2 frames, some signed, and MAVLink 1 frames, many
//! with payloads of 2 or 3 bytes right after a MAVLink 2 frame). pymavlink's own reader loses
//! the record after each of those (the script says why); mavstack must lose none: every record,
//! in order, with its timestamp and header as pymavlink wrote them.
//!
//! Never skipped: without pymavlink 2.4.50 the test fails.

use crate::support;

use std::ffi::OsStr;
use std::io::Write as _;
use std::path::Path;
use std::process::{Command, Stdio};

use serde_json::Value;
use support::{require_pymavlink, run_script, text};

/// The records pymavlink wrote to `path`, as the script describes them.
fn write_log(path: &Path) -> Vec<Value> {
    let out = run_script(
        "short_v1_tlog.py",
        &[path.as_os_str(), OsStr::new("--records"), OsStr::new("500")],
    );
    let rows: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).expect("the script prints JSON lines"))
        .collect();
    assert_eq!(rows.len(), 500, "{out}");
    // The case is there: short MAVLink 1 frames right after MAVLink 2 ones.
    let after_v2 = rows
        .windows(2)
        .filter(|w| w[0]["version"] == 2 && w[1]["short_v1"] == true)
        .count();
    assert!(
        after_v2 >= 50,
        "{after_v2} short MAVLink 1 frames after MAVLink 2 ones"
    );
    rows
}

/// `mavstack decode --dialect ardupilotmega ARGS`, with `stdin` fed to it when given: its
/// JSON lines.
fn decode(args: &[&OsStr], stdin: Option<&[u8]>) -> Vec<Value> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(["decode", "--dialect", "ardupilotmega"])
        .args(args)
        .stdin(if stdin.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mavstack runs");
    if let Some(data) = stdin {
        // The log (18 KB) fits in the pipe's buffer: written whole before the output is read.
        let mut pipe = child.stdin.take().expect("stdin pipe");
        pipe.write_all(data).expect("stdin written");
    }
    let out = child.wait_with_output().expect("mavstack finishes");
    assert!(out.status.success(), "{}", text(&out.stderr));
    text(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("decode prints JSON lines"))
        .collect()
}

/// Every decoded line is the record pymavlink wrote at its place.
fn assert_every_record(got: &[Value], want: &[Value], how: &str) {
    let fields = ["ts_us", "version", "seq", "sysid", "compid", "msgid"];
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        for field in fields {
            assert_eq!(g[field], w[field], "{how}: record {i}: {field}: {g} / {w}");
        }
        assert_eq!(g["name"], w["type"], "{how}: record {i}");
    }
    assert_eq!(got.len(), want.len(), "{how}: records decoded");
}

#[test]
fn decode_loses_no_record_after_short_mavlink_1_frames_of_a_pymavlink_tlog() {
    require_pymavlink();
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("short_v1.tlog");
    let want = write_log(&path);
    // A file: read after pymavlink's indexing walk, as mavlink_connection opens one.
    assert_every_record(&decode(&[path.as_os_str()], None), &want, "file");
    // Standard input: read from the start, no walk.
    let log = std::fs::read(&path).expect("the log");
    assert_every_record(&decode(&[OsStr::new("--tlog")], Some(&log)), &want, "stdin");
    let counted = decode(&[OsStr::new("--count"), path.as_os_str()], None);
    assert_eq!(counted.len(), 1);
    assert_eq!(counted[0]["frames"], 500, "{}", counted[0]);
    assert_eq!(counted[0]["skipped_bytes"], 0, "{}", counted[0]);
}
