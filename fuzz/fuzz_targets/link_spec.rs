#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack::link_spec::fuzz_link_spec(data));
