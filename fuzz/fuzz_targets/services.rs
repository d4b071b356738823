#![no_main]
//! The services fed any messages from anyone, their heap counted by the allocator.
use stats_alloc::{INSTRUMENTED_SYSTEM, StatsAlloc};
use std::alloc::System;

#[global_allocator]
static HEAP: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn live_bytes() -> Option<usize> {
    let s = HEAP.stats();
    let live = s.bytes_allocated as isize - s.bytes_deallocated as isize + s.bytes_reallocated;
    usize::try_from(live).ok()
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::fuzz_services(data, &live_bytes));
