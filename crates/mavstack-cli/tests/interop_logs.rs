//! Log download (LOG_*) against independent peers: `tests-interop/log_interop.py` with logs
//! of 1, 90, 91 bytes and 1 MiB served by `mavstack vehicle --log-dir DIR`, downloaded by
//! MAVProxy 1.8.75's log module (`log list`, `log download ID FILE`), by pymavlink 2.4.50
//! doing LOG_REQUEST_LIST / LOG_REQUEST_DATA itself (with the server's answers to a range, to
//! a request at the end, to an unknown id and to LOG_REQUEST_END checked), by MAVSDK 4.1.0's
//! log_files plugin, and by `mavstack log download` (by LOG_DATA, over MAVFTP, and `auto`
//! choosing LOG_DATA); and `mavstack log download` against a log server written with pymavlink
//! that drops 20 % of its LOG_DATA, whose gaps must be asked for again. Every file is
//! compared with the original byte for byte; the script prints the throughput of each
//! download.
//!
//! Never skipped: without pymavlink 2.4.50, MAVProxy or mavsdk the script fails.

use crate::support;

use std::ffi::OsStr;

use support::{require_pymavlink, run_script};

#[test]
fn mavproxy_pymavlink_mavsdk_and_mavstack_download_logs() {
    require_pymavlink();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "log_interop.py",
        &[
            OsStr::new("--mavstack"),
            OsStr::new(bin),
            OsStr::new("--big-kib"),
            OsStr::new("1024"),
        ],
    );
    assert!(
        !out.lines().any(|l| l.starts_with("FAIL"))
            && out.lines().any(|l| l.starts_with("log_interop: all ")),
        "{out}"
    );
    // Every peer downloaded every size.
    for peer in [
        "a mavproxy→mavstack: log download",
        "b pymavlink→mavstack: LOG_REQUEST_DATA log",
        "c mavsdk→mavstack: download_log_file",
        "d mavstack→pymavlink server (20 % LOG_DATA lost): log",
        "e mavstack→mavstack --via log: log",
        "e mavstack→mavstack --via ftp: log",
    ] {
        for size in ["(1 bytes)", "(90 bytes)", "(91 bytes)", "(1048576 bytes)"] {
            assert!(
                out.lines()
                    .any(|l| l.starts_with("ok") && l.contains(peer) && l.contains(size)),
                "{peer} {size} missing:\n{out}"
            );
        }
    }
    assert!(
        out.lines()
            .any(|l| l.starts_with("ok") && l.contains("gaps were asked for again")),
        "{out}"
    );
    // The throughput of each download, in the test's output.
    for line in out.lines().filter(|l| l.starts_with("throughput")) {
        println!("{line}");
    }
}
