//! `mavstack camera CONN list | photo | video start|stop | interval start S|stop | mode
//! photo|video | settings [--set NAME=VALUE]...`: a system's cameras through
//! `mavstack::system::Cameras` (the camera protocol v2).

use clap::{Args, Subcommand, ValueEnum};
use mavstack::dialects::common::CameraMode;
use mavstack::services::camera::{CameraInfo, ExtValue, ImageCaptured, mode_name};
use mavstack::system::{Camera, SettingView, System, SystemError};
use serde_json::{Value, json};

use crate::link_cmd::runtime;
use crate::remote::{RemoteArgs, close, connect, print_lines};
use crate::{Failure, fail, other};

#[derive(Debug, Args)]
pub(crate) struct CameraArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    /// Which camera, as `list` numbers them (from 1).
    #[arg(long, global = true, default_value_t = 1)]
    camera: usize,
    #[command(subcommand)]
    what: What,
}

#[derive(Debug, Subcommand)]
enum What {
    /// The cameras: component, vendor, model, definition, status, storage.
    List,
    /// Take a photo; prints its CAMERA_IMAGE_CAPTURED (index, file, where).
    Photo,
    /// Start or stop recording.
    Video {
        /// `start` or `stop`.
        action: StartStop,
    },
    /// Photos at an interval: `start SECONDS [--count N]`, or `stop`.
    Interval {
        /// `start` or `stop`.
        action: StartStop,
        /// Seconds between photos (with `start`).
        seconds: Option<f32>,
        /// How many (0: until stopped).
        #[arg(long, default_value_t = 0)]
        count: u32,
    },
    /// Switch to photo or video mode.
    Mode {
        /// `photo` or `video`.
        mode: ModeArg,
    },
    /// Its settings (PARAM_EXT_*, described by its definition file); `--set NAME=VALUE`
    /// sets one first (an option's name or a value; checked against the definition).
    Settings {
        /// NAME=VALUE to set (repeatable).
        #[arg(long = "set", value_name = "NAME=VALUE")]
        set: Vec<String>,
    },
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum StartStop {
    Start,
    Stop,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum ModeArg {
    Photo,
    Video,
}

/// A value the camera's definition rules out, refused before it was sent: bad input (exit 2).
fn refused(e: SystemError) -> Failure {
    match e {
        SystemError::CameraSetting(_) | SystemError::Invalid(_) => {
            Failure::Input(anyhow::Error::new(e))
        }
        e => fail(e),
    }
}

pub(crate) fn camera(args: &CameraArgs) -> Result<(), Failure> {
    if args.camera == 0 {
        return Err(Failure::Input(anyhow::anyhow!("--camera counts from 1")));
    }
    if let What::Interval {
        action: StartStop::Start,
        seconds,
        ..
    } = args.what
        && !seconds.is_some_and(|s| s.is_finite() && s > 0.0)
    {
        return Err(Failure::Input(anyhow::anyhow!(
            "interval start takes the seconds between photos (a positive number)"
        )));
    }
    let sets = args
        .what
        .settings()
        .iter()
        .map(|s| {
            s.split_once('=')
                .map(|(n, v)| (n.trim().to_owned(), v.trim().to_owned()))
                .ok_or_else(|| Failure::Input(anyhow::anyhow!("--set {s:?}: NAME=VALUE")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let result = run(args, session.system(), &sets).await;
        close(session).await?;
        result
    })
}

impl What {
    fn settings(&self) -> &[String] {
        match self {
            Self::Settings { set } => set,
            _ => &[],
        }
    }
}

async fn run(args: &CameraArgs, system: &System, sets: &[(String, String)]) -> Result<(), Failure> {
    let json = args.remote.json;
    let cameras = system.cameras().list().await.map_err(fail)?;
    if cameras.is_empty() {
        return Err(other(format!(
            "system {} has no camera (no component answered CAMERA_INFORMATION)",
            system.target().system
        )));
    }
    if let What::List = args.what {
        let mut lines = Vec::new();
        for (i, cam) in cameras.iter().enumerate() {
            lines.push(describe(i + 1, cam, json).await);
        }
        return print_lines(&lines);
    }
    let n = args.camera;
    let cam = cameras.get(n - 1).ok_or_else(|| {
        other(format!(
            "system {} has {} camera(s): no camera {n}",
            system.target().system,
            cameras.len()
        ))
    })?;
    let done = |what: &str| {
        if json {
            json!({"camera": n, "request": what, "result": "ACCEPTED"}).to_string()
        } else {
            format!("camera {n}: {what} accepted")
        }
    };
    match &args.what {
        What::List => Ok(()),
        What::Photo => {
            let image = cam.take_photo().await.map_err(fail)?;
            print_lines(&[photo_line(n, &image, json)])?;
            if image.success {
                Ok(())
            } else {
                Err(other(format!(
                    "camera {n} failed to take photo {}",
                    image.index
                )))
            }
        }
        What::Video { action } => {
            match action {
                StartStop::Start => cam.start_video().await,
                StartStop::Stop => cam.stop_video().await,
            }
            .map_err(fail)?;
            let what = match action {
                StartStop::Start => "video start",
                StartStop::Stop => "video stop",
            };
            print_lines(&[done(what)])
        }
        What::Interval {
            action,
            seconds,
            count,
        } => match action {
            StartStop::Start => {
                cam.start_photo_interval(seconds.unwrap_or(0.0), *count)
                    .await
                    .map_err(refused)?;
                print_lines(&[done("interval start")])
            }
            StartStop::Stop => {
                cam.stop_photo_interval().await.map_err(fail)?;
                print_lines(&[done("interval stop")])
            }
        },
        What::Mode { mode } => {
            let m = match mode {
                ModeArg::Photo => CameraMode::IMAGE,
                ModeArg::Video => CameraMode::VIDEO,
            };
            cam.set_mode(m).await.map_err(fail)?;
            print_lines(&[done(&format!("mode {}", mode_name(m)))])
        }
        What::Settings { .. } => {
            for (name, value) in sets {
                let taken = cam.set(name, value).await.map_err(refused)?;
                eprintln!("camera {n}: {name} = {taken}");
            }
            let settings = cam.settings().await.map_err(fail)?;
            let lines: Vec<String> = settings.iter().map(|s| setting_line(s, json)).collect();
            print_lines(&lines)
        }
    }
}

fn value_json(v: &ExtValue) -> Value {
    match v {
        ExtValue::Custom(s) => json!(s),
        ExtValue::F32(f) => json!(f),
        ExtValue::F64(f) => json!(f),
        ExtValue::U64(u) => json!(u),
        ExtValue::I64(i) => json!(i),
        other => json!(other.as_f64().map(|f| f as i64)),
    }
}

fn setting_line(s: &SettingView, json: bool) -> String {
    if json {
        return json!({
            "name": s.name,
            "value": value_json(&s.value),
            "type": s.value.ty().name(),
            "option": s.option,
            "description": s.description,
            "options": s.options.iter().map(|(n, v)| json!({"name": n, "value": value_json(v)})).collect::<Vec<_>>(),
            "excluded": s.excluded,
            "read_only": s.read_only,
        })
        .to_string();
    }
    let value = match &s.option {
        Some(o) => format!("{} ({o})", s.value),
        None => s.value.to_string(),
    };
    let mut line = format!("{:<16} {value}", s.name);
    if !s.description.is_empty() {
        line.push_str(&format!("  — {}", s.description));
    }
    if s.excluded {
        line.push_str(" [does not apply now]");
    }
    if s.read_only {
        line.push_str(" [read-only]");
    }
    line
}

fn photo_line(n: usize, i: &ImageCaptured, json: bool) -> String {
    if json {
        return json!({
            "camera": n,
            "index": i.index,
            "success": i.success,
            "file_url": i.file_url,
            "time_utc_us": i.time_utc_us,
            "lat": i.lat,
            "lon": i.lon,
            "alt": i.alt_m,
            "relative_alt": i.relative_alt_m,
        })
        .to_string();
    }
    format!(
        "camera {n}: photo {} {} at {:.7}, {:.7}, {:.1} m ({:.1} m up){}",
        i.index,
        if i.file_url.is_empty() {
            "(no file)"
        } else {
            &i.file_url
        },
        i.lat,
        i.lon,
        i.alt_m,
        i.relative_alt_m,
        if i.success { "" } else { ", FAILED" }
    )
}

async fn describe(n: usize, cam: &Camera, json: bool) -> String {
    let info: &CameraInfo = cam.info();
    let status = cam.capture_status().await.ok();
    let storage = cam.storage().await.unwrap_or_default();
    if json {
        return json!({
            "camera": n,
            "component": {"system": info.component.system, "component": info.component.component},
            "vendor": info.vendor,
            "model": info.model,
            "firmware": info.firmware,
            "resolution": info.resolution.map(|(h, v)| json!([h, v])),
            "focal_length_mm": info.focal_length_mm,
            "flags": info.flags.0,
            "definition_uri": info.definition_uri,
            "definition_version": info.definition_version,
            "image_count": status.map(|s| s.image_count),
            "video_on": status.map(|s| s.video_on),
            "interval_on": status.map(|s| s.interval_on),
            "storage": storage.iter().map(|s| json!({
                "id": s.id, "name": s.name, "total_mib": s.total_mib,
                "used_mib": s.used_mib, "available_mib": s.available_mib,
            })).collect::<Vec<_>>(),
        })
        .to_string();
    }
    let mut line = format!(
        "camera {n}: {} {} {}",
        info.component, info.vendor, info.model
    );
    if let Some((h, v)) = info.resolution {
        line.push_str(&format!(", {h}x{v}"));
    }
    if !info.definition_uri.is_empty() {
        line.push_str(&format!(
            ", definition {} v{}",
            info.definition_uri, info.definition_version
        ));
    }
    if let Some(s) = status {
        line.push_str(&format!(
            ", {} photos{}{}",
            s.image_count,
            if s.video_on { ", recording" } else { "" },
            if s.interval_on { ", interval on" } else { "" }
        ));
    }
    for s in &storage {
        line.push_str(&format!(
            ", storage {} {:.0}/{:.0} MiB free",
            s.id, s.available_mib, s.total_mib
        ));
    }
    line
}
