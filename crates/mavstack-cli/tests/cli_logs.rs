//! `mavstack log list | download` against `mavstack vehicle` (its generated logs) on
//! loopback, and their errors. Against other implementations, and with a log directory:
//! `interop_logs.rs`.

use crate::vehicle;

use std::process::{Command, Output};

use mavstack_sim::logs::generated_log;
use serde_json::Value;
use vehicle::Vehicle;

fn mavstack(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(args)
        .output()
        .expect("mavstack runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stdout)
}

#[test]
fn the_vehicles_logs_are_listed_and_downloaded_whole() {
    let v = Vehicle::start(&[]);
    let conn = format!("udpout:127.0.0.1:{}", v.port);
    let list: Vec<Value> = ok(&mavstack(&["log", "list", &conn, "--json"]))
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect();
    assert_eq!(list.len(), 2);
    assert_eq!(list[1]["id"], 2);
    assert_eq!(list[1]["size"], 123_457);
    assert_eq!(list[1]["time_utc"], 1_700_003_600);
    assert_eq!(list[1]["time"], "2023-11-14T23:13:20Z");
    let table = ok(&mavstack(&["log", "list", &conn]));
    assert!(
        table
            .lines()
            .next()
            .is_some_and(|l| l.contains("time (UTC)")),
        "{table}"
    );
    assert!(table.contains("300000  2023-11-14T22:13:20Z"), "{table}");

    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("logs");
    let out_s = out.to_str().expect("utf-8");
    let latest = ok(&mavstack(&[
        "log", "download", &conn, "--latest", "--out", out_s, "--json",
    ]));
    let line: Value = serde_json::from_str(latest.trim()).expect("one JSON line");
    assert_eq!(line["id"], 2);
    assert_eq!(line["bytes"], 123_457);
    assert_eq!(line["via"], "log", "the generated logs are not files");
    assert_eq!(
        std::fs::read(out.join("log_2.bin")).expect("log_2.bin"),
        generated_log(2).expect("log 2")
    );
    let one = ok(&mavstack(&["log", "download", &conn, "1", "--out", out_s]));
    assert!(
        one.starts_with("log 1 → ")
            && one.contains("300000 bytes")
            && one.contains("by LOG_REQUEST_DATA"),
        "{one}"
    );
    assert_eq!(
        std::fs::read(out.join("log_1.bin")).expect("log_1.bin"),
        generated_log(1).expect("log 1")
    );
    let names: Vec<String> = std::fs::read_dir(&out)
        .expect("out")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 2, "no .part left: {names:?}");
}

#[test]
fn a_log_the_vehicle_does_not_have_and_bad_arguments_fail() {
    let v = Vehicle::start(&[]);
    let conn = format!("udpout:127.0.0.1:{}", v.port);
    let dir = tempfile::tempdir().expect("tmp");
    let out_s = dir.path().to_str().expect("utf-8");
    let o = mavstack(&["log", "download", &conn, "7", "--out", out_s]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o.stderr));
    assert!(text(&o.stderr).starts_with("error: ") && text(&o.stderr).contains("no log 7"));
    assert!(!dir.path().join("log_7.bin").exists());
    // Nothing chosen, or two ways of choosing: usage errors.
    for args in [
        vec!["log", "download", &conn],
        vec!["log", "download", &conn, "1", "--all"],
        vec![
            "log",
            "download",
            &conn,
            "--latest",
            "--via",
            "carrier-pigeon",
        ],
    ] {
        let o = mavstack(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o.stderr));
    }
    // A log directory that is not there.
    let missing = dir.path().join("no-such-dir");
    let o = mavstack(&[
        "vehicle",
        "udpin:127.0.0.1:0",
        "--log-dir",
        missing.to_str().expect("utf-8"),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--log-dir"), "{}", text(&o.stderr));
}

/// `log erase` needs `--yes`; with it every log is gone, as the list says afterwards.
#[test]
fn erase_needs_yes_and_leaves_no_log() {
    let v = Vehicle::start(&[]);
    let conn = format!("udpout:127.0.0.1:{}", v.port);
    let refused = mavstack(&["log", "erase", &conn]);
    assert_eq!(refused.status.code(), Some(2), "{}", text(&refused.stderr));
    assert!(text(&refused.stderr).contains("--yes"));
    let listed = ok(&mavstack(&["log", "list", &conn, "--json"]));
    assert_eq!(listed.lines().count(), 2, "nothing erased without --yes");
    let erased = ok(&mavstack(&["log", "erase", &conn, "--yes", "--json"]));
    let line: Value = serde_json::from_str(erased.trim()).expect("one JSON line");
    assert_eq!(line["erased"], true);
    assert_eq!(ok(&mavstack(&["log", "list", &conn, "--json"])), "");
}
