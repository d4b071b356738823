//! `mavstack`'s diagnostics (docs/contracts/cli.md, Logging): warnings of every layer on
//! stderr naming the link, `-q`, `--log-format json`, `RUST_LOG`.
//!
//! The event used is a fleet link (`mqtt://`) to a broker port that is closed: the bridge
//! warns on every failed connection attempt. Waits are bounded (5 s for a line that comes
//! within 0.1 s of the start), never asserted as speeds.

use core::time::Duration;
use std::io::{BufRead as _, BufReader};
use std::net::TcpListener;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Instant;

/// How long a test waits for a line it expects (or watches for one it must not see).
const WAIT: Duration = Duration::from_secs(5);

/// A loopback port with nothing listening on it.
fn closed_port() -> u16 {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind a port");
    let port = listener.local_addr().expect("its address").port();
    drop(listener);
    port
}

/// The router with one MQTT link to a closed port; stderr piped.
struct Router {
    child: Child,
    lines: mpsc::Receiver<String>,
    /// The link's name: its connection string without the options, by default.
    link: String,
}

impl Router {
    fn start(log_args: &[&str], env: &[(&str, &str)]) -> Self {
        let link = format!("mqtt://127.0.0.1:{}", closed_port());
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_mavstack"));
        cmd.args(log_args)
            .args([
                "router",
                &format!("{link}?fleet=f&vid=v"),
                "--tcp-server",
                "0",
            ])
            .env_remove("RUST_LOG")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        for (k, v) in env {
            cmd.env(k, v);
        }
        let mut child = cmd.spawn().expect("start mavstack router");
        let stderr = child.stderr.take().expect("stderr piped");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self { child, lines, link }
    }

    /// The first stderr line that `want` accepts within [`WAIT`], and every line seen.
    fn wait_for(&self, want: impl Fn(&str) -> bool) -> (Option<String>, Vec<String>) {
        let until = Instant::now() + WAIT;
        let mut seen = Vec::new();
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    if want(&line) {
                        return (Some(line), seen);
                    }
                    seen.push(line);
                }
                Err(_) => break,
            }
        }
        (None, seen)
    }
}

impl Drop for Router {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn a_fleet_link_whose_broker_is_down_is_a_warning_naming_the_link() {
    let router = Router::start(&[], &[]);
    let link = router.link.clone();
    let (line, seen) = router.wait_for(|l| l.contains("WARN") && l.contains(&link));
    let line = line.unwrap_or_else(|| panic!("no WARN line naming {link}; stderr: {seen:?}"));
    assert!(line.contains("mqtt"), "{line}");
    assert!(
        line.contains(&format!("link={link}")),
        "the link as a field: {line}"
    );
}

#[test]
fn quiet_keeps_warnings_off_stderr() {
    let router = Router::start(&["-q"], &[]);
    // The same wait in which the default shows the warning (a few attempts are made in it).
    let (line, _) = router.wait_for(|l| l.contains("WARN") || l.contains("mqtt"));
    assert_eq!(line, None, "-q shows errors only");
}

#[test]
fn json_format_writes_one_object_a_line_with_level_and_fields() {
    let router = Router::start(&["--log-format", "json"], &[]);
    let link = router.link.clone();
    let (line, seen) = router.wait_for(|l| l.contains(&link));
    let line = line.unwrap_or_else(|| panic!("no line naming {link}; stderr: {seen:?}"));
    let obj: serde_json::Value =
        serde_json::from_str(&line).unwrap_or_else(|e| panic!("not a JSON object ({e}): {line}"));
    assert_eq!(obj["level"], "WARN", "{obj}");
    assert_eq!(obj["fields"]["link"], link.as_str(), "{obj}");
    assert!(
        obj["fields"]["message"]
            .as_str()
            .is_some_and(|m| m.contains("mqtt")),
        "{obj}"
    );
    // The diagnostics are JSON; the command's own status line (`mavstack router: ready`) is
    // not a diagnostic.
    for other in seen.iter().filter(|l| !l.starts_with("mavstack router:")) {
        assert!(
            serde_json::from_str::<serde_json::Value>(other).is_ok(),
            "every diagnostic line is JSON: {other}"
        );
    }
}

#[test]
fn rust_log_is_honoured_over_the_flags() {
    // `-q` asks for errors only; RUST_LOG=debug wins and shows debug lines.
    let router = Router::start(&["-q"], &[("RUST_LOG", "debug")]);
    let (line, seen) = router.wait_for(|l| l.contains("DEBUG"));
    assert!(
        line.is_some(),
        "no DEBUG line with RUST_LOG=debug; stderr: {seen:?}"
    );
}

#[test]
fn verbose_flags_are_counted_and_quiet_conflicts_with_them() {
    let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(["-q", "-v", "dialect", "list"])
        .output()
        .expect("run mavstack");
    assert_eq!(out.status.code(), Some(2), "-q with -v is a usage error");
    let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(["-vv", "--log-format", "json", "dialect", "list"])
        .output()
        .expect("run mavstack");
    assert_eq!(out.status.code(), Some(0));
    let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(["--log-format", "xml", "dialect", "list"])
        .output()
        .expect("run mavstack");
    assert_eq!(
        out.status.code(),
        Some(2),
        "an unknown format is a usage error"
    );
}
