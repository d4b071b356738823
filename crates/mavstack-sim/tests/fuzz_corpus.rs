//! The seed corpus of the `param_file` fuzz target, replayed on stable.

use std::path::Path;

#[test]
fn param_file_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/param_file");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).expect("corpus directory") {
        let path = entry.expect("entry").path();
        mavstack_sim::params::fuzz_param_file(&std::fs::read(&path).expect("seed"));
        n += 1;
    }
    assert!(n >= 3, "seed corpus missing: {}", dir.display());
}
