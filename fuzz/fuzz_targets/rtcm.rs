#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::rtcm::fuzz_rtcm(data));
