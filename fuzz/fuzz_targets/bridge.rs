#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_bridge::fuzzing::fuzz_bridge(data));
