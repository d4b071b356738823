//! The pymavlink dialect generated from our definitions (PROTOCOL_VERSION included), for the
//! scenarios that need it: included with `#[path]` by the test binaries that use it.

use std::ffi::OsStr;
use std::process::Command;
use std::sync::OnceLock;

use super::support::{python, script, text};

/// Generates the pymavlink dialect once, before scenarios run in parallel (its cache is
/// written by whichever process comes first).
pub(crate) fn dialect_ready() {
    static READY: OnceLock<Result<(), String>> = OnceLock::new();
    let ready = READY.get_or_init(|| {
        let dir = script("");
        let code = "import sys; sys.path.insert(0, sys.argv[1]); import mavstack_dialect; \
                    print(mavstack_dialect.load().MAVLINK_MSG_ID_PROTOCOL_VERSION)";
        let out = Command::new(python())
            .args([OsStr::new("-c"), OsStr::new(code), dir.as_os_str()])
            .output()
            .map_err(|e| format!("cannot run python: {e}"))?;
        if out.status.success() && text(&out.stdout).trim() == "300" {
            Ok(())
        } else {
            Err(format!(
                "mavstack_dialect.load() failed ({}): {}{}",
                out.status,
                text(&out.stdout),
                text(&out.stderr)
            ))
        }
    });
    if let Err(e) = ready {
        panic!("pymavlink dialect with PROTOCOL_VERSION: {e}");
    }
}
