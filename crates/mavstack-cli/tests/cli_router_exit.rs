//! `mavstack router` as a daemon (`docs/operations.md`): when its node stops on its own it
//! exits 1 with the reason, with or without `--stats`, instead of staying up forwarding
//! nothing. The failure is real: the router runs under a file-size limit (`ulimit -f`, with
//! SIGXFSZ ignored, as a full disk it makes `write` fail: EFBIG instead of ENOSPC), and its
//! `--log` tlog outgrows it while HEARTBEATs arrive.

use core::time::Duration;
use std::io::Read as _;
use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::Instant;

/// A MAVLink 2 HEARTBEAT with a good checksum (the tlog module's example frame).
const HEARTBEAT: [u8; 21] = [
    0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74,
];

fn free_port() -> u16 {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.local_addr().unwrap().port()
}

#[test]
fn a_router_whose_log_cannot_be_written_exits_1_naming_the_file() {
    let dir = std::env::temp_dir().join(format!("router-exit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_port();
    // 8 blocks of 512 bytes: the log fails after about 140 records.
    let script = r#"trap "" XFSZ; ulimit -f 8 || exit 97; exec "$0" "$@""#;
    let mut router = Command::new("sh")
        .args(["-c", script, env!("CARGO_BIN_EXE_mavstack"), "router"])
        .arg(format!("udpin:127.0.0.1:{port}?name=in"))
        .arg("--log")
        .arg(&dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = router.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });
    let sender = UdpSocket::bind("127.0.0.1:0").unwrap();
    // Sends until the router exits (a bounded wait: 20 s).
    let deadline = Instant::now() + Duration::from_secs(20);
    let status = loop {
        if let Some(status) = router.try_wait().unwrap() {
            break Some(status);
        }
        if Instant::now() > deadline {
            break None;
        }
        for _ in 0..50 {
            let _ = sender.send_to(&HEARTBEAT, ("127.0.0.1", port));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    if status.is_none() {
        let _ = router.kill();
        let _ = router.wait();
    }
    let text = reader.join().unwrap();
    let logs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    std::fs::remove_dir_all(&dir).unwrap();
    let status = status
        .unwrap_or_else(|| panic!("the router kept running after its log failed; stderr:\n{text}"));
    assert_eq!(status.code(), Some(1), "stderr:\n{text}");
    assert_eq!(logs.len(), 1, "{logs:?}");
    let name = logs[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(
        name.starts_with("mavstack-") && name.ends_with(".tlog") && name.len() == 29,
        "log name {name}"
    );
    let last = text.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: the router stopped: log ") && last.contains(&name),
        "last stderr line {last:?}; stderr:\n{text}"
    );
}
