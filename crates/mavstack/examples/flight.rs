//! A whole flight through the `System` API, against any vehicle: telemetry at requested rates,
//! then arm (waiting for the estimator, with the vehicle's reasons shown), take off, a mission
//! flown to its end, return and land.
//!
//! ```text
//! cargo run -p mavstack --features services --example flight -- tcp:127.0.0.1:5760
//! cargo run -p mavstack --features services --example flight -- udpin:127.0.0.1:14550 --rates-only
//! ```
//!
//! Prints one JSON object per step (`{"step":"rates",...}`, `{"step":"armed",...}`, ...) and
//! exits 1 when a step fails. `scripts/flight-stacks.sh` runs it against ArduPilot SITL, PX4
//! SITL and the simulator. The plan follows each autopilot's convention
//! (`mavstack::services::plan`), the modes their names (`mavstack::modes`).

use core::time::Duration;

use mavstack::core::Message as _;
use mavstack::dialects::common::{
    Attitude, GlobalPositionInt, Heartbeat, MavCmd, MavFrame, MavMissionType, MavModeFlag,
    MavResult, MissionItemInt, MissionItemReached,
};
use mavstack::modes::Flavour;
use mavstack::services::command::{Command, CommandError};
use mavstack::services::plan::{self, Convention};
use mavstack::system::{System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};
use tokio::time::Instant;

type Error = Box<dyn core::error::Error>;

fn step(json: &serde_json::Value) {
    println!("{json}");
}

/// Counts messages `T` from the system for `span`: their rate in Hz.
async fn rate<T: mavstack::core::Message>(v: &System, span: Duration) -> f64 {
    let mut samples = v.telemetry().subscribe::<T>().await;
    let until = Instant::now() + span;
    let mut n = 0u32;
    while let Ok(Some(_)) = tokio::time::timeout_at(until, samples.recv()).await {
        n += 1;
    }
    f64::from(n) / span.as_secs_f64()
}

async fn command(v: &mut System, command: MavCmd, p: [f32; 7]) -> Result<(), SystemError> {
    v.commands()
        .send_with_progress(Command::long(command, p), |_| {})
        .await
        .map(drop)
}

/// The plan: home, a take-off to 10 m, three waypoints about 40 m apart (item 0 home, as QGC
/// writes plans).
/// Switches to `mode`, asking again every half second for up to ten seconds while the
/// vehicle answers TEMPORARILY_REJECTED (PX4 does right after arming, until its checks have
/// seen the new state: "try again later" is what that result means).
async fn set_mode_when_ready(v: &System, mode: &str) -> Result<(), SystemError> {
    let until = Instant::now() + Duration::from_secs(10);
    loop {
        match v.modes().set(mode).await {
            Ok(_) => return Ok(()),
            Err(SystemError::Command {
                reason:
                    CommandError::Rejected {
                        result: MavResult::TEMPORARILY_REJECTED,
                        ..
                    },
                ..
            }) if Instant::now() < until => {
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            Err(e) => return Err(e),
        }
    }
}

fn plan(home: &MissionItemInt) -> Vec<MissionItemInt> {
    let item = |seq: u16, command, frame, dlat: i32, dlon: i32, z| MissionItemInt {
        seq,
        command,
        frame,
        x: home.x + dlat,
        y: home.y + dlon,
        z,
        autocontinue: 1,
        ..MissionItemInt::default()
    };
    let rel = MavFrame::GLOBAL_RELATIVE_ALT;
    vec![
        *home,
        item(1, MavCmd::NAV_TAKEOFF, rel, 0, 0, 10.0),
        item(2, MavCmd::NAV_WAYPOINT, rel, 3_600, 0, 10.0),
        item(3, MavCmd::NAV_WAYPOINT, rel, 3_600, 4_500, 12.0),
        item(4, MavCmd::NAV_WAYPOINT, rel, 0, 4_500, 10.0),
    ]
}

/// Waits until `done` holds for a message `T` of the system, up to `limit`.
async fn until<T: mavstack::core::Message>(
    v: &System,
    limit: Duration,
    mut done: impl FnMut(&T) -> bool,
) -> bool {
    let mut samples = v.telemetry().subscribe::<T>().await;
    let end = Instant::now() + limit;
    while let Ok(Some(s)) = tokio::time::timeout_at(end, samples.recv()).await {
        if done(&s.message) {
            return true;
        }
    }
    false
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> Result<(), Error> {
    let mut args = std::env::args().skip(1);
    let conn = args.next().ok_or("usage: flight CONN [--rates-only]")?;
    let rates_only = args.any(|a| a == "--rates-only");
    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(&conn, &|_| None)?)
        .start()
        .await?;
    let t0 = Instant::now();
    let secs = || (t0.elapsed().as_secs_f64() * 100.0).round() / 100.0;
    let mut v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(30)).await?;
    let flavour = v.flavour().ok_or("neither ArduPilot nor PX4")?;

    // Telemetry at requested rates, measured over 5 s.
    let att = v.telemetry().request_rate(Attitude::ID, 10.0).await?;
    let gpi = v
        .telemetry()
        .request_rate(GlobalPositionInt::ID, 5.0)
        .await?;
    let span = Duration::from_secs(5);
    let (att_hz, gpi_hz) = tokio::join!(
        rate::<Attitude>(&v, span),
        rate::<GlobalPositionInt>(&v, span)
    );
    let within = |hz: f64, want: f64| (hz - want).abs() <= want * 0.2;
    let rates_ok = within(att_hz, 10.0) && within(gpi_hz, 5.0);
    step(
        &serde_json::json!({"step": "rates", "ok": rates_ok, "attitude_hz": att_hz,
        "attitude_by": format!("{:?}", att.how), "global_position_int_hz": gpi_hz,
        "global_position_int_by": format!("{:?}", gpi.how), "t_s": secs()}),
    );
    if rates_only {
        gcs.shutdown().await?;
        return if rates_ok {
            Ok(())
        } else {
            Err("rates off by more than 20 %".into())
        };
    }

    // The plan, under the autopilot's convention.
    // A flight stack has a home once its position is known (ArduPilot SITL: ~30 s after
    // boot); until then it refuses HOME_POSITION. Asked every 5 s.
    let home_by = Instant::now() + Duration::from_secs(120);
    let home = loop {
        if let Some(home) = v.mission().home_item(Duration::from_secs(5)).await {
            break home;
        }
        if Instant::now() > home_by {
            return Err("no HOME_POSITION within 120 s".into());
        }
    };
    step(&serde_json::json!({"step": "home", "ok": true, "t_s": secs()}));
    let convention = Convention::of(v.autopilot());
    let sent = plan(&home);
    v.mission()
        .upload(MavMissionType::MISSION, plan::to_vehicle(convention, &sent))
        .await?;
    let stored = v.mission().download(MavMissionType::MISSION).await?;
    let last = u16::try_from(stored.len().saturating_sub(1))?;
    let back = plan::from_vehicle(convention, &stored, Some(home));
    step(
        &serde_json::json!({"step": "mission", "ok": plan::same(&sent, &back),
        "items": stored.len(), "t_s": secs()}),
    );

    // Arm: refused until the estimator is ready; the reasons are the vehicle's.
    let guided = if flavour == Flavour::Px4 {
        "AUTO.LOITER"
    } else {
        "GUIDED"
    };
    v.modes().set(guided).await?;
    let arm_by = Instant::now() + Duration::from_secs(120);
    let mut refusals = Vec::new();
    loop {
        match command(
            &mut v,
            MavCmd::COMPONENT_ARM_DISARM,
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )
        .await
        {
            Ok(()) => break,
            Err(SystemError::Command { statustext, .. }) if Instant::now() < arm_by => {
                if refusals.len() < 5 {
                    refusals.extend(statustext);
                }
                tokio::time::sleep(Duration::from_secs(2)).await;
            }
            Err(e) => return Err(e.into()),
        }
    }
    step(&serde_json::json!({"step": "armed", "ok": true, "refusals": refusals, "t_s": secs()}));

    // Take off and fly the mission.
    let reached = std::sync::Arc::new(std::sync::Mutex::new(Vec::<u16>::new()));
    let mut items_seen = v.telemetry().subscribe::<MissionItemReached>().await;
    let seen = reached.clone();
    let watcher = tokio::spawn(async move {
        while let Some(s) = items_seen.recv().await {
            if let Ok(mut r) = seen.lock() {
                r.push(s.message.seq);
            }
        }
    });
    match flavour {
        Flavour::Px4 => set_mode_when_ready(&v, "AUTO.MISSION").await?,
        _ => {
            command(
                &mut v,
                MavCmd::NAV_TAKEOFF,
                [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, 10.0],
            )
            .await?;
            let up =
                until::<GlobalPositionInt>(&v, Duration::from_secs(60), |p| p.relative_alt > 8_000)
                    .await;
            step(&serde_json::json!({"step": "takeoff", "ok": up, "t_s": secs()}));
            v.modes().set("AUTO").await.map(drop)?;
        }
    }
    let flown_by = Instant::now() + Duration::from_secs(240);
    let done = loop {
        let got = reached.lock().map(|r| r.clone()).unwrap_or_default();
        if got.contains(&last) {
            break got;
        }
        if Instant::now() > flown_by {
            break got;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    // Each item once, in order (PX4 repeats MISSION_ITEM_REACHED while it holds an item).
    let mut order: Vec<u16> = done;
    order.dedup();
    let first = u16::from(convention == Convention::ArduPilot);
    let all = order.iter().copied().eq(first..=last);
    step(&serde_json::json!({"step": "mission_flown", "ok": all, "reached": order, "t_s": secs()}));

    // Home and down.
    let rtl = if flavour == Flavour::Px4 {
        "AUTO.RTL"
    } else {
        "RTL"
    };
    v.modes().set(rtl).await?;
    let landed = until::<Heartbeat>(&v, Duration::from_secs(240), |h| {
        h.base_mode.0 & MavModeFlag::SAFETY_ARMED.0 == 0
    })
    .await;
    step(&serde_json::json!({"step": "landed_disarmed", "ok": landed, "t_s": secs()}));
    watcher.abort();
    gcs.shutdown().await?;
    if rates_ok && all && landed {
        Ok(())
    } else {
        Err("a step failed".into())
    }
}
