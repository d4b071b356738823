//! The seed corpus of the `tlog` fuzz target (records of frames pymavlink packed, clean and
//! damaged; fuzz/make_seeds.py) replayed on stable, whole and at every fifth prefix.

#[test]
fn tlog_seeds() {
    for seed in mavstack_core::fuzz_seeds("tlog", 4) {
        for end in (0..seed.len()).step_by(5).chain([seed.len()]) {
            mavstack_transport::tlog::fuzz_tlog(&seed[..end]);
        }
    }
}
