//! A simulated vehicle in a ground station's test: the test starts the vehicle in-process on
//! a loopback port, drives it through the API and asserts what it answers. `cargo test -p
//! mavstack --features sim --example vehicle_in_test` runs it as a test; `cargo run ...`
//! runs the same check as a program.

use core::time::Duration;

use mavstack::dialects::common::{CommandLong, MavCmd, MavResult};
use mavstack::services::command::Command;
use mavstack::services::param::{Name, Value};
use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{System, Wanted};
use mavstack::{LinkSpec, Node};

type Error = Box<dyn core::error::Error>;

/// What the test checks: a parameter set sticks, and the vehicle arms on command.
async fn check_the_vehicle() -> Result<String, Error> {
    let none = |_: &str| None;
    let vehicle = SimVehicle::start(
        Node::builder().link(LinkSpec::parse("udpin:127.0.0.1:0?version=2", &none)?),
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot)),
    )
    .await?;
    let port = vehicle.node().local_addrs()[0].ok_or("no port")?.port();
    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(
            &format!("udpout:127.0.0.1:{port}?version=2"),
            &none,
        )?)
        .start()
        .await?;
    let v = System::wait(
        &gcs.handle(),
        Wanted::System(1, Some(1)),
        Duration::from_secs(5),
    )
    .await?;
    let name = Name::new("RTL_ALT")?;
    let set = v.params().set(name, Value::F32(3000.0)).await?;
    assert_eq!(set.value.as_f64(), 3000.0);
    let arm = Command::Long(CommandLong {
        command: MavCmd::COMPONENT_ARM_DISARM,
        param1: 1.0,
        ..CommandLong::default()
    });
    let ack = v.commands().send_with_progress(arm, |_| {}).await?;
    assert_eq!(ack.result, MavResult::ACCEPTED);
    drop(v);
    gcs.shutdown().await?;
    vehicle.shutdown().await?;
    Ok(format!(
        "RTL_ALT set to {}, arming {:?}",
        set.value.as_f64(),
        ack.result
    ))
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Error> {
    println!("vehicle in a test: {}", check_the_vehicle().await?);
    Ok(())
}

#[cfg(test)]
mod tests {
    #[tokio::test]
    async fn the_vehicle_keeps_a_parameter_and_arms() {
        super::check_the_vehicle().await.expect("the check passes");
    }
}
