#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_core::fuzz_frame(data));
