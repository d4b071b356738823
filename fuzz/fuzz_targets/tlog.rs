#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_transport::tlog::fuzz_tlog(data));
