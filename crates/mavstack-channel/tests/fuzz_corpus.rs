//! Replays the checked-in seed corpus of the `channel` fuzz target (fuzz/corpus/channel) on
//! stable Rust: whole seeds and every seventh prefix.

use std::path::Path;

#[test]
fn channel_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/channel");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).expect("corpus folder exists") {
        let data = std::fs::read(entry.expect("entry").path()).expect("readable seed");
        mavstack_channel::fuzz_channel(&data);
        for end in (0..data.len()).step_by(7) {
            mavstack_channel::fuzz_channel(&data[..end]);
        }
        count += 1;
    }
    assert!(count >= 16, "only {count} seeds");
}
