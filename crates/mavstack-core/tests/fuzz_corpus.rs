//! Replays the checked-in seed corpora of the `deframer` and `frame` fuzz targets
//! (fuzz/corpus/) on stable Rust.

use std::path::Path;

fn replay(target: &str, run: fn(&[u8])) -> usize {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(target);
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).expect("corpus folder exists") {
        let data = std::fs::read(entry.expect("entry").path()).expect("readable seed");
        run(&data);
        // Every prefix too: truncated frames at every length.
        for end in (0..data.len()).step_by(7) {
            run(&data[..end]);
        }
        count += 1;
    }
    count
}

#[test]
fn deframer_seeds() {
    assert!(replay("deframer", mavstack_core::fuzz_deframer) >= 16);
}

#[test]
fn frame_seeds() {
    assert!(replay("frame", mavstack_core::fuzz_frame) >= 4);
}
