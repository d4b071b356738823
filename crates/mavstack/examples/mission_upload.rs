//! Uploads a mission from a QGroundControl `QGC WPL 110` file (MAVProxy's and Mission
//! Planner's `.waypoints` too) and reads it back, against the in-process simulated vehicle:
//!
//! ```text
//! cargo run -p mavstack --features sim --example mission_upload -- [PLAN.waypoints]
//! ```
//!
//! Without a file it uploads a built-in plan (home, take-off, three waypoints, return). Point
//! the ground station at a real vehicle by replacing the `udpout:` link with its connection.

use core::time::Duration;

use mavstack::dialects::common::MavMissionType;
use mavstack::services::wpl;
use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{System, Wanted};
use mavstack::{LinkSpec, Node};

const PLAN: &str = "QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t-35.36326100\t149.16523000\t584.000000\t1
1\t0\t3\t22\t0\t0\t0\tnan\t-35.36326100\t149.16523000\t20.000000\t1
2\t0\t3\t16\t0\t0\t0\tnan\t-35.36272200\t149.16523000\t25.000000\t1
3\t0\t3\t16\t0\t0\t0\tnan\t-35.36272200\t149.16589000\t25.000000\t1
4\t0\t3\t16\t0\t0\t0\tnan\t-35.36326100\t149.16589000\t20.000000\t1
5\t0\t0\t20\t0\t0\t0\t0\t0\t0\t0\t1
";

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Box<dyn core::error::Error>> {
    let (name, text) = match std::env::args().nth(1) {
        Some(path) => {
            let text = std::fs::read_to_string(&path).map_err(|e| format!("{path}: {e}"))?;
            (path, text)
        }
        None => ("the built-in plan".to_owned(), PLAN.to_owned()),
    };
    let items = wpl::parse(&text).map_err(|e| format!("{name}: {e}"))?;
    let none = |_: &str| None;

    let vehicle = SimVehicle::start(
        Node::builder().link(LinkSpec::parse("udpin:127.0.0.1:0", &none)?),
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot)),
    )
    .await?;
    let port = vehicle.node().local_addrs()[0]
        .ok_or("the vehicle has no UDP port")?
        .port();

    // A ground station: its HEARTBEAT once a second, a link that runs the MAVLink 2
    // handshake when the vehicle still speaks MAVLink 1.
    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none)?)
        .start()
        .await?;
    let target = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5)).await?;
    println!(
        "found {} ({:?}) on {}",
        target.target(),
        target.autopilot(),
        target.link_name()
    );

    let t = tokio::time::Instant::now();
    target
        .mission()
        .upload(MavMissionType::MISSION, items.clone())
        .await?;
    println!(
        "uploaded {} items from {name} in {:.0} ms",
        items.len(),
        t.elapsed().as_secs_f64() * 1000.0
    );
    let back = target.mission().download(MavMissionType::MISSION).await?;
    let same = back.len() == items.len()
        && back.iter().zip(&items).all(|(a, b)| {
            (a.command, a.frame, a.x, a.y, a.z.to_bits())
                == (b.command, b.frame, b.x, b.y, b.z.to_bits())
        });
    println!(
        "read back {} items: {}",
        back.len(),
        if same { "identical" } else { "DIFFERENT" }
    );
    drop(target);
    gcs.shutdown().await?;
    vehicle.shutdown().await?;
    if same {
        Ok(())
    } else {
        Err("the plan read back differs from the one uploaded".into())
    }
}
