#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack::web::json::fuzz_web_json(data));
