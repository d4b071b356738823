#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::camera::fuzz_camera_definition(data));
