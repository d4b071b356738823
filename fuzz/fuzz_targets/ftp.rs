#![no_main]
//! MAVFTP: a server fed any requests, a client fed any replies, a file through a lossy wire.
libfuzzer_sys::fuzz_target!(|data: &[u8]| mavstack_services::ftp::fuzz_ftp(data));
