#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_xml::json::fuzz_json_frames(data));
