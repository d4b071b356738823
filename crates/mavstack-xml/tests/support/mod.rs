//! Running pymavlink (the reference implementation) from tests.
//!
//! The python comes from `MAVSTACK_PYTHON` (default: the workspace's `.venv/bin/python`, which
//! `scripts/test.sh` creates) and needs pymavlink 2.4.50. A missing python or pymavlink fails
//! the test: it is never skipped.

use std::process::Command;

/// The default interpreter, relative to the workspace root: the virtualenv that
/// `scripts/test.sh` sets up with pymavlink.
const DEFAULT_PYTHON: &str = ".venv/bin/python";

/// How to get a python that can run these tests.
const INSTALL: &str = "run scripts/setup-peers.sh (creates .venv with pymavlink==2.4.50), \
                       or set MAVSTACK_PYTHON to a python that has pymavlink 2.4.50";

/// Status with which scripts/pymavlink_definitions.py reports that pymavlink is missing.
const EXIT_NO_PYMAVLINK: i32 = 3;

/// The python interpreter to run.
pub(crate) fn python() -> String {
    std::env::var("MAVSTACK_PYTHON").unwrap_or_else(|_| {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        root.join(DEFAULT_PYTHON).display().to_string()
    })
}

/// Runs python with `args` and returns its standard output; panics with install instructions
/// if python or pymavlink is missing, and with python's error output if it fails otherwise.
pub(crate) fn run_python(args: &[&str]) -> String {
    let python = python();
    let output = Command::new(&python)
        .args(args)
        .output()
        .unwrap_or_else(|e| {
            panic!("cannot run {python:?} ({e}): these tests need pymavlink. Install it: {INSTALL}")
        });
    let stderr = String::from_utf8_lossy(&output.stderr);
    if !output.status.success() {
        if output.status.code() == Some(EXIT_NO_PYMAVLINK)
            || stderr.contains("No module named 'pymavlink'")
        {
            panic!(
                "{python} has no pymavlink ({}). Install it: {INSTALL}",
                stderr.trim()
            );
        }
        panic!("{python} {args:?} failed ({}):\n{stderr}", output.status);
    }
    String::from_utf8(output.stdout).expect("python prints UTF-8")
}
