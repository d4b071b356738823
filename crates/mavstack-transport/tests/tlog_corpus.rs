//! The seed corpus of the `tlog` fuzz target (records of frames pymavlink packed, clean and
//! damaged; fuzz/make_seeds.py) replayed on stable, whole and at every fifth prefix.

use std::path::Path;

#[test]
fn tlog_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/tlog");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("corpus directory") {
        let data = std::fs::read(entry.expect("entry").path()).expect("seed");
        for end in (0..data.len()).step_by(5).chain([data.len()]) {
            mavstack_transport::tlog::fuzz_tlog(&data[..end]);
        }
        n += 1;
    }
    assert!(n >= 4, "seed corpus missing: {}", dir.display());
}
