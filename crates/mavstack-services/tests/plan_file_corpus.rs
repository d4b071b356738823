//! The seed corpora of the `wpl` and `mission_file` fuzz targets, replayed on stable, and
//! the errors and units of the WPL format.

use mavstack_dialects::common::{MavCmd, MavFrame};
use mavstack_services::wpl::{self, WplError};

#[cfg(feature = "fuzzing")]
#[test]
fn wpl_seeds() {
    for seed in mavstack_core::fuzz_seeds("wpl", 4) {
        wpl::fuzz_wpl(&seed);
    }
}

#[cfg(all(feature = "json", feature = "fuzzing"))]
#[test]
fn mission_file_seeds() {
    for seed in mavstack_core::fuzz_seeds("mission_file", 4) {
        mavstack_services::mission_json::fuzz_mission_json(&seed);
        wpl::fuzz_wpl(&seed);
    }
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
