//! The seed corpora of the payload fuzz targets, replayed on stable: quaternions and
//! GIMBAL_DEVICE_ATTITUDE_STATUS payloads (`gimbal_angles`: finite angles within their
//! ranges for every rotation, `None` for the rest), and camera definition files
//! (`camera_definition`: the simulated camera's, ranges, exclusions naming nothing, an
//! unclosed element, a default out of its type's range, an entity bomb, another XML
//! format, binary). Each seed's properties are the target's own (see
//! `fuzz_gimbal_angles`, `fuzz_camera_definition`).

#[test]
fn gimbal_angles_seeds() {
    for seed in mavstack_core::fuzz_seeds("gimbal_angles", 4) {
        mavstack_services::gimbal::fuzz_gimbal_angles(&seed);
    }
}

#[test]
fn camera_definition_seeds() {
    for seed in mavstack_core::fuzz_seeds("camera_definition", 7) {
        mavstack_services::camera::fuzz_camera_definition(&seed);
    }
}
