//! `mavstack::probe` against the in-process simulated vehicle: a vehicle that answers
//! PROTOCOL_VERSION switches from MAVLink 1 to 2 and says MAVLINK2 in AUTOPILOT_VERSION; one
//! that refuses it as ArduPilot does is proven MAVLink 2 by the fallback; a link where nobody
//! answers is an error naming the link without its key. `mavstack probe`'s JSON is checked
//! against pymavlink vehicles in `crates/mavstack-cli/tests/interop_versions.rs`.
#![cfg(feature = "sim")]

use core::time::Duration;

use mavstack::channel::{HandshakeMethod, HandshakeResult};
use mavstack::core::wire::Version;
use mavstack::dialects::common::{MavAutopilot, MavType};
use mavstack::probe::{self, ProbeError, ProbeOptions, ProbedSystem};
use mavstack::router::{LinkRole, ProtocolVersionSupport};
use mavstack::sim::Autopilot;
use mavstack::sim_vehicle::SimVehicle;
use mavstack::{LinkSpec, Node};

fn spec(s: &str) -> LinkSpec {
    LinkSpec::parse(s, &|_| None).expect("spec")
}

/// How long a test waits for a probe before it calls it hung: the probe's own waits end
/// it well before; this bound measures nothing.
const HUNG: Duration = Duration::from_secs(120);

/// Probes a simulated ArduPilot vehicle that treats PROTOCOL_VERSION as `support` says.
async fn probe_sim(support: ProtocolVersionSupport) -> Vec<ProbedSystem> {
    let vehicle = SimVehicle::start(
        Node::builder()
            .link(spec("udpin:127.0.0.1:0"))
            .role(LinkRole::Vehicle {
                protocol_version: support,
            }),
        SimVehicle::config(
            Autopilot::Ardupilot,
            mavstack::sim::params::defaults(Autopilot::Ardupilot),
        ),
    )
    .await
    .expect("vehicle starts");
    let port = vehicle.node().local_addrs()[0].expect("bound").port();
    let probed = tokio::time::timeout(
        HUNG,
        probe::run(
            spec(&format!("udpout:127.0.0.1:{port}")),
            &ProbeOptions::default(),
        ),
    )
    .await
    .expect("the probe ends by itself")
    .expect("a system found");
    vehicle.shutdown().await.expect("stops");
    probed
}

#[tokio::test]
async fn a_vehicle_that_answers_switches_to_mavlink2() {
    let systems = probe_sim(ProtocolVersionSupport::Answer).await;
    assert_eq!(systems.len(), 1, "{systems:#?}");
    let s = &systems[0];
    assert_eq!((s.system_id, s.component_id), (1, 1));
    assert_eq!(s.autopilot, MavAutopilot::ARDUPILOTMEGA);
    assert_ne!(s.kind, MavType::GCS);
    assert_eq!(
        (s.version_before, s.version_after),
        (Version::V1, Version::V2)
    );
    assert!(
        matches!(
            s.handshake.map(|o| o.result),
            Some(HandshakeResult::ProtocolVersion(_))
        ),
        "{s:#?}"
    );
    assert_eq!(s.handshake_method, HandshakeMethod::RequestMessage300);
    assert_eq!(s.handshake_result(), "protocol_version");
    assert_eq!(s.protocol_version_supported, None);
    assert_eq!(s.mavlink2_capability, Some(true));
    assert!(!s.signed);
}

#[tokio::test]
async fn a_vehicle_that_refuses_protocol_version_is_proven_by_the_fallback() {
    let systems = probe_sim(ProtocolVersionSupport::Refuse).await;
    assert_eq!(systems.len(), 1, "{systems:#?}");
    let s = &systems[0];
    assert!(s.handshake.is_some_and(|o| o.fallback.is_some()), "{s:#?}");
    assert_eq!(s.handshake_result(), "message_v2", "{s:#?}");
    assert!(
        matches!(
            s.handshake_method,
            HandshakeMethod::RequestMessageOther { .. }
        ),
        "{s:#?}"
    );
    assert_eq!(s.protocol_version_supported, Some(false));
    assert_eq!(s.version_after, Version::V2);
}

#[tokio::test]
async fn nobody_on_the_link_is_an_error_naming_it_without_its_key() {
    let key = "ab".repeat(32);
    let options = ProbeOptions::default().wait(Duration::from_millis(300));
    let e = probe::run(spec(&format!("udpin:127.0.0.1:0?key={key}")), &options)
        .await
        .expect_err("nobody there");
    assert!(matches!(e, ProbeError::NotFound { .. }), "{e:?}");
    assert_eq!(
        e.to_string(),
        "no system found on udpin:127.0.0.1:0?key=<redacted> within 0.3 s"
    );
    assert!(!format!("{e:?}").contains(&key));
}
