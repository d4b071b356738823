//! RTK corrections against an independent peer: `tests-interop/rtk_interop.py` with pymavlink
//! 2.4.50 as the vehicle, which puts GPS_RTCM_DATA back together by its own reading of
//! common.xml. `mavstack rtk --from FILE` and `--from tcp:...` (a server sending the stream
//! in pieces of 1-97 bytes): frames of 9, 180, 181, 360, 540 and 720 bytes arrive whole, in
//! order, byte for byte, between garbage, a damaged frame and an 808-byte frame that never
//! arrive; 360 and 540 bytes end with an empty fragment, 720 with four full ones; one
//! sequence id per message, going up by one. 20 kB of garbage: exit 1, nothing sent.
//!
//! Never skipped: without pymavlink 2.4.50 the script fails.

use crate::support;

use std::ffi::OsStr;

use support::{require_pymavlink, run_script};

#[test]
fn pymavlink_vehicle_reassembles_every_correction() {
    require_pymavlink();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "rtk_interop.py",
        &[OsStr::new("--mavstack"), OsStr::new(bin)],
    );
    assert!(
        !out.lines().any(|l| l.starts_with("FAIL"))
            && out
                .lines()
                .any(|l| l.starts_with("rtk_interop: all 16 checks ok")),
        "{out}"
    );
}
