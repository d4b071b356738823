//! Bad input from outside never panics the `mavstack` command: every bounded numeric option
//! out of its range is exit 2 with an `error:` line naming the option and the range
//! (docs/contracts/cli.md), and `log summary` reports a tlog whose clock goes back.

use std::path::Path;
use std::process::{Command, Output};

fn mavstack(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(args)
        .env_remove("RUST_LOG")
        .output()
        .expect("run mavstack")
}

/// A loopback address nothing answers on (the commands below never get to use it).
const NOWHERE: &str = "udpout:127.0.0.1:9";

#[test]
fn every_bounded_number_out_of_range_is_exit_2_naming_the_option_and_its_range() {
    let dir = tempfile::tempdir().expect("temp dir");
    let log = dir.path().join("in.tlog");
    std::fs::write(&log, b"").expect("write a log");
    let out = dir.path().join("out.tlog");
    let (log, out) = (log.to_str().expect("utf-8"), out.to_str().expect("utf-8"));
    // (arguments, the option, a piece of the range its error must give)
    #[rustfmt::skip]
    let cases: &[(&[&str], &str, &str)] = &[
        (&["replay", log, NOWHERE, "--speed", "1e-300"], "--speed", "0.001 to 1000000"),
        (&["replay", log, NOWHERE, "--speed", "nan"], "--speed", "0.001 to 1000000"),
        (&["replay", log, NOWHERE, "--speed", "inf"], "--speed", "0.001 to 1000000"),
        (&["replay", log, NOWHERE, "--speed=-1"], "--speed", "0.001 to 1000000"),
        (&["replay", log, NOWHERE, "--speed", "1e300"], "--speed", "0.001 to 1000000"),
        (&["record", NOWHERE, out, "--duration", "1e300"], "--duration", "to 31536000"),
        (&["record", NOWHERE, out, "--duration", "0"], "--duration", "0.001 to"),
        (&["listen", NOWHERE, "--duration", "nan"], "--duration", "to 31536000"),
        (&["probe", NOWHERE, "--timeout", "1e300"], "--timeout", "0.001 to 86400"),
        (&["probe", NOWHERE, "--timeout=-1"], "--timeout", "0.001 to 86400"),
        (&["probe", NOWHERE, "--timeout", "0"], "--timeout", "0.001 to 86400"),
        (&["probe", NOWHERE, "--other-id", "5"], "--other-id", "256"),
        (&["probe", NOWHERE, "--other-id", "16777216"], "--other-id", "16777215"),
        (&["conform", NOWHERE, "--timeout", "1e300"], "--timeout", "0.001 to 86400"),
        (&["param", "list", NOWHERE, "--timeout", "nan"], "--timeout", "0.001 to 86400"),
        (&["command", "arm", NOWHERE, "--timeout", "1e9"], "--timeout", "0.001 to 86400"),
        (&["radio", NOWHERE, NOWHERE, "--interval", "0"], "--interval", "0.01 to 86400"),
        (&["radio", NOWHERE, NOWHERE, "--interval", "1e300"], "--interval", "0.01 to 86400"),
        (&["router", NOWHERE, "--route-ttl", "1e300"], "--route-ttl", "0.01 to 86400"),
        (&["router", NOWHERE, "--stats", "0"], "--stats", "0.01 to 86400"),
        (&["router", NOWHERE, "--dedup", "99999999999"], "--dedup", "3600000"),
        (&["vehicle", NOWHERE, "--estimator-settle", "1e9"], "--estimator-settle", "0 to 3600"),
        (&["log", "filter", log, out, "--from", "nan"], "--from", "0 to 10000000000000"),
        (&["log", "filter", log, out, "--to", "1e300"], "--to", "0 to 10000000000000"),
    ];
    let mut wrong = Vec::new();
    for (args, option, range) in cases {
        let o = mavstack(args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        let ok = o.status.code() == Some(2)
            && stderr.starts_with("error:")
            && stderr.contains(option)
            && stderr.contains(range);
        if !ok {
            wrong.push(format!(
                "{args:?}: exit {:?}, stderr {stderr:?}",
                o.status.code()
            ));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn replay_speed_0_is_as_fast_as_possible_not_an_error() {
    let dir = tempfile::tempdir().expect("temp dir");
    let log = dir.path().join("in.tlog");
    write_tlog(&log, &[1_000_000, 2_000_000]);
    let o = mavstack(&[
        "replay",
        log.to_str().expect("utf-8"),
        NOWHERE,
        "--speed",
        "0",
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("replayed 2 frames"), "{stderr}");
}

/// CRC-16/MCRF4XX, as MAVLink checksums.
fn crc(bytes: &[u8]) -> u16 {
    let mut crc = 0xFFFFu16;
    for &b in bytes {
        let mut t = b ^ (crc & 0xFF) as u8;
        t ^= t << 4;
        crc = (crc >> 8) ^ (u16::from(t) << 8) ^ (u16::from(t) << 3) ^ (u16::from(t) >> 4);
    }
    crc
}

/// A tlog of MAVLink 1 HEARTBEATs of 1/1 at the timestamps given (µs).
fn write_tlog(path: &Path, stamps: &[u64]) {
    let mut bytes = Vec::new();
    for (seq, ts) in stamps.iter().enumerate() {
        let mut frame = vec![0xFE, 9, seq as u8, 1, 1, 0, 0, 0, 0, 0, 2, 3, 0x51, 4, 3];
        let mut sum = frame[1..].to_vec();
        sum.push(50); // HEARTBEAT's CRC_EXTRA
        frame.extend_from_slice(&crc(&sum).to_le_bytes());
        bytes.extend_from_slice(&ts.to_be_bytes());
        bytes.extend_from_slice(&frame);
    }
    std::fs::write(path, bytes).expect("write the tlog");
}

#[test]
fn log_summary_counts_timestamps_that_go_back_and_does_not_panic() {
    let dir = tempfile::tempdir().expect("temp dir");
    let log = dir.path().join("back.tlog");
    // 1 s, 3 s, back to 2 s, 4 s, back to 0.5 s: two steps back; the last record is the
    // earliest of all (a plain last-minus-first underflows).
    write_tlog(&log, &[1_000_000, 3_000_000, 2_000_000, 4_000_000, 500_000]);
    let path = log.to_str().expect("utf-8");
    let o = mavstack(&["log", "summary", path, "--json"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    let obj: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(obj["frames"], 5, "{obj}");
    assert_eq!(obj["time_backward_steps"], 2, "{obj}");
    // From the first timestamp to the latest.
    assert_eq!(obj["duration_s"], 3.0, "{obj}");
    let o = mavstack(&["log", "summary", path]);
    let table = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(table.contains("goes back 2 times"), "{table}");
    // A log whose clock only goes forward says 0.
    write_tlog(&log, &[1_000_000, 2_000_000]);
    let o = mavstack(&["log", "summary", path, "--json"]);
    let obj: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    assert_eq!(obj["time_backward_steps"], 0, "{obj}");
}

/// A file argument that is a directory: the error says what the operating system said.
#[test]
fn a_directory_for_a_file_gives_the_os_error() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().to_str().expect("utf-8");
    for args in [
        vec!["decode", path],
        vec!["decode", "--count", path],
        vec!["log", "summary", path],
        vec!["replay", path, NOWHERE],
        vec!["router", "--conf", path],
        vec!["ftp", "put", NOWHERE, path, "/x"],
    ] {
        let out = mavstack(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_ne!(out.status.code(), Some(0), "{args:?}");
        assert!(
            err.contains(&format!("cannot read {path}: Is a directory (os error 21)")),
            "{args:?}: {err}"
        );
    }
}

/// A link that cannot be opened: the error says why once, however many layers pass the
/// cause on (the ground-station commands' `cannot open LINK: link "LINK": cannot bind ...`
/// printed the bind error twice).
#[test]
fn a_link_that_cannot_be_opened_says_why_once() {
    // TEST-NET-1: no interface of this machine has it, so binding it fails at once.
    let link = "udpin:192.0.2.1:14550";
    let why = "cannot bind udp 192.0.2.1:14550";
    for args in [
        vec!["param", "list", link],
        vec!["mission", "download", link],
        vec!["ftp", "ls", link, "/"],
        vec!["probe", link],
        vec!["conform", link],
        vec!["listen", link],
        vec!["router", link],
        vec!["vehicle", link],
    ] {
        let out = mavstack(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.starts_with("error: "), "{args:?}: {err}");
        assert_eq!(err.matches(why).count(), 1, "{args:?}: {err}");
    }
}

/// Every command that reads or writes frames on a link takes the link options all link
/// commands take (here `name` and `max_peers`), as `router` and `vehicle` do.
#[test]
fn link_commands_take_link_options() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out.tlog");
    let out = out.to_str().expect("utf-8");
    let link = "udpin:127.0.0.1:0?name=x&max_peers=4";
    for args in [
        vec!["listen", link, "--duration", "0.2"],
        vec!["record", link, out, "--duration", "0.2"],
        vec!["probe", link, "--timeout", "0.2"],
        vec!["conform", link, "--timeout", "0.2"],
        vec!["param", "list", link, "--timeout", "0.2"],
    ] {
        let got = mavstack(&args);
        let err = String::from_utf8_lossy(&got.stderr);
        assert_ne!(got.status.code(), Some(2), "{args:?}: {err}");
        assert!(!err.contains("bad port"), "{args:?}: {err}");
    }
}
