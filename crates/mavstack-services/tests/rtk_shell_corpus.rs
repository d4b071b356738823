//! The seed corpora of the `rtcm` and `serial_control` fuzz targets, replayed on stable:
//! RTCM3 streams (a base station's frames, one of exactly 360 and 720 bytes, one over 720,
//! garbage, a damaged and a cut frame, a false start) through the deframer, the
//! GPS_RTCM_DATA fragmenter and the reassembler; SERIAL_CONTROL replies (from others, of
//! another device, with a count over 70, escape sequences) through a shell session and a
//! command's transcript. Each seed's properties are the targets' own (see `fuzz_rtcm`,
//! `fuzz_serial_control`).

#[test]
fn rtcm_seeds() {
    for seed in mavstack_core::fuzz_seeds("rtcm", 7) {
        mavstack_services::rtcm::fuzz_rtcm(&seed);
    }
}

#[test]
fn serial_control_seeds() {
    for seed in mavstack_core::fuzz_seeds("serial_control", 4) {
        mavstack_services::shell::fuzz_serial_control(&seed);
    }
}
