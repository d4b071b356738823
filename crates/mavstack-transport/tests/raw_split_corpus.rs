//! The seed corpus of the `raw_split` fuzz target (streams of the `deframer` target's seeds
//! behind the three bytes that choose parts, window and chunk length) replayed on stable,
//! whole and at every seventh prefix.

#[test]
fn raw_split_seeds() {
    for seed in mavstack_core::fuzz_seeds("raw_split", 4) {
        for end in (0..seed.len()).step_by(7).chain([seed.len()]) {
            mavstack_transport::raw::fuzz_raw_split(&seed[..end]);
        }
    }
}
