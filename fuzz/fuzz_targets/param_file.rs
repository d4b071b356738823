#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_sim::params::fuzz_param_file(data));
