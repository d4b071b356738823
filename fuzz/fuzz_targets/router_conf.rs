#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack::router_conf::fuzz_router_conf(data));
