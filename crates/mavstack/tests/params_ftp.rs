//! Parameters over MAVFTP: `System::params_via_ftp` reads the simulated vehicle's
//! `@PARAM/param.pck` and gets the table `System::params` (PARAM_REQUEST_LIST) gets, for
//! both flavours; the file follows PARAM_SET; a vehicle without MAVFTP does not advertise it.
#![cfg(feature = "sim")]

use core::time::Duration;
use std::time::Instant;

use mavstack::dialects::common::MavProtocolCapability;
use mavstack::router::{LinkRole, ProtocolVersionSupport};
use mavstack::services::param::{Name, Value};
use mavstack::sim::{Autopilot, SimConfig, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{PATIENT_RETRIES, ParamsVia, System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};

fn none(_: &str) -> Option<u32> {
    None
}

async fn vehicle_and_gcs(config: SimConfig) -> (SimVehicle, Node) {
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
    (vehicle, gcs)
}

/// The vehicle as a `System` of the ground station, and whether it advertises MAVFTP.
async fn found(gcs: &Node) -> (System, bool) {
    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the vehicle is found");
    let caps = v
        .capabilities(Duration::from_secs(3))
        .await
        .expect("AUTOPILOT_VERSION");
    (v, caps.contains(MavProtocolCapability::FTP))
}

/// Values compared bit for bit (NaN equals NaN).
fn same(a: &[(Name, Value)], b: &[(Name, Value)]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.0 == y.0 && x.1.same_as(y.1))
}

#[tokio::test]
async fn params_via_ftp_equal_params_for_both_flavours() {
    for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
        let defaults = params::defaults(autopilot);
        let (vehicle, gcs) = vehicle_and_gcs(SimVehicle::config(autopilot, defaults.clone())).await;
        let (v, ftp) = found(&gcs).await;
        assert!(ftp, "{autopilot}");

        let t = Instant::now();
        let listed = v.params().get_all().await.expect("PARAM_REQUEST_LIST");
        let by_list = t.elapsed();
        let t = Instant::now();
        let by_ftp_table = v
            .params()
            .get_all_via_ftp(|_, _| {})
            .await
            .expect("param.pck");
        let by_ftp = t.elapsed();
        eprintln!(
            "{autopilot}: {} parameters, list {by_list:?}, ftp {by_ftp:?}",
            listed.len()
        );
        assert!(
            same(&listed, &by_ftp_table),
            "{autopilot}: {listed:?} != {by_ftp_table:?}"
        );
        assert_eq!(listed.len(), defaults.len());
        let (auto, way) = v
            .params()
            .get_all_via(ParamsVia::Auto, |_, _, _| {})
            .await
            .expect("the table, auto");
        assert_eq!(way, ParamsVia::Ftp, "{autopilot}: advertised, so by MAVFTP");
        assert!(same(&listed, &auto), "{autopilot}");

        // The file is made from the table as it is when opened.
        let (name, old) = listed
            .iter()
            .copied()
            .find(|(_, v)| matches!(v, Value::F32(_)))
            .expect("a float parameter");
        let new = Value::F32(old.as_f64() as f32 + 3.0);
        v.params().set(name, new).await.expect("PARAM_SET");
        let after = v
            .params()
            .get_all_via_ftp(|_, _| {})
            .await
            .expect("param.pck again");
        let got = after.iter().find(|(n, _)| *n == name).expect("still there");
        assert!(got.1.same_as(new), "{autopilot}: {got:?}");

        gcs.shutdown().await.expect("gcs stops");
        vehicle.shutdown().await.expect("vehicle stops");
    }
}

#[tokio::test]
async fn a_vehicle_without_mavftp_does_not_advertise_it_and_has_no_file() {
    let config = SimConfig {
        ftp: false,
        ..SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot))
    };
    let (vehicle, gcs) = vehicle_and_gcs(config).await;
    let (v, ftp) = found(&gcs).await;
    assert!(!ftp);
    v.set_retries(1);
    let err = v
        .params()
        .get_all_via_ftp(|_, _| {})
        .await
        .expect_err("nobody answers MAVFTP");
    assert!(matches!(err, SystemError::Ftp { .. }), "{err}");
    // Auto asks nothing of MAVFTP here: the table comes by PARAM_REQUEST_LIST.
    v.set_retries(PATIENT_RETRIES);
    let (table, way) = v
        .params()
        .get_all_via(ParamsVia::Auto, |_, _, _| {})
        .await
        .expect("the table");
    assert_eq!(way, ParamsVia::List);
    assert_eq!(table.len(), params::defaults(Autopilot::Ardupilot).len());
    gcs.shutdown().await.expect("gcs stops");
    vehicle.shutdown().await.expect("vehicle stops");
}

#[tokio::test]
async fn a_long_table_comes_whole_both_ways() {
    let table: Vec<(Name, Value)> = (0..1000)
        .map(|i| {
            let name = Name::new(&format!("GRP{}_PARAM_{i}", i % 7)).expect("name");
            let value = if i % 3 == 0 {
                Value::I32(i * 1000)
            } else {
                Value::F32(i as f32 / 7.0)
            };
            (name, value)
        })
        .collect();
    let (vehicle, gcs) = vehicle_and_gcs(SimVehicle::config(Autopilot::Px4, table.clone())).await;
    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the vehicle is found");
    let t = Instant::now();
    let listed = v.params().get_all().await.expect("PARAM_REQUEST_LIST");
    let by_list = t.elapsed();
    let t = Instant::now();
    let by_ftp_table = v
        .params()
        .get_all_via_ftp(|_, _| {})
        .await
        .expect("param.pck");
    let by_ftp = t.elapsed();
    eprintln!("1000 parameters: list {by_list:?}, ftp {by_ftp:?}");
    assert!(same(&listed, &table));
    assert!(same(&by_ftp_table, &table));
    gcs.shutdown().await.expect("gcs stops");
    vehicle.shutdown().await.expect("vehicle stops");
}
