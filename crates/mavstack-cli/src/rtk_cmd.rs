//! `mavstack rtk CONN --from SOURCE`: an RTCM3 stream forwarded to a vehicle as RTK
//! corrections, over `mavstack::system::Rtk::forward` (GPS_RTCM_DATA, frames found by their
//! CRC-24Q, the rest counted). The counts and the rate go to stderr every `--every` seconds
//! (or as JSON lines on stdout with `--json`), and a summary at the end: when the source
//! ends (a file read to its end, a TCP server that closed) or on SIGINT/SIGTERM.

use clap::Args;
use mavstack::system::{RtcmSource, RtkReport};
use serde_json::json;

use crate::link_cmd::{interrupted, period_arg, runtime, seconds};
use crate::remote::{RemoteArgs, close, connect, print_lines};
use crate::{Failure, fail, other};

#[derive(Debug, Args)]
pub(crate) struct RtkArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    /// Where the RTCM3 stream comes from: tcp:HOST:PORT, serial:DEVICE:BAUD, or a file.
    #[arg(long)]
    from: String,
    /// Seconds between two reports of the counts and the rate.
    #[arg(long, default_value_t = 1.0, value_parser = period_arg)]
    every: f64,
}

pub(crate) fn rtk(args: &RtkArgs) -> Result<(), Failure> {
    let source = RtcmSource::parse(&args.from).map_err(|e| Failure::Input(e.into()))?;
    let every = seconds(args.every, "--every")?;
    let json = args.remote.json;
    runtime()?.block_on(async {
        let stop = interrupted();
        let reader = source.open().await.map_err(fail)?;
        let session = connect(&args.remote).await?;
        let rtk = session.system().rtk();
        let mut last = RtkReport::default();
        let mut before = RtkReport::default();
        let ended = {
            let forward = rtk.forward(reader, every, |report| {
                show(report, &before, json);
                before = *report;
                last = *report;
            });
            tokio::select! {
                result = forward => Some(result),
                () = stop => None,
            }
        };
        close(session).await?;
        let report = match ended {
            Some(result) => result.map_err(fail)?,
            None => last,
        };
        summary(&report, &source, json)?;
        if report.frames == 0 {
            return Err(other(format!(
                "no RTCM3 frame in {} bytes from {source} ({} damaged)",
                report.read, report.damaged
            )));
        }
        Ok(())
    })
}

/// Frames and bytes a second between two reports.
fn rate(now: &RtkReport, before: &RtkReport) -> (f64, f64) {
    let dt = now.elapsed.saturating_sub(before.elapsed).as_secs_f64();
    if dt <= 0.0 {
        return (0.0, 0.0);
    }
    let frames = now.sent.saturating_sub(before.sent) as f64 / dt;
    let bytes = now.sent_bytes.saturating_sub(before.sent_bytes) as f64 / dt;
    ((frames * 10.0).round() / 10.0, bytes.round())
}

fn counts(r: &RtkReport) -> serde_json::Value {
    json!({
        "seconds": (r.elapsed.as_secs_f64() * 1000.0).round() / 1000.0,
        "read": r.read,
        "frames": r.frames,
        "sent": r.sent,
        "sent_bytes": r.sent_bytes,
        "messages": r.fragments,
        "damaged": r.damaged,
        "skipped": r.skipped,
        "too_long": r.too_long,
    })
}

fn line(r: &RtkReport) -> String {
    format!(
        "{} frames sent ({} bytes in {} GPS_RTCM_DATA), {} damaged, {} too long, {} bytes \
         skipped",
        r.sent, r.sent_bytes, r.fragments, r.damaged, r.too_long, r.skipped
    )
}

/// A report while forwarding: the counts and the rate since the one before.
fn show(report: &RtkReport, before: &RtkReport, json: bool) {
    let (frames, bytes) = rate(report, before);
    if json {
        let mut object = counts(report);
        object["frames_per_second"] = json!(frames);
        object["bytes_per_second"] = json!(bytes);
        // A closed stdout ends the command at its summary, which reports it.
        let _ = print_lines(&[object.to_string()]);
    } else {
        eprintln!("rtk: {frames} frames/s, {bytes} B/s; {}", line(report));
    }
}

/// The last line: what was forwarded from where, with the rate over the whole run.
fn summary(report: &RtkReport, source: &RtcmSource, json: bool) -> Result<(), Failure> {
    let (frames, bytes) = rate(report, &RtkReport::default());
    let text = if json {
        let mut object = counts(report);
        object["source"] = json!(source.to_string());
        object["done"] = json!(true);
        object["frames_per_second"] = json!(frames);
        object["bytes_per_second"] = json!(bytes);
        object.to_string()
    } else {
        format!(
            "rtk from {source}: {}, in {:.1} s ({frames} frames/s, {bytes} B/s)",
            line(report),
            report.elapsed.as_secs_f64()
        )
    };
    print_lines(&[text])
}
