//! `mavstack router --conf`: each key of mavlink-router's `main.conf` is honoured, or warned
//! about as having no effect with its `file:line`, or refused with `file:line: what`
//! (`docs/contracts/router.md`, "--conf"). The parse of every key is tested in
//! `crates/mavstack/src/router_conf/tests.rs`; these tests check what the router does with it.

use crate::router;

use router::Router;

use core::time::Duration;
use std::ffi::OsStr;
use std::net::UdpSocket;
use std::process::Command;

fn mavstack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
}

fn free_udp() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn udp_server(port: u16) -> String {
    format!("[UdpEndpoint a]\nMode = Server\nAddress = 127.0.0.1\nPort = {port}\n")
}

#[test]
fn report_stats_prints_the_statistics_lines() {
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("main.conf");
    let text = format!(
        "[General]\nTcpServerPort = 0\nReportStats = true\n{}",
        udp_server(free_udp())
    );
    std::fs::write(&conf, text).unwrap();
    let mut router = Router::start([OsStr::new("--conf"), conf.as_os_str()]);
    let lines = router.stdout_lines();
    // The first statistics object (the wait is only bounded: it comes after a period).
    let line = lines
        .recv_timeout(Duration::from_secs(10))
        .expect("a statistics line from ReportStats");
    let stats: serde_json::Value = serde_json::from_str(&line).unwrap();
    assert_eq!(stats["links"][0]["name"], "a", "{line}");
    router.stop();
}

#[test]
fn keys_without_effect_are_warned_about_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("main.conf");
    let keys = [
        ("DebugLogLevel", "info"),
        ("SnifferSysid", "254"),
        ("LogMode", "always"),
        ("MinFreeSpace", "0"),
        ("MaxLogFiles", "0"),
        ("LogSystemId", "1"),
        ("LogTelemetry", "false"),
    ];
    let mut text = String::from("[General]\nTcpServerPort = 0\n");
    for (key, value) in keys {
        text.push_str(&format!("{key} = {value}\n"));
    }
    let port = free_udp();
    // A TCP endpoint with RetryTimeout (line 13), and Group on the UDP endpoint (line 19).
    text.push_str(&format!(
        "[TcpEndpoint t]\nAddress = 127.0.0.1\nPort = {}\nRetryTimeout = 5\n\n{}Group = g\n",
        free_udp(),
        udp_server(port)
    ));
    std::fs::write(&conf, &text).unwrap();
    let router = Router::start([OsStr::new("--conf"), conf.as_os_str()]);
    let warnings = router.before_ready.clone();
    router.stop();
    let path = conf.display();
    let mut expected: Vec<String> = keys
        .iter()
        .enumerate()
        .map(|(i, (key, _))| format!("warning: {path}:{}: {key} has no effect in mavstack", i + 3))
        .collect();
    expected.push(format!(
        "warning: {path}:13: RetryTimeout has no effect in mavstack"
    ));
    expected.push(format!(
        "warning: {path}:19: Group has no effect in mavstack"
    ));
    for line in &expected {
        assert!(warnings.contains(line), "{line} not in {warnings:#?}");
    }
}

#[test]
fn keys_that_cannot_be_honoured_are_refused_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("main.conf");
    std::fs::write(
        &conf,
        format!(
            "[General]\nTcpServerPort = 0\nReportStats = maybe\n{}",
            udp_server(free_udp())
        ),
    )
    .unwrap();
    let out = mavstack()
        .args(["router", "--conf"])
        .arg(&conf)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    let want = format!("{}:3: General: ReportStats \"maybe\"", conf.display());
    assert!(err.contains(&want), "{err}");
}
