#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::gimbal::fuzz_gimbal_angles(data));
