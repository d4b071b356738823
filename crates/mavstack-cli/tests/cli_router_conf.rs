//! `mavstack router --conf`: each key of mavlink-router's `main.conf` is honoured, or warned
//! about as having no effect with its `file:line`, or refused with `file:line: what`
//! (`docs/contracts/router.md`, "--conf"). The parse of every key is tested in
//! `crates/mavstack/src/router_conf/tests.rs`; these tests check what the router does with it.

use core::time::Duration;
use std::io::{BufRead as _, BufReader};
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::mpsc;
use std::time::Instant;

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

/// A router started with `--conf conf`; its stderr up to "ready" is kept.
struct Router {
    child: Child,
    before_ready: Vec<String>,
}

impl Router {
    fn start(conf: &Path) -> Self {
        let mut child = mavstack()
            .args(["router", "--conf"])
            .arg(conf)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut err = BufReader::new(child.stderr.take().unwrap());
        let mut before_ready = Vec::new();
        loop {
            let mut line = String::new();
            assert!(
                err.read_line(&mut line).unwrap() > 0,
                "router exited before it was ready: {before_ready:?}"
            );
            if line.contains("mavstack router: ready") {
                break;
            }
            before_ready.push(line.trim_end().to_owned());
        }
        std::thread::spawn(move || for _ in err.lines() {});
        Self {
            child,
            before_ready,
        }
    }

    /// Its stdout, line by line, through a channel (a wait on it can be bounded).
    fn stdout_lines(&mut self) -> mpsc::Receiver<String> {
        let out: ChildStdout = self.child.stdout.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        rx
    }

    fn stop(mut self) {
        let pid = self.child.id().to_string();
        Command::new("kill").args(["-TERM", &pid]).status().unwrap();
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                assert!(status.success(), "router exit status {status}");
                return;
            }
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "router did not stop"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
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
    let mut router = Router::start(&conf);
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
    let router = Router::start(&conf);
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
