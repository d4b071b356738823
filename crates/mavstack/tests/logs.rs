//! Log download over real sockets: `System::log_list`, `log_download` and `log_erase`
//! against the simulated vehicle on loopback UDP, with its generated logs and with a
//! directory's files (also read over MAVFTP as `APM/LOGS/0000000N.BIN`).
#![cfg(feature = "sim")]

use core::time::Duration;

use mavstack::router::{LinkRole, ProtocolVersionSupport};
use mavstack::sim::logs::{GENERATED, LogDir, ftp_path, generated_log};
use mavstack::sim::{Autopilot, SimConfig, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};

fn none(_: &str) -> Option<u32> {
    None
}

async fn vehicle_and_system(config: SimConfig) -> (SimVehicle, Node, System) {
    let vehicle = SimVehicle::start(
        Node::builder()
            .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
            .role(LinkRole::Vehicle {
                protocol_version: ProtocolVersionSupport::Answer,
            }),
        config,
    )
    .await
    .expect("vehicle starts");
    let port = vehicle.node().local_addrs()[0].expect("bound").port();
    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let system = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the vehicle is found");
    (vehicle, gcs, system)
}

fn config() -> SimConfig {
    SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot))
}

#[tokio::test]
async fn the_generated_logs_download_whole_and_erase_empties_the_list() {
    let (vehicle, gcs, v) = vehicle_and_system(config()).await;
    let list = v.logs().list().await.expect("list");
    let want: Vec<(u16, u32, u32)> = GENERATED.to_vec();
    assert_eq!(
        list.iter()
            .map(|e| (e.id, e.time_utc, e.size))
            .collect::<Vec<_>>(),
        want
    );
    let mut last = (0, 0);
    let bytes = v
        .logs()
        .download(2, |done, total| {
            assert!(done >= last.0 && done <= total);
            last = (done, total);
        })
        .await
        .expect("download");
    assert_eq!(bytes, generated_log(2).expect("log 2"));
    assert_eq!(last, (123_457, 123_457));
    let err = v.logs().download(9, |_, _| {}).await.expect_err("no log 9");
    assert!(matches!(err, SystemError::NoSuchLog { id: 9 }), "{err}");
    v.logs().erase().await.expect("erased");
    assert!(v.logs().list().await.expect("list").is_empty());
    gcs.shutdown().await.expect("gcs stops");
    vehicle.shutdown().await.expect("vehicle stops");
}

#[tokio::test]
async fn a_directory_is_served_by_log_download_and_over_mavftp() {
    let dir = tempfile::tempdir().expect("tempdir");
    let files: Vec<(&str, Vec<u8>)> = vec![
        ("a.bin", vec![7]),
        ("b.bin", (0..90u8).collect()),
        ("c.bin", (0..91u8).collect()),
        (
            "d.bin",
            (0..200_000u32).map(|i| ((i * 31) >> 3) as u8).collect(),
        ),
    ];
    for (name, bytes) in &files {
        std::fs::write(dir.path().join(name), bytes).expect("write");
    }
    let config = SimConfig {
        log_dir: Some(LogDir::new(dir.path()).expect("log dir")),
        ..config()
    };
    let (vehicle, gcs, v) = vehicle_and_system(config).await;
    let list = v.logs().list().await.expect("list");
    assert_eq!(
        list.iter().map(|e| (e.id, e.size)).collect::<Vec<_>>(),
        [(1, 1), (2, 90), (3, 91), (4, 200_000)]
    );
    for (id, (name, bytes)) in (1u16..).zip(&files) {
        let got = v.logs().download(id, |_, _| {}).await.expect("download");
        assert_eq!(&got, bytes, "{name} by LOG_DATA");
        let got = v
            .ftp()
            .read(&format!("/{}", ftp_path(id)), |_, _| {})
            .await
            .expect("over MAVFTP");
        assert_eq!(&got, bytes, "{name} over MAVFTP");
    }
    let listing = v.ftp().list("/APM/LOGS").await.expect("ls");
    assert_eq!(listing.len(), 4);
    v.logs().erase().await.expect("erased");
    assert!(
        v.ftp().list("/APM/LOGS").await.is_err(),
        "gone over MAVFTP too"
    );
    assert!(dir.path().join("d.bin").exists(), "the files stay on disk");
    gcs.shutdown().await.expect("gcs stops");
    vehicle.shutdown().await.expect("vehicle stops");
}
