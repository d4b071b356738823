#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_xml::fuzz_dialect_xml(data));
