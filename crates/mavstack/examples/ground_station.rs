//! A ground station printing a vehicle's telemetry, against the in-process simulated vehicle:
//!
//! ```text
//! cargo run -p mavstack --features sim --example ground_station -- 3
//! ```
//!
//! prints the vehicle's HEARTBEAT, ATTITUDE and GLOBAL_POSITION_INT for 3 seconds (the
//! argument), then the ground station's link report. Point the ground station at a real
//! vehicle by replacing the `udpout:` link with the vehicle's connection.

use core::time::Duration;

use mavstack::core::MessageSet as _;
use mavstack::dialects::common::{Heartbeat, MavAutopilot, MavMessage, MavType};
use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::{LinkSpec, Node};

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn core::error::Error>> {
    let seconds: f64 = std::env::args()
        .nth(1)
        .map_or(Ok(3.0), |s| s.parse())
        .map_err(|e| format!("seconds: {e}"))?;
    let none = |_: &str| None;

    // The vehicle, in this process, on a UDP port of its own.
    let vehicle = SimVehicle::start(
        Node::builder().link(LinkSpec::parse("udpin:127.0.0.1:0", &none)?),
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot)),
    )
    .await?;
    let port = vehicle
        .node()
        .local_addrs()
        .first()
        .copied()
        .flatten()
        .ok_or("the vehicle has no UDP port")?
        .port();

    // The ground station: system 255, a GCS HEARTBEAT once a second, MAVLink 2 from the start
    // (the vehicle's link switches to MAVLink 2 on its first MAVLink 2 frame).
    let gcs = Node::builder()
        .identity(255, 190)
        .heartbeat(
            &Heartbeat {
                r#type: MavType::GCS,
                autopilot: MavAutopilot::INVALID,
                mavlink_version: 3,
                ..Heartbeat::default()
            },
            Duration::from_secs(1),
        )
        .link(LinkSpec::parse(
            &format!("udpout:127.0.0.1:{port}?name=vehicle&version=2"),
            &none,
        )?)
        .start()
        .await?;
    let mut frames = gcs.subscribe().await;
    let t0 = tokio::time::Instant::now();
    let until = tokio::time::Instant::now() + Duration::from_secs_f64(seconds);
    while let Ok(Some(incoming)) = tokio::time::timeout_at(until, frames.recv()).await {
        let f = incoming.frame.frame.view();
        let Ok(message) = MavMessage::decode(f.msg_id(), f.payload()) else {
            continue;
        };
        let from = format!(
            "{:.2}s {}/{}",
            t0.elapsed().as_secs_f64(),
            f.sysid(),
            f.compid()
        );
        match message {
            MavMessage::Heartbeat(h) => {
                println!("{from} HEARTBEAT {:?} {:?}", h.r#type, h.autopilot);
            }
            MavMessage::Attitude(a) => println!(
                "{from} ATTITUDE roll {:.1}° pitch {:.1}° yaw {:.1}°",
                a.roll.to_degrees(),
                a.pitch.to_degrees(),
                a.yaw.to_degrees()
            ),
            MavMessage::GlobalPositionInt(p) => println!(
                "{from} GLOBAL_POSITION_INT {:.6} {:.6} {:.1} m",
                f64::from(p.lat) / 1e7,
                f64::from(p.lon) / 1e7,
                f64::from(p.relative_alt) / 1e3
            ),
            _ => {}
        }
    }
    let report = gcs.shutdown().await?;
    for link in &report.links {
        println!(
            "link {} ({}): {} frames in, {} out",
            link.name, link.version, link.rx_frames, link.tx_frames
        );
    }
    vehicle.shutdown().await?;
    Ok(())
}
