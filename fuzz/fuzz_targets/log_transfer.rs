#![no_main]
//! Log download (LOG_*): a server fed any requests, a client fed any answers, a log through a
//! lossy wire.
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::log_transfer::fuzz_log_transfer(data));
