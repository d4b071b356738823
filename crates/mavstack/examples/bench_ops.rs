//! Microservice operations timed in a connected session of the Rust API, from the call to
//! the result (what `tests-interop/bench_ops.py` sets beside MAVSDK, pymavlink and
//! `mavstack.aio`): the whole parameter table, a plan of home + N waypoints uploaded and
//! downloaded ROUNDS times (one second's pause before each), and COMMANDS commands' round
//! trips (DO_SET_MODE to the vehicle's hold mode, 10 by default).
//!
//! `cargo run --release -p mavstack --features services --example bench_ops -- CONN [N [ROUNDS [COMMANDS]]]`
//! prints one JSON object: `{"connect_s", "params_s", "params", "upload_s": [..],
//! "download_s": [..], "command_rtts": [..], "command_failed"}` (a step that failed is
//! `null`, a command that failed is counted in `command_failed`, each with its error in
//! `errors`).

use core::time::Duration;
use std::time::Instant;

use mavstack::LinkSpec;
use mavstack::dialects::common::{MavCmd, MavFrame, MavMissionType, MissionItemInt};
use mavstack::modes::{self, Flavour};
use mavstack::services::command::Command;
use mavstack::system::{System, Wanted};
use serde_json::json;

type Error = Box<dyn core::error::Error>;

/// The pause before each timed transfer.
const TRANSFER_SETTLE: Duration = Duration::from_secs(1);

/// Home + `n` waypoints around the vehicle's home.
fn plan(home: (f64, f64, f32), n: usize) -> Vec<MissionItemInt> {
    let item = |i: usize, lat: f64, lon: f64, z: f32, frame| MissionItemInt {
        seq: i as u16,
        frame,
        command: MavCmd::NAV_WAYPOINT,
        autocontinue: 1,
        x: (lat * 1e7) as i32,
        y: (lon * 1e7) as i32,
        z,
        mission_type: MavMissionType::MISSION,
        ..MissionItemInt::default()
    };
    core::iter::once(item(0, home.0, home.1, home.2, MavFrame::GLOBAL))
        .chain((1..=n).map(|i| {
            let lat = home.0 + 0.00005 * (i % 20) as f64;
            let lon = home.1 + 0.00005 * (i / 20) as f64;
            item(i, lat, lon, 20.0, MavFrame::GLOBAL_RELATIVE_ALT_INT)
        }))
        .collect()
}

#[tokio::main]
async fn main() -> Result<(), Error> {
    let mut args = std::env::args().skip(1);
    let conn = args
        .next()
        .ok_or("usage: bench_ops CONN [N [ROUNDS [COMMANDS]]]")?;
    let n: usize = args.next().map_or(Ok(100), |a| a.parse())?;
    let rounds: usize = args.next().map_or(Ok(1), |a| a.parse())?;
    let commands: usize = args.next().map_or(Ok(10), |a| a.parse())?;
    let t = Instant::now();
    let session = System::connect(
        LinkSpec::parse(&conn, &|_| None)?,
        Wanted::AnyAutopilot,
        Duration::from_secs(60),
    )
    .await?;
    let connect_s = t.elapsed().as_secs_f64();
    let v = session.system();
    let mut errors = Vec::new();
    let mut timed = |what: &str, r: Result<f64, mavstack::system::SystemError>| match r {
        Ok(s) => Some(s),
        Err(e) => {
            errors.push(format!("{what}: {}", mavstack::error_chain(&e)));
            None
        }
    };
    let t = Instant::now();
    let table = v.params().get_all().await;
    let count = table.as_ref().map_or(0, Vec::len);
    let params_s = timed("params", table.map(|_| t.elapsed().as_secs_f64()));
    let home = v.telemetry().home(Duration::from_secs(5)).await.map_or(
        (-35.363_261, 149.165_23, 584.0),
        |h| {
            (
                f64::from(h.latitude) * 1e-7,
                f64::from(h.longitude) * 1e-7,
                h.altitude as f32 / 1000.0,
            )
        },
    );
    let items = plan(home, n);
    // As every tool of tests-interop/bench_ops.py: PX4 goes on sending its parameter list
    // for about a second after a client that re-requests gaps has it all.
    tokio::time::sleep(Duration::from_secs(2)).await;
    let (mut upload_s, mut download_s) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        // As every tool: PX4 checks a plan it has just taken, reading every item back, and a
        // transfer started meanwhile waits on its storage.
        tokio::time::sleep(TRANSFER_SETTLE).await;
        let t = Instant::now();
        let up = v
            .mission()
            .upload_plan(MavMissionType::MISSION, &items, |_, _| {})
            .await;
        upload_s.push(timed("upload", up.map(|_| t.elapsed().as_secs_f64())));
        tokio::time::sleep(TRANSFER_SETTLE).await;
        let t = Instant::now();
        let down = v.mission().download(MavMissionType::MISSION).await;
        download_s.push(timed("download", down.map(|_| t.elapsed().as_secs_f64())));
    }
    let hold = match v.flavour() {
        Some(Flavour::Px4) => "AUTO.LOITER",
        _ => "LOITER",
    };
    let command = v.flavour().and_then(|f| {
        let m = modes::by_name(f, hold)?;
        let (p1, p2, p3) = f.command_params(m.custom_mode);
        Some(Command::long(
            MavCmd::DO_SET_MODE,
            [p1, p2, p3, 0., 0., 0., 0.],
        ))
    });
    let mut command_rtts = Vec::new();
    let mut command_failed = 0;
    if let Some(command) = command {
        for _ in 0..commands {
            let t = Instant::now();
            match v.commands().send(command.clone()).await {
                Ok(_) => command_rtts.push(t.elapsed().as_secs_f64()),
                Err(e) => {
                    errors.push(format!("command: {}", mavstack::error_chain(&e)));
                    command_failed += 1;
                }
            }
        }
    }
    println!(
        "{}",
        json!({
            "connect_s": connect_s,
            "params_s": params_s,
            "params": count,
            "upload_s": upload_s,
            "download_s": download_s,
            "command_rtts": command_rtts,
            "command_failed": command_failed,
            "errors": errors,
        })
    );
    session.close().await?;
    Ok(())
}
