//! Replays the checked-in seed corpora of the `deframer` and `frame` fuzz targets
//! (fuzz/corpus/) on stable Rust.

fn replay(target: &str, at_least: usize, run: fn(&[u8])) {
    for data in mavstack_core::fuzz_seeds(target, at_least) {
        run(&data);
        // Every prefix too: truncated frames at every length.
        for end in (0..data.len()).step_by(7) {
            run(&data[..end]);
        }
    }
}

#[test]
fn deframer_seeds() {
    replay("deframer", 16, mavstack_core::fuzz_deframer);
}

#[test]
fn frame_seeds() {
    replay("frame", 4, mavstack_core::fuzz_frame);
}
