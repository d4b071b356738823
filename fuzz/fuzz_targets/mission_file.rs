#![no_main]
//! Mission files as `mavstack mission` reads them: JSON plans and QGC WPL 110 text.
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    mavstack_services::mission_json::fuzz_mission_json(data);
    mavstack_services::wpl::fuzz_wpl(data);
});
