//! The operator tools against independent readers: `mavstack log summary`, `log filter` and
//! `log plot` on tlogs pymavlink 2.4.50 writes, checked against pymavlink's own mavloss.py,
//! mavsummarize.py and mavutil; the `--http` status page of `mavstack router` loaded in
//! Debian's headless chromium (tests-interop/log_tools.py, where each scenario is described).
//!
//! The plot and a screenshot of the page are kept under `target/operator-tools/` for a
//! person to look at. Never skipped: without pymavlink, chromium or chromedriver they fail.

use crate::pymavlink_dialect;
use crate::support;

use std::ffi::OsStr;

use support::{require_pymavlink, run_script, workspace};

fn scenario(name: &str) {
    require_pymavlink();
    pymavlink_dialect::dialect_ready();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let artifacts = workspace().join("target/operator-tools");
    let out = run_script(
        "log_tools.py",
        &[
            OsStr::new(name),
            OsStr::new("--mavstack"),
            OsStr::new(bin),
            OsStr::new("--artifacts"),
            artifacts.as_os_str(),
        ],
    );
    assert!(
        out.starts_with(&format!("{name}: ")) && out.trim_end().ends_with(" ok"),
        "{name}: {out}"
    );
}

#[test]
fn log_summary_agrees_with_mavloss_mavsummarize_and_mavutil() {
    scenario("summary");
}

#[test]
fn log_filter_writes_exactly_the_frames_mavutil_selects() {
    scenario("filter");
}

#[test]
fn log_plot_draws_one_series_per_field_and_system_at_the_size_asked() {
    scenario("plot");
}

#[test]
fn status_page_in_chromium_shows_versions_and_live_rates() {
    scenario("status_page");
}
