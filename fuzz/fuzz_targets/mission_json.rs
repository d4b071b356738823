#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::mission_json::fuzz_mission_json(data));
