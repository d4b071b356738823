//! What the interop tests share: the workspace, the Python with pymavlink (the peer), and
//! running its harness scripts.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The pymavlink release the expectations come from.
pub(crate) const PYMAVLINK: &str = "2.4.50";

pub(crate) fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("workspace root")
}

pub(crate) fn script(name: &str) -> PathBuf {
    workspace().join("tests-interop").join(name)
}

pub(crate) fn python() -> PathBuf {
    std::env::var_os("MAVSTACK_PYTHON")
        .filter(|p| !p.is_empty())
        .map_or_else(|| workspace().join(".venv/bin/python"), PathBuf::from)
}

pub(crate) fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Fails (never skips) unless the python runs and has pymavlink 2.4.50; checked once.
pub(crate) fn require_pymavlink() {
    static CHECKED: OnceLock<Result<(), String>> = OnceLock::new();
    let checked = CHECKED.get_or_init(|| {
        let py = python();
        let probe = "from importlib.metadata import version; import pymavlink.dialects.v20.all; \
                     print(version('pymavlink'))";
        let out = Command::new(&py).args(["-c", probe]).output().map_err(|e| {
            format!(
                "cannot run python {}: {e}. Run scripts/setup-peers.sh or set MAVSTACK_PYTHON",
                py.display()
            )
        })?;
        if !out.status.success() {
            return Err(format!(
                "python {} has no usable pymavlink: {}. Run scripts/setup-peers.sh or set MAVSTACK_PYTHON",
                py.display(),
                text(&out.stderr).trim()
            ));
        }
        let version = text(&out.stdout).trim().to_owned();
        if version != PYMAVLINK {
            return Err(format!(
                "python {} has pymavlink {version}, the expectations need {PYMAVLINK}. Run scripts/setup-peers.sh",
                py.display()
            ));
        }
        Ok(())
    });
    if let Err(e) = checked {
        panic!("interop tests need pymavlink: {e}");
    }
}

/// Runs a harness script; panics with its output unless it succeeds.
pub(crate) fn run_script(name: &str, args: &[&OsStr]) -> String {
    let py = python();
    let out = Command::new(&py)
        .arg(script(name))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {} {name}: {e}", py.display()));
    let stdout = text(&out.stdout);
    assert!(
        out.status.success(),
        "{name} {} failed ({}):\n{stdout}{}",
        args.iter()
            .map(|a| a.to_string_lossy())
            .collect::<Vec<_>>()
            .join(" "),
        out.status,
        text(&out.stderr)
    );
    stdout
}

/// Runs scenario `name` of a harness script that takes `SCENARIO --mavstack BIN` and ends
/// with "<name>: ... ok" (router_interop.py, bridge_interop.py, version_interop.py), against
/// `bin`; panics with its output unless it passes.
pub(crate) fn scenario(script: &str, name: &str, bin: &str) {
    require_pymavlink();
    let out = run_script(
        script,
        &[OsStr::new(name), OsStr::new("--mavstack"), OsStr::new(bin)],
    );
    assert!(
        out.starts_with(&format!("{name}: ")) && out.trim_end().ends_with(" ok"),
        "{name}: {out}"
    );
}
