#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_dialect::fuzz_dialect_xml(data));
