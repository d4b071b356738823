//! A companion computer between a flight controller and a ground station: one node, two
//! links, each in its own version, forwarding between them; it also reads the flight
//! controller's telemetry itself.
//!
//! ```text
//! cargo run -p mavstack --features sim --example companion -- [FC_LINK]
//! ```
//!
//! `FC_LINK` is the flight controller's link, e.g. `'serial:/dev/ttyAMA0:921600?version=2'`.
//! Without it the flight controller is the in-process simulated vehicle on a UDP port, and a
//! ground station in the same process reads a parameter of the vehicle through the
//! companion.

use core::time::Duration;

use mavstack::dialects::common::{Attitude, Heartbeat, MavAutopilot, MavType};
use mavstack::services::param::Name;
use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{System, Wanted};
use mavstack::{LinkSpec, Node};

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn core::error::Error>> {
    let none = |_: &str| None;
    let given = std::env::args().nth(1);
    let simulated = match &given {
        Some(_) => None,
        None => Some(
            SimVehicle::start(
                Node::builder().link(LinkSpec::parse("udpin:127.0.0.1:0", &none)?),
                SimVehicle::config(Autopilot::Px4, params::defaults(Autopilot::Px4)),
            )
            .await?,
        ),
    };
    let fc_link = match (&given, &simulated) {
        (Some(link), _) => link.clone(),
        (None, Some(v)) => format!(
            "udpout:127.0.0.1:{}?name=fc",
            v.node().local_addrs()[0].ok_or("no port")?.port()
        ),
        (None, None) => unreachable!("a simulated vehicle when no link is given"),
    };

    // The companion: system 1 like its vehicle, component 191 (onboard computer).
    let companion = Node::builder()
        .identity(1, 191)
        .heartbeat(
            &Heartbeat {
                r#type: MavType::ONBOARD_CONTROLLER,
                autopilot: MavAutopilot::INVALID,
                mavlink_version: 3,
                ..Heartbeat::default()
            },
            Duration::from_secs(1),
        )
        .link(LinkSpec::parse(&fc_link, &none)?)
        .link(LinkSpec::parse("udpin:127.0.0.1:0?name=gcs", &none)?)
        .start()
        .await?;
    let gcs_port = companion.local_addrs()[1].ok_or("no port")?.port();
    println!(
        "companion: flight controller on {fc_link}, ground stations on udp 127.0.0.1:{gcs_port}"
    );

    // What the companion itself reads: the vehicle's attitude.
    let vehicle = System::wait(
        &companion.handle(),
        Wanted::AnyAutopilot,
        Duration::from_secs(5),
    )
    .await?;
    let mut attitude = vehicle.telemetry().subscribe::<Attitude>().await;
    if let Ok(Some(a)) = tokio::time::timeout(Duration::from_secs(3), attitude.recv()).await {
        println!(
            "companion ← ATTITUDE from {}: roll {:.1}°",
            a.from,
            a.message.roll.to_degrees()
        );
    }

    if simulated.is_some() {
        // A ground station on the companion's UDP port reaches the vehicle through it.
        let gcs = Node::ground_station(255, 190)
            .link(LinkSpec::parse(
                &format!("udpout:127.0.0.1:{gcs_port}"),
                &none,
            )?)
            .start()
            .await?;
        let fc = System::wait(
            &gcs.handle(),
            Wanted::System(1, Some(1)),
            Duration::from_secs(5),
        )
        .await?;
        let p = fc.params().get(Name::new("MAV_SYS_ID")?).await?;
        println!(
            "ground station ← MAV_SYS_ID = {} (through the companion)",
            p.value.as_f64()
        );
        drop(fc);
        gcs.shutdown().await?;
    } else {
        tokio::signal::ctrl_c().await?;
    }
    drop(attitude);
    drop(vehicle);
    let report = companion.shutdown().await?;
    for link in &report.links {
        println!(
            "companion link {} ({}): {} frames in, {} out",
            link.name, link.version, link.rx_frames, link.tx_frames
        );
    }
    if let Some(v) = simulated {
        v.shutdown().await?;
    }
    Ok(())
}
