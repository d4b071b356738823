//! `mavstack modes` and `mavstack fly`: a vehicle's flight modes, and flying it — takeoff,
//! land, return home, hold, goto, a velocity for a while — through `System::modes()`,
//! `System::action()` and `System::offboard()`, with progress on stderr.

use core::time::Duration;

use clap::{Args, Subcommand};
use mavstack::system::{Setpoint, SystemError};
use serde_json::json;

use crate::link_cmd::runtime;
use crate::remote::{RemoteArgs, close, connect, print_lines};
use crate::{Failure, fail};

/// How long a landing (or a return home that ends landed) may take.
const LANDING_LIMIT: Duration = Duration::from_secs(600);

/// The rate of `fly velocity`'s setpoints (Hz).
const VELOCITY_RATE_HZ: f32 = 20.0;

#[derive(Debug, Args)]
pub(crate) struct ModesArgs {
    #[command(flatten)]
    remote: RemoteArgs,
}

#[derive(Debug, Args)]
pub(crate) struct FlyArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    #[command(subcommand)]
    what: Fly,
}

#[derive(Debug, Subcommand)]
enum Fly {
    /// Take off to HEIGHT metres above home (armed first); done at 95 % of it.
    Takeoff {
        /// Metres above home.
        height: f32,
    },
    /// Land where it is; done when landed and disarmed.
    Land,
    /// Return home; done when landed and disarmed.
    Rtl,
    /// Hold position.
    Hold,
    /// Go to a point at HEIGHT metres above home; done within 1.5 m of it.
    Goto {
        /// Latitude (degrees).
        #[arg(allow_negative_numbers = true)]
        lat: f64,
        /// Longitude (degrees).
        #[arg(allow_negative_numbers = true)]
        lon: f64,
        /// Metres above home.
        #[arg(allow_negative_numbers = true)]
        height: f32,
        /// Heading to face (degrees from north).
        #[arg(long, allow_negative_numbers = true)]
        yaw: Option<f32>,
    },
    /// Fly north, east, down at these speeds (m/s) for `--for` seconds (offboard setpoints),
    /// then hold.
    Velocity {
        /// North (m/s).
        #[arg(allow_negative_numbers = true)]
        north: f32,
        /// East (m/s).
        #[arg(allow_negative_numbers = true)]
        east: f32,
        /// Down (m/s; negative climbs).
        #[arg(allow_negative_numbers = true)]
        down: f32,
        /// How long (seconds, from 0.001 to 86400).
        #[arg(long = "for", value_parser = crate::link_cmd::timeout_arg)]
        seconds: f64,
    },
}

/// Exit 2 for what was refused before anything was sent, 1 otherwise.
fn failure(e: SystemError) -> Failure {
    match e {
        SystemError::Invalid(_) | SystemError::UnknownMode { .. } => Failure::Input(e.into()),
        e => fail(e),
    }
}

pub(crate) fn modes(args: &ModesArgs) -> Result<(), Failure> {
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let modes = session.system().modes();
        let list = modes.list().await;
        let current = modes.current().await.map(|m| m.custom_mode);
        close(session).await?;
        let lines: Vec<String> = if args.remote.json {
            list.iter()
                .map(|m| {
                    json!({
                        "name": m.name,
                        "standard": m.standard_name(),
                        "custom_mode": m.custom_mode,
                        "current": Some(m.custom_mode) == current,
                        "selectable": m.selectable,
                    })
                    .to_string()
                })
                .collect()
        } else {
            list.iter()
                .map(|m| {
                    format!(
                        "{} {:<24} {:<14} {:>10}{}",
                        if Some(m.custom_mode) == current {
                            "*"
                        } else {
                            " "
                        },
                        m.name,
                        m.standard_name().unwrap_or_default(),
                        m.custom_mode,
                        if m.selectable {
                            ""
                        } else {
                            "  (not selectable)"
                        }
                    )
                })
                .collect()
        };
        print_lines(&lines)
    })
}

pub(crate) fn fly(args: &FlyArgs) -> Result<(), Failure> {
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let system = session.system().clone();
        let action = system.action();
        let mut last_shown = f32::NAN;
        let mut show = |what: &str, value: f32, unit: &str| {
            // A line when it has changed by a metre (or at the first reading).
            if last_shown.is_nan() || (value - last_shown).abs() >= 1.0 {
                last_shown = value;
                eprintln!("{what}: {value:.1} {unit}");
            }
        };
        let done = match &args.what {
            Fly::Takeoff { height } => action
                .takeoff(*height, |h| show("height", h, "m"))
                .await
                .map(|()| format!("takeoff: at {height} m above home")),
            Fly::Land => match action.land().await {
                Ok(()) => action
                    .wait_landed(LANDING_LIMIT, |h| show("height", h, "m"))
                    .await
                    .map(|()| "landed and disarmed".to_owned()),
                Err(e) => Err(e),
            },
            Fly::Rtl => match action.return_home().await {
                Ok(()) => action
                    .wait_landed(LANDING_LIMIT, |h| show("height", h, "m"))
                    .await
                    .map(|()| "home, landed and disarmed".to_owned()),
                Err(e) => Err(e),
            },
            Fly::Hold => action.hold().await.map(|()| "holding".to_owned()),
            Fly::Goto {
                lat,
                lon,
                height,
                yaw,
            } => action
                .goto(*lat, *lon, *height, *yaw, true, |left| {
                    show("to go", left, "m")
                })
                .await
                .map(|()| format!("at {lat}, {lon}, {height} m above home")),
            Fly::Velocity {
                north,
                east,
                down,
                seconds,
            } => velocity(&system, [*north, *east, *down], *seconds).await,
        };
        close(session).await?;
        let line = done.map_err(failure)?;
        if args.remote.json {
            print_lines(&[json!({"done": line}).to_string()])
        } else {
            print_lines(&[line])
        }
    })
}

/// Flies at `ned` m/s for `seconds`, then holds.
async fn velocity(
    system: &mavstack::system::System,
    ned: [f32; 3],
    seconds: f64,
) -> Result<String, SystemError> {
    let setpoint = Setpoint::VelocityNed {
        north: ned[0],
        east: ned[1],
        down: ned[2],
        yaw_deg: None,
    };
    setpoint.check()?;
    let for_ = Duration::try_from_secs_f64(seconds)
        .map_err(|_| SystemError::Invalid(format!("--for {seconds}: not a number of seconds")))?;
    let start = system.telemetry().last_position();
    let session = system.offboard().start(VELOCITY_RATE_HZ, setpoint).await?;
    eprintln!(
        "offboard: {} m/s north, {} m/s east, {} m/s down",
        ned[0], ned[1], ned[2]
    );
    tokio::time::sleep(for_).await;
    let sent = session.sent();
    session.stop().await?;
    let moved = match (start, system.telemetry().last_position()) {
        (Some(a), Some(b)) => format!(
            ", moved {:.1} m",
            mavstack::system::distance_m(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg)
        ),
        _ => String::new(),
    };
    Ok(format!(
        "velocity for {seconds} s ({sent} setpoints){moved}, holding"
    ))
}
