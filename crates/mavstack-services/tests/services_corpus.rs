//! The seed corpus of the `services` fuzz target replayed on stable, with the heap counted
//! by the allocator: every service of the crate fed messages pymavlink packed (and random
//! ones) from any sender, and never holding more than `HEAP_BOUND` bytes more than at the
//! start. One test in its own binary, so that no other test's allocations are counted.

use std::alloc::System;

use stats_alloc::{INSTRUMENTED_SYSTEM, StatsAlloc};

#[global_allocator]
static HEAP: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn live_bytes() -> Option<usize> {
    let s = HEAP.stats();
    let allocated = isize::try_from(s.bytes_allocated).ok()?;
    let freed = isize::try_from(s.bytes_deallocated).ok()?;
    usize::try_from(allocated - freed + s.bytes_reallocated).ok()
}

#[test]
fn services_seeds_stay_within_their_heap_bound() {
    for seed in mavstack_core::fuzz_seeds("services", 8) {
        mavstack_services::fuzz_services(&seed, &live_bytes);
    }
    // The counter counts: a megabyte held shows.
    let before = live_bytes().expect("counted");
    let held = vec![1u8; 1 << 20];
    assert!(live_bytes().expect("counted") >= before + held.len());
}
