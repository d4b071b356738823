//! Offboard control with `System::offboard`: take off, fly a velocity for a few seconds,
//! hold. The setpoint stream is the library's: it keeps its rate whatever this program does
//! between setpoints.
//!
//! `cargo run -p mavstack --features sim --example offboard [px4|ardupilot|CONN]`: against
//! an in-process simulated vehicle of that flavour (PX4 by default), or a vehicle reached at
//! the connection string CONN (`udpin:0.0.0.0:14550` for PX4 SITL).

use core::time::Duration;

use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{Setpoint, System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};

type Error = Box<dyn core::error::Error>;

/// Arms, asking again while the vehicle refuses (its estimator settling), up to `tries`.
async fn arm(vehicle: &System, tries: u32) -> Result<(), Error> {
    for _ in 0..tries {
        match vehicle.action().arm().await {
            Ok(()) => return Ok(()),
            Err(SystemError::Command { statustext, .. }) => {
                println!("arming refused: {}", statustext.join("; "));
                tokio::time::sleep(Duration::from_secs(3)).await;
            }
            Err(e) => return Err(e.into()),
        }
    }
    Err("the vehicle never armed".into())
}

async fn fly(vehicle: &System) -> Result<(), Error> {
    arm(vehicle, 60).await?;
    vehicle.action().takeoff(10.0, |_| {}).await?;
    let start = vehicle
        .telemetry()
        .position(Duration::from_secs(3))
        .await
        .ok_or("no position")?;
    println!("took off: {:.1} m above home", start.height_m);
    let north = Setpoint::VelocityNed {
        north: 3.0,
        east: 0.0,
        down: 0.0,
        yaw_deg: None,
    };
    let session = vehicle.offboard().start(20.0, north).await?;
    println!("offboard: 3 m/s north");
    tokio::time::sleep(Duration::from_secs(5)).await;
    let sent = session.sent();
    session.stop().await?;
    let end = vehicle
        .telemetry()
        .position(Duration::from_secs(3))
        .await
        .ok_or("no position")?;
    let moved =
        mavstack::system::distance_m(start.lat_deg, start.lon_deg, end.lat_deg, end.lon_deg);
    let mode = vehicle.modes().current().await.map(|m| m.name);
    println!(
        "offboard ended after {sent} setpoints: moved {moved:.1} m north, now {}",
        mode.as_deref().unwrap_or("?")
    );
    vehicle.action().land().await?;
    vehicle
        .action()
        .wait_landed(Duration::from_secs(120), |_| {})
        .await?;
    println!("landed and disarmed");
    Ok(())
}

#[tokio::main]
async fn main() -> Result<(), Error> {
    let arg = std::env::args().nth(1).unwrap_or_else(|| "px4".to_owned());
    let none = |_: &str| None;
    let autopilot = match arg.as_str() {
        "px4" => Some(Autopilot::Px4),
        "ardupilot" => Some(Autopilot::Ardupilot),
        _ => None,
    };
    let Some(autopilot) = autopilot else {
        // A real vehicle.
        let session = System::connect(
            LinkSpec::parse(&arg, &none)?,
            Wanted::AnyAutopilot,
            Duration::from_secs(30),
        )
        .await?;
        let result = fly(session.system()).await;
        session.close().await?;
        return result;
    };
    let sim = SimVehicle::start(
        Node::builder().link(LinkSpec::parse("udpin:127.0.0.1:0", &none)?),
        SimVehicle::config(autopilot, params::defaults(autopilot)),
    )
    .await?;
    let port = sim.node().local_addrs()[0].ok_or("no port")?.port();
    let session = System::connect(
        LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none)?,
        Wanted::AnyAutopilot,
        Duration::from_secs(5),
    )
    .await?;
    println!("{arg} simulator found: {}", session.system().target());
    let result = fly(session.system()).await;
    session.close().await?;
    sim.shutdown().await?;
    result
}
