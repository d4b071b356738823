#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_transport::raw::fuzz_raw_split(data));
