#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::shell::fuzz_serial_control(data));
