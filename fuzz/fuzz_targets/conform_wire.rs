//! `mavstack conform`'s wire reader and graders on arbitrary input (body in
//! `mavstack::conform::fuzz_wire`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack::conform::fuzz_wire(data));
