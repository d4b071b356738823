//! `mavstack shell` and `mavstack rtk` against `mavstack vehicle` on loopback: a command's
//! output (text and JSON, a long one in many SERIAL_CONTROL replies), ArduPilot's missing
//! shell, the interactive mode in a pseudo-terminal (raw mode, Ctrl-C passed on, Ctrl-D
//! leaves, the terminal restored) and with piped input; corrections from a file counted by
//! the vehicle, a stream of garbage sending nothing, bad sources. Against pymavlink:
//! `interop_rtk.rs`.

use crate::vehicle;

use core::time::Duration;
use std::io::{Read as _, Write as _};
use std::net::UdpSocket;
use std::process::{Child, Command, Output, Stdio};
use std::time::Instant;

use vehicle::Vehicle;

fn mavstack(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_mavstack"));
    c.args(args);
    c
}

fn at(port: u16) -> String {
    format!("udpout:127.0.0.1:{port}")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn shell(port: u16, extra: &[&str]) -> Output {
    mavstack(&["shell", &at(port), "--timeout", "10"])
        .args(extra)
        .output()
        .expect("mavstack runs")
}

#[test]
fn shell_command_prints_the_output_of_px4s_nsh() {
    let v = Vehicle::start(&["--autopilot", "px4"]);
    let out = shell(v.port, &["--command", "ver all"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let ver = text(&out.stdout);
    assert!(ver.starts_with("HW arch: MAVSTACK_SIM\n"), "{ver}");
    assert!(
        ver.contains("\nPX4 version: Release 4.1.0 (67174655)\n"),
        "{ver}"
    );
    assert!(ver.ends_with("MCU: MAVSTACK simulated, rev. 1\n"), "{ver}");
    assert!(!ver.contains("nsh>") && !ver.contains("NuttShell"), "{ver}");

    let out = shell(v.port, &["--command", "help", "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(json["command"], "help");
    let help = json["output"].as_str().expect("output");
    // Longer than eight SERIAL_CONTROL replies, put back together line by line.
    assert!(help.len() > 8 * 70, "{help}");
    assert!(help.lines().any(|l| l == "  work_queue"), "{help}");
    assert_eq!(help.lines().filter(|l| l.starts_with("  ")).count(), 58);

    let long: String = (0..200)
        .map(|i| char::from(b'a' + (i % 26) as u8))
        .collect();
    // Three SERIAL_CONTROL messages to the shell, echoed back whole.
    let out = shell(v.port, &["--command", &format!("echo {long}")]);
    assert_eq!(text(&out.stdout), format!("{long}\n"));

    let out = shell(v.port, &["--command", "nosuch"]);
    assert_eq!(text(&out.stdout), "nsh: nosuch: command not found\n");
}

#[test]
fn shell_on_ardupilot_fails_with_the_reason() {
    let v = Vehicle::start(&["--autopilot", "ardupilot"]);
    let out = shell(v.port, &["--command", "ver all"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty());
    let err = text(&out.stderr);
    assert!(
        err.contains("no answer from the shell within 5.0 s") && err.contains("ArduPilot"),
        "{err}"
    );
}

#[test]
fn shell_with_piped_input_sends_it_and_leaves_when_quiet() {
    let v = Vehicle::start(&["--autopilot", "px4"]);
    let mut child = mavstack(&["shell", &at(v.port), "--timeout", "10"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    let mut stdin = child.stdin.take().expect("stdin");
    stdin.write_all(b"echo one\necho two\n").expect("written");
    drop(stdin);
    let out = child.wait_with_output().expect("ends");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let seen = text(&out.stdout);
    assert!(
        seen.contains("nsh> echo one\none\nnsh> echo two\ntwo\nnsh> "),
        "{seen:?}"
    );
}

/// The interactive mode in a pseudo-terminal: keys go raw (no local echo, Enter as a line
/// feed), Ctrl-C reaches the shell (which answers `^C`) instead of ending the command,
/// Ctrl-D leaves with exit 0, and the terminal is back in canonical mode afterwards.
#[cfg(target_os = "linux")]
#[test]
fn shell_interactive_in_a_terminal() {
    use nix::sys::termios::{self, LocalFlags};
    use std::os::fd::AsFd as _;

    let v = Vehicle::start(&["--autopilot", "px4"]);
    let pty = nix::pty::openpty(None, None).expect("a pseudo-terminal");
    let slave = std::fs::File::from(pty.slave);
    let mut child: Child = mavstack(&["shell", &at(v.port), "--timeout", "10"])
        .stdin(slave.try_clone().expect("fd"))
        .stdout(slave.try_clone().expect("fd"))
        .stderr(Stdio::piped())
        .spawn()
        .expect("runs");
    let mut master = std::fs::File::from(pty.master);
    let mut seen = String::new();
    let until = |master: &mut std::fs::File, want: &str, seen: &mut String| {
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut buf = [0u8; 1024];
        while !seen.contains(want) {
            assert!(Instant::now() < deadline, "never {want:?} in {seen:?}");
            let n = master.read(&mut buf).expect("the terminal reads");
            seen.push_str(&String::from_utf8_lossy(&buf[..n]));
        }
    };
    until(&mut master, "nsh> ", &mut seen);
    // Raw mode: the terminal no longer edits lines or echoes.
    let attrs = termios::tcgetattr(slave.as_fd()).expect("attributes");
    assert!(
        !attrs
            .local_flags
            .intersects(LocalFlags::ICANON | LocalFlags::ECHO)
    );
    master.write_all(b"echo hi\r").expect("typed");
    until(&mut master, "hi\r\nnsh> ", &mut seen);
    master.write_all(b"ver\x03").expect("typed");
    until(&mut master, "ver^C\r\nnsh> ", &mut seen);
    assert!(
        child.try_wait().expect("status").is_none(),
        "Ctrl-C ended it"
    );
    master.write_all(b"\x04").expect("typed");
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        if let Some(s) = child.try_wait().expect("status") {
            break s;
        }
        assert!(Instant::now() < deadline, "Ctrl-D did not leave");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "{status}");
    let attrs = termios::tcgetattr(slave.as_fd()).expect("attributes");
    assert!(
        attrs
            .local_flags
            .contains(LocalFlags::ICANON | LocalFlags::ECHO)
    );
}

/// A `mavstack vehicle -v` whose stderr (what it does) goes to a file.
struct Narrating {
    child: Child,
    port: u16,
    log: std::path::PathBuf,
}

impl Narrating {
    fn start(dir: &std::path::Path, autopilot: &str) -> Self {
        for attempt in 0..5 {
            let port = UdpSocket::bind("127.0.0.1:0")
                .and_then(|s| s.local_addr())
                .expect("a free port")
                .port();
            let log = dir.join(format!("vehicle-{attempt}.log"));
            let file = std::fs::File::create(&log).expect("log");
            let mut child = mavstack(&["vehicle", &format!("udpin:127.0.0.1:{port}")])
                .args(["--autopilot", autopilot, "-v"])
                .stdout(Stdio::null())
                .stderr(file)
                .spawn()
                .expect("vehicle starts");
            let deadline = Instant::now() + Duration::from_secs(10);
            while Instant::now() < deadline && child.try_wait().expect("status").is_none() {
                if std::fs::read_to_string(&log).is_ok_and(|t| t.contains("vehicle: ")) {
                    return Self { child, port, log };
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        panic!("mavstack vehicle -v did not start");
    }

    /// Its `rtk:` lines, once `count` have come (within 30 s).
    fn rtk_lines(&self, count: usize) -> Vec<String> {
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            let log = std::fs::read_to_string(&self.log).unwrap_or_default();
            let lines: Vec<String> = log
                .lines()
                .filter_map(|l| l.strip_prefix("vehicle: rtk: "))
                .map(str::to_owned)
                .collect();
            if lines.len() >= count || Instant::now() > deadline {
                return lines;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Narrating {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// An RTCM3 frame around `payload` (CRC-24Q computed bitwise, not by the library).
fn frame(payload: &[u8]) -> Vec<u8> {
    let mut f = vec![0xD3, (payload.len() >> 8) as u8 & 3, payload.len() as u8];
    f.extend_from_slice(payload);
    let mut crc = 0u32;
    for &b in &f {
        crc ^= u32::from(b) << 16;
        for _ in 0..8 {
            crc <<= 1;
            if crc & 0x0100_0000 != 0 {
                crc ^= 0x0186_4CFB;
            }
        }
    }
    f.extend_from_slice(&(crc & 0x00FF_FFFF).to_be_bytes()[1..]);
    f
}

#[test]
fn rtk_from_a_file_reaches_the_vehicle_and_garbage_sends_nothing() {
    let dir = tempfile::tempdir().expect("tmp");
    for autopilot in ["ardupilot", "px4"] {
        let v = Narrating::start(dir.path(), autopilot);
        let mut stream = b"garbage before".to_vec();
        stream.extend_from_slice(&frame(&[0x3e, 0xd0, 1, 2, 3]));
        let mut msm = vec![0x43, 0x50];
        msm.resize(354, 0x55);
        stream.extend_from_slice(&frame(&msm));
        let mut damaged = frame(&[0x43, 0x20, 7, 7, 7, 7]);
        damaged[5] ^= 2;
        stream.extend_from_slice(&damaged);
        let file = dir.path().join("base.rtcm3");
        std::fs::write(&file, &stream).expect("written");
        let out = mavstack(&["rtk", &at(v.port), "--from", file.to_str().expect("utf-8")])
            .output()
            .expect("runs");
        assert!(out.status.success(), "{}", text(&out.stderr));
        let summary = text(&out.stdout);
        assert!(
            summary.contains("2 frames sent (371 bytes in 4 GPS_RTCM_DATA), 1 damaged, 0 too long"),
            "{summary}"
        );
        let lines = v.rtk_lines(2);
        assert_eq!(lines.len(), 2, "{lines:?}");
        assert!(lines[0].starts_with("RTCM 1005, 11 bytes;"), "{lines:?}");
        assert!(
            lines[1].starts_with("RTCM 1077, 360 bytes; 2 messages, 371 bytes"),
            "{lines:?}"
        );

        let noise: Vec<u8> = (0..20_000u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        let garbage = dir.path().join("noise.bin");
        std::fs::write(&garbage, &noise).expect("written");
        let out = mavstack(&[
            "rtk",
            &at(v.port),
            "--from",
            garbage.to_str().expect("utf-8"),
            "--json",
        ])
        .output()
        .expect("runs");
        assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
        assert!(
            text(&out.stderr).contains("no RTCM3 frame in 20000 bytes"),
            "{}",
            text(&out.stderr)
        );
        let last: serde_json::Value =
            serde_json::from_str(text(&out.stdout).lines().last().expect("a summary"))
                .expect("JSON");
        assert_eq!(
            (last["sent"].as_u64(), last["skipped"].as_u64()),
            (Some(0), Some(20_000))
        );
        // Nothing more reached the vehicle.
        std::thread::sleep(Duration::from_millis(500));
        assert_eq!(v.rtk_lines(0).len(), 2);
    }
}

#[test]
fn rtk_refuses_sources_it_cannot_read() {
    for (source, code, says) in [
        (
            "udpin:0.0.0.0:14550",
            2,
            "an RTCM source is tcp:HOST:PORT, serial:DEVICE:BAUD or a file",
        ),
        ("tcp:127.0.0.1", 2, "missing port"),
        (
            "/nonexistent/base.rtcm3",
            1,
            "cannot open /nonexistent/base.rtcm3: No such file",
        ),
    ] {
        let out = mavstack(&[
            "rtk",
            "udpout:127.0.0.1:9",
            "--from",
            source,
            "--timeout",
            "1",
        ])
        .output()
        .expect("runs");
        assert_eq!(
            out.status.code(),
            Some(code),
            "{source}: {}",
            text(&out.stderr)
        );
        assert!(
            text(&out.stderr).contains(says),
            "{source}: {}",
            text(&out.stderr)
        );
    }
}
