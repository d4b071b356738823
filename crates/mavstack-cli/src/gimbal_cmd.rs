//! `mavstack gimbal CONN list | set PITCH YAW | rates PITCH YAW | point LAT LON ALT | clear |
//! attitude`: a system's gimbals through `mavstack::system::Gimbals` (the gimbal protocol
//! v2). Commands that move a gimbal take primary control of it first (`--no-control`: not).

use core::time::Duration;

use clap::{Args, Subcommand};
use mavstack::services::gimbal::{Attitude, GimbalInfo, YawFrame};
use mavstack::system::{Gimbal, SystemError};
use serde_json::{Value, json};

use crate::link_cmd::{runtime, seconds, timeout_arg};
use crate::remote::{RemoteArgs, close, connect, print_lines};
use crate::{Failure, fail, other};

/// How close (degrees) the attitude must come to an angle set for it to count as reached.
const REACHED_DEG: f32 = 2.0;

#[derive(Debug, Args)]
pub(crate) struct GimbalArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    /// Which gimbal, as `list` numbers them (from 1).
    #[arg(long, global = true, default_value_t = 1)]
    gimbal: usize,
    /// Do not take primary control before moving it.
    #[arg(long, global = true)]
    no_control: bool,
    /// Yaw from north rather than from the vehicle's nose.
    #[arg(long, global = true)]
    earth: bool,
    /// Seconds `set` waits for the gimbal to get there (and `attitude` for a report).
    #[arg(long, global = true, default_value_t = 10.0, value_parser = timeout_arg)]
    wait: f64,
    #[command(subcommand)]
    what: What,
}

#[derive(Debug, Subcommand)]
enum What {
    /// The gimbals (their managers): device, limits, vendor and model.
    List,
    /// Point it at PITCH (positive up) and YAW (positive right) degrees, and wait until it
    /// is there.
    Set {
        /// Degrees, positive up.
        #[arg(allow_negative_numbers = true)]
        pitch: f32,
        /// Degrees, positive right.
        #[arg(allow_negative_numbers = true)]
        yaw: f32,
    },
    /// Turn it at PITCH and YAW degrees per second.
    Rates {
        /// Degrees per second, positive up.
        #[arg(allow_negative_numbers = true)]
        pitch: f32,
        /// Degrees per second, positive right.
        #[arg(allow_negative_numbers = true)]
        yaw: f32,
    },
    /// Keep it on a location: latitude and longitude (degrees), altitude (metres above
    /// mean sea level).
    Point {
        /// Latitude (degrees).
        #[arg(allow_negative_numbers = true)]
        lat: f64,
        /// Longitude (degrees).
        #[arg(allow_negative_numbers = true)]
        lon: f64,
        /// Metres above mean sea level.
        #[arg(allow_negative_numbers = true)]
        alt: f32,
    },
    /// Stop keeping it on a location.
    Clear,
    /// Where it looks (GIMBAL_DEVICE_ATTITUDE_STATUS).
    Attitude,
}

/// A gimbal request refused before it was sent is bad input (exit 2).
fn refused(e: SystemError) -> Failure {
    match e {
        SystemError::Gimbal(_) => Failure::Input(anyhow::Error::new(e)),
        e => fail(e),
    }
}

fn range(r: Option<mavstack::services::gimbal::Range>) -> Value {
    r.map_or(Value::Null, |r| json!([round(r.min), round(r.max)]))
}

/// `v` to hundredths, never -0 (`+ 0.0` turns -0.0 into 0.0).
fn round(v: f32) -> f64 {
    (f64::from(v) * 100.0).round() / 100.0 + 0.0
}

/// `v` to tenths for the text lines, never "-0.0".
fn tenths(v: f32) -> f64 {
    (f64::from(v) * 10.0).round() / 10.0 + 0.0
}

fn describe(n: usize, g: &GimbalInfo, json: bool) -> String {
    if json {
        return json!({
            "gimbal": n,
            "manager": {"system": g.manager.system, "component": g.manager.component},
            "device_id": g.device_id,
            "cap_flags": g.cap_flags.0,
            "pitch": range(g.pitch),
            "yaw": range(g.yaw),
            "roll": range(g.roll),
            "vendor": g.vendor,
            "model": g.model,
            "custom_name": g.custom_name,
        })
        .to_string();
    }
    let show = |r: Option<mavstack::services::gimbal::Range>| {
        r.map_or_else(
            || "?".to_owned(),
            |r| format!("{:.0}..{:.0}°", r.min, r.max),
        )
    };
    let name = [g.vendor.as_str(), g.model.as_str()]
        .iter()
        .filter(|s| !s.is_empty())
        .copied()
        .collect::<Vec<_>>()
        .join(" ");
    format!(
        "gimbal {n}: manager {}, device {}, pitch {}, yaw {}{}",
        g.manager,
        g.device_id,
        show(g.pitch),
        show(g.yaw),
        if name.is_empty() {
            String::new()
        } else {
            format!(", {name}")
        }
    )
}

fn attitude_line(n: usize, a: &Attitude, json: bool) -> String {
    let opt = |v: Option<f32>| v.map_or(Value::Null, |v| json!(round(v)));
    if json {
        return json!({
            "gimbal": n,
            "roll": round(a.euler.roll_deg),
            "pitch": round(a.euler.pitch_deg),
            "yaw": round(a.euler.yaw_deg),
            "frame": a.frame.name(),
            "yaw_vehicle": opt(a.yaw_vehicle_deg),
            "yaw_earth": opt(a.yaw_earth_deg),
            "failure_flags": a.failure_flags,
        })
        .to_string();
    }
    let other = match a.frame {
        YawFrame::Vehicle => a
            .yaw_earth_deg
            .map(|y| format!(", {:.1}° from north", tenths(y))),
        YawFrame::Earth => a
            .yaw_vehicle_deg
            .map(|y| format!(", {:.1}° from the nose", tenths(y))),
    };
    format!(
        "gimbal {n}: roll {:.1}° pitch {:.1}° yaw {:.1}° ({} frame){}",
        tenths(a.euler.roll_deg),
        tenths(a.euler.pitch_deg),
        tenths(a.euler.yaw_deg),
        a.frame.name(),
        other.unwrap_or_default()
    )
}

/// Whether `a` shows `pitch` and `yaw` (in `frame`) within [`REACHED_DEG`].
fn reached(a: &Attitude, pitch: f32, yaw: f32, frame: YawFrame) -> bool {
    let yaw_now = match frame {
        YawFrame::Vehicle => a.yaw_vehicle_deg,
        YawFrame::Earth => a.yaw_earth_deg,
    };
    let diff = |a: f32, b: f32| mavstack::services::gimbal::wrap_deg(f64::from(a - b)).abs() as f32;
    (a.euler.pitch_deg - pitch).abs() <= REACHED_DEG
        && yaw_now.is_some_and(|y| diff(y, yaw) <= REACHED_DEG)
}

pub(crate) fn gimbal(args: &GimbalArgs) -> Result<(), Failure> {
    let wait = seconds(args.wait, "--wait")?;
    if args.gimbal == 0 {
        return Err(Failure::Input(anyhow::anyhow!("--gimbal counts from 1")));
    }
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let result = run(args, session.system(), wait).await;
        close(session).await?;
        result
    })
}

async fn run(
    args: &GimbalArgs,
    system: &mavstack::system::System,
    wait: Duration,
) -> Result<(), Failure> {
    let json = args.remote.json;
    let gimbals = system.gimbals().list().await.map_err(fail)?;
    if let What::List = args.what {
        if gimbals.is_empty() {
            return Err(other(format!(
                "{} has no gimbal manager (none answered GIMBAL_MANAGER_INFORMATION)",
                system.target()
            )));
        }
        let lines: Vec<String> = gimbals
            .iter()
            .enumerate()
            .map(|(i, g)| describe(i + 1, g.info(), json))
            .collect();
        return print_lines(&lines);
    }
    let n = args.gimbal;
    let g: &Gimbal = gimbals.get(n - 1).ok_or_else(|| {
        other(format!(
            "{} has {} gimbal(s): no gimbal {n}",
            system.target(),
            gimbals.len()
        ))
    })?;
    let frame = if args.earth {
        YawFrame::Earth
    } else {
        YawFrame::Vehicle
    };
    let moves = !matches!(args.what, What::Attitude);
    if moves && !args.no_control {
        g.take_control(false).await.map_err(fail)?;
    }
    match args.what {
        What::List => Ok(()),
        What::Set { pitch, yaw } => {
            g.set_angles(pitch, yaw, frame).await.map_err(refused)?;
            let end = tokio::time::Instant::now() + wait;
            let mut last = None;
            while tokio::time::Instant::now() < end {
                let left = end.saturating_duration_since(tokio::time::Instant::now());
                match g.attitude(left).await {
                    Ok(a) => {
                        let done = reached(&a, pitch, yaw, frame);
                        last = Some(a);
                        if done {
                            break;
                        }
                    }
                    Err(SystemError::Timeout { .. }) => break,
                    Err(e) => return Err(fail(e)),
                }
            }
            let Some(a) = last else {
                return Err(other(format!(
                    "gimbal {n} accepted the angles but reported no attitude within {:.0} s",
                    wait.as_secs_f64()
                )));
            };
            print_lines(&[attitude_line(n, &a, json)])?;
            if reached(&a, pitch, yaw, frame) {
                Ok(())
            } else {
                Err(other(format!(
                    "gimbal {n} did not reach pitch {pitch}° yaw {yaw}° within {:.0} s",
                    wait.as_secs_f64()
                )))
            }
        }
        What::Rates { pitch, yaw } => {
            g.set_rates(pitch, yaw, frame).await.map_err(refused)?;
            print_lines(&[accepted(n, "rates", json)])
        }
        What::Point { lat, lon, alt } => {
            g.point_at(lat, lon, alt).await.map_err(refused)?;
            print_lines(&[accepted(n, "point", json)])
        }
        What::Clear => {
            g.clear_roi().await.map_err(fail)?;
            print_lines(&[accepted(n, "clear", json)])
        }
        What::Attitude => {
            let a = g.attitude(wait).await.map_err(fail)?;
            print_lines(&[attitude_line(n, &a, json)])
        }
    }
}

fn accepted(n: usize, what: &str, json: bool) -> String {
    if json {
        json!({"gimbal": n, "request": what, "result": "ACCEPTED"}).to_string()
    } else {
        format!("gimbal {n}: {what} accepted")
    }
}
