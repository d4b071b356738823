//! The seed corpora of the `wpl` and `mission_json` fuzz targets, replayed on stable, and
//! the errors and units of the WPL format.

use std::path::Path;

use mavstack_dialects::common::{MavCmd, MavFrame};
use mavstack_services::wpl::{self, WplError};

#[test]
fn wpl_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/wpl");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("corpus directory") {
        let path = entry.expect("entry").path();
        wpl::fuzz_wpl(&std::fs::read(&path).expect("seed"));
        n += 1;
    }
    assert!(n >= 4, "seed corpus missing: {}", dir.display());
}

#[cfg(feature = "json")]
#[test]
fn mission_json_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/mission_json");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("corpus directory") {
        let data = std::fs::read(entry.expect("entry").path()).expect("seed");
        mavstack_services::mission_json::fuzz_mission_json(&data);
        n += 1;
    }
    assert!(n >= 4, "seed corpus missing: {}", dir.display());
}

#[test]
fn errors_name_the_line_and_the_field() {
    let e = wpl::parse("QGC WPL 110\n\n0\t1\t0\t16\t1e39\t0\t0\t0\t1\t2\t3\t1\n").unwrap_err();
    assert_eq!(
        e,
        WplError::Line {
            line: 3,
            what: "param1 1000000000000000000000000000000000000000 is beyond the range of a 32-bit float"
                .to_owned()
        }
    );
    let e = wpl::parse("QGC WPL 110\n0 1 300 16 0 0 0 0 1 2 3 1\n").unwrap_err();
    assert_eq!(e.to_string(), "line 2: frame \"300\" is above 255");
    assert_eq!(wpl::parse("").unwrap_err(), WplError::Empty);
}

#[test]
fn local_frames_are_in_metres_times_ten_thousand() {
    let items = wpl::parse("QGC WPL 110\n0 0 1 16 0 0 0 0 12.5 -3.25 -10 1\n").unwrap();
    assert_eq!(items[0].frame, MavFrame::LOCAL_NED);
    assert_eq!((items[0].x, items[0].y), (125_000, -32_500));
    assert_eq!(items[0].command, MavCmd::NAV_WAYPOINT);
}
