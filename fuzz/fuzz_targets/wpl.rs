#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::wpl::fuzz_wpl(data));
