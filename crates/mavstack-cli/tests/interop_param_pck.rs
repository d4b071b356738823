//! Parameters over MAVFTP (`@PARAM/param.pck`): `tests-interop/param_pck_interop.py` reads
//! `mavstack vehicle`'s packed file with pymavlink 2.4.50's MAVFTP (`cmd_get` decoded by its
//! own `ftp_param_decode`, and `cmd_getparams` with defaults) and compares it with
//! PARAM_REQUEST_LIST, for both flavours; `mavstack param list --via ftp|list|auto` prints
//! the same table every way. Uploads: MAVProxy 1.8.75's `param ftpload` and `mavstack param
//! load --via ftp|set` change the vehicle's values, read back by MAVProxy and pymavlink.
//!
//! Never skipped: without pymavlink 2.4.50 the script test fails.

use crate::support;
use crate::vehicle;

use std::ffi::OsStr;
use std::process::{Command, Output};

use support::{require_pymavlink, run_script};
use vehicle::Vehicle;

#[test]
fn pymavlink_reads_the_packed_parameters_as_param_request_list_gives_them() {
    require_pymavlink();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "param_pck_interop.py",
        &[OsStr::new("--mavstack"), OsStr::new(bin)],
    );
    assert!(
        !out.lines().any(|l| l.starts_with("FAIL"))
            && out.lines().any(|l| l == "param_pck_interop: all ok"),
        "{out}"
    );
    for flavour in ["ardupilot", "px4"] {
        assert!(
            out.lines()
                .any(|l| l.starts_with(&format!("ok {flavour}: ")) && l.contains("same names")),
            "{flavour}:\n{out}"
        );
    }
    for upload in [
        "ok upload: MAVProxy param ftpload set ",
        "ok upload: mavstack param load --via ftp set 4 parameters",
        "ok upload: mavstack param load --via set set 4 parameters",
    ] {
        assert!(
            out.lines().any(|l| l.starts_with(upload)),
            "{upload}:\n{out}"
        );
    }
}

fn param_list(port: u16, via: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(["param", "list"])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .args(["--via", via, "--timeout", "5"])
        .output()
        .expect("mavstack runs")
}

fn ok(out: &Output) -> (String, String) {
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    );
    assert!(out.status.success(), "{stdout}\n{stderr}");
    (stdout, stderr)
}

#[test]
fn param_list_prints_the_same_table_via_ftp_list_and_auto() {
    for flavour in ["ardupilot", "px4"] {
        let v = Vehicle::start(&["--autopilot", flavour]);
        let (by_list, said) = ok(&param_list(v.port, "list"));
        assert!(said.contains("(PARAM_REQUEST_LIST)"), "{said}");
        let (by_ftp, said) = ok(&param_list(v.port, "ftp"));
        assert!(said.contains("(MAVFTP)"), "{said}");
        let (by_auto, said) = ok(&param_list(v.port, "auto"));
        assert!(said.contains("(MAVFTP)"), "auto chose MAVFTP: {said}");
        assert!(by_list.lines().count() > 30, "{by_list}");
        assert_eq!(by_ftp, by_list, "{flavour}");
        assert_eq!(by_auto, by_list, "{flavour}");
    }
}
