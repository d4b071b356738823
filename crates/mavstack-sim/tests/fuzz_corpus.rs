//! The seed corpus of the `param_file` fuzz target, replayed on stable.

#[test]
fn param_file_seeds() {
    for seed in mavstack_core::fuzz_seeds("param_file", 3) {
        mavstack_sim::params::fuzz_param_file(&seed);
    }
}
