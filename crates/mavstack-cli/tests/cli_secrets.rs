//! No command shows a signing key: every command that takes a link is run with `?key=` in
//! its link string (and `--key` where it has one), at once, and everything it prints —
//! stdout, stderr, `-v` logs, JSON and `--stats` objects — is searched for the key. Where a
//! command names its link (the "nothing heard" errors, `recording ...`), it shows
//! `key=<redacted>`.

use std::io::Read as _;

use core::time::Duration;
use mavstack_core::wire::{FrameHeader, Version, emit_message};
use mavstack_dialects::common::Heartbeat;
use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};
use std::thread;
use std::time::Instant;

const KEY: &str = "00112233445566778899aabbccddeeff0123456789abcdef0011223344556677";

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port()
}

/// One command to run: its arguments, and whether it must name its link (redacted).
struct Case {
    args: Vec<String>,
    names_link: bool,
}

fn case(args: &[&str], names_link: bool) -> Case {
    Case {
        args: args.iter().map(|a| (*a).to_owned()).collect(),
        names_link,
    }
}

/// Runs `args` for at most `limit` (then SIGTERM, as an operator's Ctrl-C), returning
/// everything it printed.
fn run(args: &[String], limit: Duration) -> String {
    let mut child: Child = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mavstack runs");
    let started = Instant::now();
    while child.try_wait().expect("waits").is_none() {
        if started.elapsed() > limit {
            let _ = Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status();
            break;
        }
        thread::sleep(Duration::from_millis(50));
    }
    let _ = child.wait();
    let mut text = String::new();
    if let Some(mut out) = child.stdout.take() {
        let _ = out.read_to_string(&mut text);
    }
    if let Some(mut err) = child.stderr.take() {
        let _ = err.read_to_string(&mut text);
    }
    text
}

#[test]
fn no_command_prints_a_signing_key() {
    let dir = tempfile::tempdir().expect("tmp");
    let tlog = dir.path().join("x.tlog");
    // A tlog of one HEARTBEAT for `replay`.
    let mut frame = [0u8; 280];
    let header = FrameHeader {
        version: Version::V2,
        seq: 0,
        sysid: 1,
        compid: 1,
        signed: false,
    };
    let len = emit_message(&header, &Heartbeat::default(), &mut frame).expect("emits");
    std::fs::write(&tlog, [&0u64.to_be_bytes()[..], &frame[..len]].concat()).expect("writes");
    let plan = dir.path().join("plan.waypoints");
    std::fs::write(&plan, "QGC WPL 110\n").expect("writes");
    let params = dir.path().join("p.parm");
    std::fs::write(&params, "RTL_ALT 1500\n").expect("writes");
    let rtcm = dir.path().join("base.rtcm3");
    std::fs::write(&rtcm, [0xD3u8, 0, 0, 0x47, 0xEA, 0x4B]).expect("writes");
    let link = || format!("udpin:127.0.0.1:{}?key={KEY}", free_port());
    let gcs = |words: &[&str]| {
        let mut args: Vec<String> = words.iter().map(|w| (*w).to_owned()).collect();
        let at = args.iter().position(|a| a == "LINK").expect("LINK");
        args[at] = link();
        args.extend(["--timeout".to_owned(), "1".to_owned()]);
        args.insert(0, "-v".to_owned());
        Case {
            args,
            names_link: true,
        }
    };
    let tlog = tlog.display().to_string();
    let plan = plan.display().to_string();
    let params = params.display().to_string();
    let rtcm = rtcm.display().to_string();
    let cases = vec![
        gcs(&["param", "list", "LINK"]),
        gcs(&["param", "get", "LINK", "RTL_ALT"]),
        gcs(&["param", "set", "LINK", "RTL_ALT", "1500"]),
        gcs(&["param", "load", "LINK", &params]),
        gcs(&["mission", "download", "LINK"]),
        gcs(&["mission", "upload", "LINK", &plan]),
        gcs(&["mission", "clear", "LINK"]),
        gcs(&["command", "LINK", "arm"]),
        gcs(&["ftp", "ls", "LINK", "/"]),
        gcs(&["log", "list", "LINK"]),
        gcs(&["log", "download", "LINK", "--latest"]),
        gcs(&["signing", "setup", "LINK", "--key", KEY]),
        gcs(&["signing", "remove", "LINK", "--key", KEY]),
        gcs(&["shell", "LINK", "--command", "ver all"]),
        gcs(&["rtk", "LINK", "--from", &rtcm]),
        gcs(&["gimbal", "LINK", "list"]),
        gcs(&["gimbal", "LINK", "set", "-10", "0"]),
        gcs(&["camera", "LINK", "list"]),
        gcs(&["camera", "LINK", "photo", "--json"]),
        gcs(&["probe", "LINK"]),
        Case {
            names_link: false,
            ..gcs(&["conform", "LINK"])
        },
        case(
            &["-v", "listen", &link(), "--duration", "1", "--stats"],
            false,
        ),
        case(
            &[
                "-v",
                "listen",
                &link(),
                "--duration",
                "1",
                "--rate",
                "ATTITUDE:4",
            ],
            false,
        ),
        case(
            &[
                "-v",
                "record",
                &link(),
                &format!("{tlog}.out"),
                "--duration",
                "1",
            ],
            true,
        ),
        case(&["-v", "replay", &tlog, &link()], true),
        case(&["-v", "radio", &link(), &link()], false),
        case(&["-v", "router", &link(), &link(), "--stats", "0.2"], false),
        case(&["-v", "vehicle", &link()], false),
    ];
    let results: Vec<(Vec<String>, bool, String)> = thread::scope(|s| {
        let running: Vec<_> = cases
            .into_iter()
            .map(|c| {
                s.spawn(move || {
                    let out = run(&c.args, Duration::from_secs(20));
                    (c.args, c.names_link, out)
                })
            })
            .collect();
        running
            .into_iter()
            .map(|h| h.join().expect("runs"))
            .collect()
    });
    let mut problems = Vec::new();
    for (args, names_link, out) in &results {
        let shown = args.join(" ").replace(KEY, "KEY");
        // The whole key, and any 16 of its digits in a row.
        let leaked = (0..=KEY.len() - 16).any(|i| out.contains(&KEY[i..i + 16]));
        if leaked {
            problems.push(format!("`mavstack {shown}` printed the key:\n{out}"));
        }
        if *names_link && !out.contains("key=<redacted>") {
            problems.push(format!(
                "`mavstack {shown}` does not name its link as key=<redacted>:\n{out}"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n\n"));
}
