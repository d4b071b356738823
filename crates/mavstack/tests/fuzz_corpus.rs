//! The seed corpora of the `router_conf` and `link_options` fuzz targets, replayed on stable.

use std::path::Path;

fn replay(target: &str, f: fn(&[u8])) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(target);
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        f(&std::fs::read(entry.unwrap().path()).unwrap());
        n += 1;
    }
    assert!(n >= 3, "seed corpus missing: {}", dir.display());
}

#[test]
fn router_conf_seeds() {
    replay("router_conf", mavstack::router_conf::fuzz_router_conf);
}

#[test]
fn link_options_seeds() {
    replay("link_options", mavstack::router::fuzz_link_options);
}
