#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_router::fuzz_router(data));
