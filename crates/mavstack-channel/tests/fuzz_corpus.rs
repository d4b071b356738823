//! Replays the checked-in seed corpus of the `channel` fuzz target (fuzz/corpus/channel) on
//! stable Rust: whole seeds and every seventh prefix.

#[test]
fn channel_seeds() {
    for data in mavstack_core::fuzz_seeds("channel", 16) {
        mavstack_channel::fuzz_channel(&data);
        for end in (0..data.len()).step_by(7) {
            mavstack_channel::fuzz_channel(&data[..end]);
        }
    }
}
