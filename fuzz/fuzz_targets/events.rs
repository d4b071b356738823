#![no_main]
//! Event metadata (libevents JSON, xz-packed or not) from a vehicle: read, unpacked, used to
//! fill EVENTs.
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack::events::fuzz_events(data));
