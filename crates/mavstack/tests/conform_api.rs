//! `mavstack::conform` against the in-process simulated vehicle and ground station: a
//! conforming vehicle passes every rule that applies, a MAVLink 1-only link is graded as one
//! (NACK, no capability), and a ground-station node's handshake and switch pass.
#![cfg(feature = "sim")]

use core::time::Duration;

use mavstack::conform::{
    GcsOptions, Rule, Status, VehicleMode, VehicleOptions, grade_ground_station, grade_vehicle,
};
use mavstack::router::{LinkRole, ProtocolVersionSupport};
use mavstack::sim::Autopilot;
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{System, Wanted};
use mavstack::{LinkSpec, Node};

fn spec(s: &str) -> LinkSpec {
    LinkSpec::parse(s, &|_| None).expect("spec")
}

async fn grade_sim(link_options: &str) -> mavstack::conform::Report {
    grade_sim_answering(link_options, ProtocolVersionSupport::Answer).await
}

async fn grade_sim_answering(
    link_options: &str,
    protocol_version: ProtocolVersionSupport,
) -> mavstack::conform::Report {
    let vehicle = SimVehicle::start(
        Node::builder()
            .link(spec(&format!("udpin:127.0.0.1:0{link_options}")))
            .role(LinkRole::Vehicle { protocol_version }),
        SimVehicle::config(
            Autopilot::Ardupilot,
            mavstack::sim::params::defaults(Autopilot::Ardupilot),
        ),
    )
    .await
    .expect("vehicle starts");
    let port = vehicle.node().local_addrs()[0].expect("bound").port();
    let gcs = Node::builder()
        .link(spec(&format!("udpout:127.0.0.1:{port}")))
        .start()
        .await
        .expect("conform's node starts");
    let options = VehicleOptions {
        timeout: Duration::from_secs(5),
        ..VehicleOptions::default()
    };
    // Conform's waits end by its own deadlines; the bound here only keeps a hung run from
    // hanging the test, it measures nothing.
    let report = tokio::time::timeout(HUNG, grade_vehicle(&gcs.handle(), &options))
        .await
        .expect("conform stops waiting by itself");
    gcs.shutdown().await.expect("stops");
    vehicle.shutdown().await.expect("stops");
    report
}

/// How long a test waits for a conform run before it calls it hung.
const HUNG: Duration = Duration::from_secs(120);

fn status(report: &mavstack::conform::Report, rule: Rule) -> Status {
    report
        .verdict(rule)
        .map(|v| v.status)
        .expect("the rule is graded")
}

#[tokio::test]
async fn the_simulated_vehicle_conforms() {
    let report = grade_sim("").await;
    let failed: Vec<_> = report
        .verdicts
        .iter()
        .filter(|v| v.status == Status::Fail)
        .collect();
    assert!(failed.is_empty(), "{failed:#?}");
    assert_eq!(report.target, Some((1, 1)));
    for rule in [
        Rule::Heartbeat,
        Rule::Crc,
        Rule::Truncation,
        Rule::CapabilityFlag,
        Rule::SwitchOnV2,
        Rule::HandshakeAnswer,
        Rule::HandshakeV2Framing,
        Rule::Handshake519,
        Rule::HandshakeCommandInt,
        Rule::NoMixing,
    ] {
        assert_eq!(status(&report, rule), Status::Pass, "{rule}: {report:#?}");
    }
    assert_eq!(status(&report, Rule::NackWithoutV2), Status::NotApplicable);
    assert!(report.conforms());
    assert!(
        report.seconds.is_finite() && report.seconds > 0.0,
        "{}",
        report.seconds
    );
}

#[tokio::test]
async fn a_vehicle_that_refuses_protocol_version_like_ardupilot_conforms_by_the_fallback() {
    let report = grade_sim_answering("?version=2", ProtocolVersionSupport::Refuse).await;
    assert!(report.conforms(), "{report:#?}");
    let answer = report.verdict(Rule::HandshakeAnswer).expect("graded");
    assert_eq!(answer.status, Status::Pass, "{answer:?}");
    assert!(
        answer.evidence.contains("COMMAND_ACK FAILED")
            && answer.evidence.contains("AUTOPILOT_VERSION in MAVLink 2"),
        "{}",
        answer.evidence
    );
    // Reported, not graded: PROTOCOL_VERSION is deprecated, command 519 gone from PX4.
    assert_eq!(
        status(&report, Rule::ProtocolVersionSupported),
        Status::Fail
    );
    assert_eq!(status(&report, Rule::Handshake519), Status::Pass);
    assert_eq!(status(&report, Rule::HandshakeCommandInt), Status::Pass);
    assert_eq!(
        status(&report, Rule::HandshakeV2Framing),
        Status::NotApplicable
    );
    assert_eq!(status(&report, Rule::CapabilityFlag), Status::Pass);
}

#[tokio::test]
async fn a_mavlink1_only_link_nacks_and_advertises_no_mavlink2() {
    let report = grade_sim("?version=1").await;
    assert!(report.conforms(), "{report:#?}");
    assert_eq!(status(&report, Rule::NackWithoutV2), Status::Pass);
    assert_eq!(status(&report, Rule::CapabilityFlag), Status::Pass);
    let flag = report.verdict(Rule::CapabilityFlag).expect("graded");
    assert!(
        flag.evidence.starts_with("MAVLINK2 clear"),
        "{}",
        flag.evidence
    );
    assert_eq!(
        status(&report, Rule::HandshakeAnswer),
        Status::NotApplicable
    );
    assert_eq!(status(&report, Rule::Truncation), Status::NotApplicable);
}

#[tokio::test]
async fn nobody_heard_fails_heartbeat_only() {
    let gcs = Node::builder()
        .link(spec("udpin:127.0.0.1:0"))
        .start()
        .await
        .expect("starts");
    let options = VehicleOptions {
        timeout: Duration::from_millis(300),
        ..VehicleOptions::default()
    };
    let report = grade_vehicle(&gcs.handle(), &options).await;
    assert_eq!(report.target, None);
    assert_eq!(status(&report, Rule::Heartbeat), Status::Fail);
    assert_eq!(report.count(Status::Fail), 1);
    assert!(!report.conforms());
    gcs.shutdown().await.expect("stops");
}

#[tokio::test]
async fn a_ground_station_node_requests_in_mavlink2_and_switches() {
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port();
    let grading = tokio::spawn(async move {
        let options = GcsOptions {
            timeout: Duration::from_secs(5),
            mode: VehicleMode::Answer,
            watch: Duration::from_secs(6),
            ..GcsOptions::default()
        };
        grade_ground_station(spec(&format!("udpin:127.0.0.1:{port}")), &options).await
    });
    tokio::time::sleep(Duration::from_millis(200)).await;
    let gcs = Node::ground_station(255, 190)
        .link(spec(&format!("udpout:127.0.0.1:{port}")))
        .start()
        .await
        .expect("ground station starts");
    // Finding the vehicle runs the handshake (the vehicle starts in MAVLink 1).
    let vehicle = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the simulated vehicle is found");
    assert_eq!(vehicle.link_version().await, Some("2"));
    let report = grading.await.expect("joins").expect("grades");
    gcs.shutdown().await.expect("stops");
    assert_eq!(report.target, Some((255, 190)));
    for rule in [
        Rule::GcsHandshakeV2Framing,
        Rule::GcsSwitch,
        Rule::GcsNoMixing,
    ] {
        assert_eq!(status(&report, rule), Status::Pass, "{rule}: {report:#?}");
    }
    assert_eq!(status(&report, Rule::GcsFallback), Status::NotApplicable);
}
