//! The seed corpus of the `bridge` fuzz target (fuzz/corpus/bridge), replayed on stable.

#[test]
fn bridge_seeds() {
    for seed in mavstack_core::fuzz_seeds("bridge", 8) {
        mavstack_bridge::fuzzing::fuzz_bridge(&seed);
    }
}
