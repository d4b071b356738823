//! The seed corpora of the payload fuzz targets, replayed on stable: quaternions and
//! GIMBAL_DEVICE_ATTITUDE_STATUS payloads (`gimbal_angles`: finite angles within their
//! ranges for every rotation, `None` for the rest). Each seed's properties are the
//! target's own (see `fuzz_gimbal_angles`).

#[test]
fn gimbal_angles_seeds() {
    for seed in mavstack_core::fuzz_seeds("gimbal_angles", 4) {
        mavstack_services::gimbal::fuzz_gimbal_angles(&seed);
    }
}
