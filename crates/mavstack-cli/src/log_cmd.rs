//! `mavstack log summary | plot | filter`: what a tlog (or raw capture) holds, time series of
//! its fields as an image, and a smaller log of the frames selected
//! (`docs/contracts/logs-and-operator-tools.md`).

use std::collections::{BTreeMap, HashMap};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow};
use clap::{Args, Subcommand};
use mavstack_xml::Dialect;
use serde_json::{Map, Value, json};

use crate::Failure;
use crate::log_plot::{PlotArgs, plot};
use crate::log_reader::{LogFrame, is_tlog, read_log};
use mavstack_transport::tlog;

/// `mavstack log ...`.
#[derive(Debug, Subcommand)]
pub(crate) enum LogAction {
    /// Duration, systems and components, message counts and rates per type, sequence loss
    /// per source, versions and signed share, bad frames and skipped bytes.
    Summary(SummaryArgs),
    /// Time series of fields (`ATTITUDE.roll GLOBAL_POSITION_INT.relative_alt`) as a PNG or
    /// SVG image, one series per field and system.
    Plot(PlotArgs),
    /// A smaller log with exactly the frames selected, bytes and timestamps unchanged.
    Filter(FilterArgs),
    /// A vehicle's logs (LOG_REQUEST_LIST): id, size and time; with `--json` one
    /// `{"id","size","time_utc","time"}` object per log.
    List(crate::log_download_cmd::ListArgs),
    /// Download a vehicle's logs as `log_<ID>.bin` (LOG_REQUEST_DATA with lost chunks asked
    /// for again, or MAVFTP where the vehicle keeps them as files).
    Download(crate::log_download_cmd::DownloadArgs),
    /// Erase every log on the vehicle (LOG_ERASE, then LOG_REQUEST_LIST to see that none is
    /// left); needs `--yes`.
    Erase(crate::log_download_cmd::EraseArgs),
}

/// `mavstack log summary`.
#[derive(Debug, Args)]
pub(crate) struct SummaryArgs {
    /// A tlog (`.tlog`) or a raw MAVLink capture.
    file: PathBuf,
    /// One JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// A built-in dialect name or a path to an XML file (message names and checksums).
    #[arg(long, default_value = "ardupilotmega")]
    dialect: String,
}

/// `mavstack log filter`.
#[derive(Debug, Args)]
pub(crate) struct FilterArgs {
    /// A tlog (`.tlog`) or a raw MAVLink capture.
    file: PathBuf,
    /// Where to write: a tlog when the name ends in `.tlog` (the input must be one), raw
    /// frames otherwise.
    out: PathBuf,
    /// Only these message types (names, comma-separated: `HEARTBEAT,ATTITUDE`).
    #[arg(long, value_delimiter = ',', value_name = "A,B")]
    types: Vec<String>,
    /// Only frames from this system id.
    #[arg(long, value_name = "N")]
    sysid: Option<u8>,
    /// Only frames from this many seconds after the log's first timestamp on (tlogs; from 0
    /// to 1e13).
    #[arg(long, value_name = "S", value_parser = offset_arg)]
    from: Option<f64>,
    /// Only frames up to this many seconds after the log's first timestamp (tlogs; from 0 to
    /// 1e13).
    #[arg(long, value_name = "S", value_parser = offset_arg)]
    to: Option<f64>,
    /// A built-in dialect name or a path to an XML file (message names and checksums).
    #[arg(long, default_value = "ardupilotmega")]
    dialect: String,
}

pub(crate) fn run(action: LogAction) -> Result<(), Failure> {
    match action {
        LogAction::Summary(args) => summary(&args),
        LogAction::Plot(args) => plot(&args),
        LogAction::Filter(args) => filter(&args),
        LogAction::List(args) => crate::log_download_cmd::list(&args),
        LogAction::Download(args) => crate::log_download_cmd::download(&args),
        LogAction::Erase(args) => crate::log_download_cmd::erase(&args),
    }
}

/// The name of message `id` in `dialect`, or pymavlink's `UNKNOWN_<id>`.
pub(crate) fn message_name(dialect: &Dialect, id: u32) -> String {
    dialect
        .message(id)
        .map_or_else(|| format!("UNKNOWN_{id}"), |m| m.name.clone())
}

/// One source's counts.
#[derive(Default)]
struct Source {
    frames: u64,
    lost: u64,
    last_seq: Option<u8>,
    types: HashMap<u32, u64>,
}

/// What `log summary` counts.
#[derive(Default)]
struct Summary {
    first_ts: Option<u64>,
    /// The latest timestamp seen (a log whose clock stepped back keeps its end).
    max_ts: Option<u64>,
    /// The previous record's timestamp.
    prev_ts: Option<u64>,
    /// Records whose timestamp is earlier than the record's before them.
    backward_steps: u64,
    v1: u64,
    v2: u64,
    signed: u64,
    sources: BTreeMap<(u8, u8), Source>,
}

impl Summary {
    fn add(&mut self, f: &LogFrame<'_>) {
        if let Some(ts) = f.ts_us {
            self.first_ts.get_or_insert(ts);
            if self.prev_ts.is_some_and(|prev| ts < prev) {
                self.backward_steps += 1;
            }
            self.prev_ts = Some(ts);
            self.max_ts = Some(self.max_ts.map_or(ts, |m| m.max(ts)));
        }
        let frame = &f.frame;
        if frame.version() == mavstack_core::wire::Version::V2 {
            self.v2 += 1;
        } else {
            self.v1 += 1;
        }
        if frame.is_signed() {
            self.signed += 1;
        }
        let source = self
            .sources
            .entry((frame.sysid(), frame.compid()))
            .or_default();
        source.frames += 1;
        // As mavloss counts: the gap between the sequence number expected and the one seen.
        let seq = frame.seq();
        if let Some(last) = source.last_seq {
            source.lost += u64::from(seq.wrapping_sub(last.wrapping_add(1)));
        }
        source.last_seq = Some(seq);
        *source.types.entry(frame.msg_id()).or_default() += 1;
    }

    /// From the first timestamp to the latest one (0 when none is later than the first).
    fn duration_s(&self) -> Option<f64> {
        Some(self.max_ts?.saturating_sub(self.first_ts?) as f64 / 1e6)
    }
}

fn summary(args: &SummaryArgs) -> Result<(), Failure> {
    let dialect = crate::dialect_cmd::load(&args.dialect)?;
    let mut s = Summary::default();
    let counts = read_log(&args.file, &dialect, "summary", |f| s.add(f))?;
    let duration = s.duration_s();
    let rate = |n: u64| match duration {
        Some(d) if d > 0.0 => Some((n as f64 / d * 1000.0).round() / 1000.0),
        _ => None,
    };
    let systems: Vec<Value> = s
        .sources
        .iter()
        .map(|(&(sysid, compid), src)| {
            let mut types: Vec<(String, u64)> = src
                .types
                .iter()
                .map(|(&id, &n)| (message_name(&dialect, id), n))
                .collect();
            types.sort();
            let types: Map<String, Value> = types
                .into_iter()
                .map(|(name, n)| (name, json!({"count": n, "rate_hz": rate(n)})))
                .collect();
            json!({"sysid": sysid, "compid": compid, "frames": src.frames, "lost": src.lost,
                   "types": types})
        })
        .collect();
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    if args.json {
        let obj = json!({
            "file": args.file.display().to_string(),
            "duration_s": duration.map(|d| (d * 1000.0).round() / 1000.0),
            "start_unix_s": s.first_ts.map(|t| t as f64 / 1e6),
            "frames": counts.frames,
            "bad_frames": counts.bad_frames,
            "skipped_bytes": counts.skipped_bytes,
            "bytes": counts.bytes,
            "signed_frames": s.signed,
            "time_backward_steps": s.first_ts.map(|_| s.backward_steps),
            "versions": {"1": s.v1, "2": s.v2},
            "systems": systems,
        });
        writeln!(out, "{obj}").context("writing output")?;
    } else {
        write_table(&mut out, args, &s, &counts, duration, &dialect).context("writing output")?;
    }
    out.flush().context("writing output")?;
    Ok(())
}

fn write_table(
    out: &mut impl Write,
    args: &SummaryArgs,
    s: &Summary,
    counts: &crate::log_reader::ReadCounts,
    duration: Option<f64>,
    dialect: &Dialect,
) -> std::io::Result<()> {
    let pct = |part: u64, whole: u64| 100.0 * part as f64 / whole.max(1) as f64;
    writeln!(out, "{}", args.file.display())?;
    match duration {
        Some(d) => writeln!(
            out,
            "  duration     {d:.1} s ({}:{:02})",
            (d / 60.0) as u64,
            (d % 60.0) as u64
        )?,
        None => writeln!(
            out,
            "  duration     unknown (a raw capture has no timestamps)"
        )?,
    }
    if s.backward_steps > 0 {
        writeln!(
            out,
            "  time         goes back {} times (timestamps earlier than the record's before)",
            s.backward_steps
        )?;
    }
    writeln!(
        out,
        "  frames       {} (MAVLink 1: {}, MAVLink 2: {}, signed: {} = {:.1} %)",
        counts.frames,
        s.v1,
        s.v2,
        s.signed,
        pct(s.signed, counts.frames)
    )?;
    writeln!(
        out,
        "  bad frames   {} ({} bytes skipped)",
        counts.bad_frames, counts.skipped_bytes
    )?;
    for (&(sysid, compid), src) in &s.sources {
        writeln!(
            out,
            "\n  system {sysid} component {compid}: {} frames, {} lost ({:.1} %)",
            src.frames,
            src.lost,
            pct(src.lost, src.frames + src.lost)
        )?;
        let mut types: Vec<(u64, String)> = src
            .types
            .iter()
            .map(|(&id, &n)| (n, message_name(dialect, id)))
            .collect();
        types.sort_by(|a, b| b.0.cmp(&a.0).then_with(|| a.1.cmp(&b.1)));
        for (n, name) in types {
            match duration.filter(|d| *d > 0.0) {
                Some(d) => writeln!(out, "    {name:<32} {n:>9} {:>9.2} Hz", n as f64 / d)?,
                None => writeln!(out, "    {name:<32} {n:>9}")?,
            }
        }
    }
    Ok(())
}

/// The message ids named by `--types`, each checked against the dialect.
pub(crate) fn type_ids(dialect: &Dialect, names: &[String]) -> Result<Vec<u32>, Failure> {
    names
        .iter()
        .filter(|n| !n.trim().is_empty())
        .map(|name| {
            dialect
                .messages
                .iter()
                .find(|m| m.name.eq_ignore_ascii_case(name.trim()))
                .map(|m| m.id)
                .ok_or_else(|| {
                    Failure::Input(anyhow!(
                        "--types: no message {name} in dialect {}",
                        dialect.name
                    ))
                })
        })
        .collect()
}

/// `--from`/`--to`: seconds from 0 to 1e13 (a tlog's microsecond timestamps reach 1.8e13 s).
fn offset_arg(text: &str) -> Result<f64, String> {
    crate::link_cmd::number_within(text, 0.0, 1e13, "seconds")
}

fn seconds_arg(value: Option<f64>, what: &str) -> Result<Option<u64>, Failure> {
    value
        .map(|s| {
            if s.is_finite() && s >= 0.0 {
                Ok((s * 1e6) as u64)
            } else {
                Err(Failure::Input(anyhow!(
                    "{what} must be a number of seconds, 0 or more"
                )))
            }
        })
        .transpose()
}

fn filter(args: &FilterArgs) -> Result<(), Failure> {
    let dialect = crate::dialect_cmd::load(&args.dialect)?;
    let types = type_ids(&dialect, &args.types)?;
    let from = seconds_arg(args.from, "--from")?;
    let to = seconds_arg(args.to, "--to")?;
    let tlog_in = is_tlog(&args.file);
    let tlog_out = is_tlog(&args.out);
    if !tlog_in && (from.is_some() || to.is_some()) {
        return Err(Failure::Input(anyhow!(
            "--from and --to need a tlog: {} is a raw capture without timestamps",
            args.file.display()
        )));
    }
    if !tlog_in && tlog_out {
        return Err(Failure::Input(anyhow!(
            "{} is a raw capture without timestamps: write a raw file, not {}",
            args.file.display(),
            args.out.display()
        )));
    }
    if same_file(&args.file, &args.out) {
        return Err(Failure::Input(anyhow!(
            "{} is both the input and the output",
            args.out.display()
        )));
    }
    let file = std::fs::File::create(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    // The one tlog writer: records as `record` and the router write them, raw frames alike.
    let mut out = tlog::Writer::new(file);
    let mut first: Option<u64> = None;
    let mut written = 0u64;
    let mut error: Option<std::io::Error> = None;
    read_log(&args.file, &dialect, "filter", |f| {
        let frame = &f.frame;
        let at = f
            .ts_us
            .map(|ts| ts.saturating_sub(*first.get_or_insert(ts)));
        let selected = (types.is_empty() || types.contains(&frame.msg_id()))
            && args.sysid.is_none_or(|s| s == frame.sysid())
            && from.is_none_or(|from| at.is_some_and(|t| t >= from))
            && to.is_none_or(|to| at.is_some_and(|t| t <= to));
        if !selected || error.is_some() {
            return;
        }
        let result = match f.ts_us.filter(|_| tlog_out) {
            Some(ts) => out.write_record(ts, frame.as_bytes()),
            None => out.write_raw(frame.as_bytes()),
        };
        match result {
            Ok(()) => written += 1,
            Err(e) => error = Some(e),
        }
    })?;
    if let Some(e) = error {
        return Err(Failure::Other(
            anyhow::Error::new(e).context(format!("writing {}", args.out.display())),
        ));
    }
    out.flush()
        .with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("{written} frames written to {}", args.out.display());
    Ok(())
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_core::wire::Frame;

    fn frame(seq: u8) -> Vec<u8> {
        // A MAVLink 1 HEARTBEAT of 1/1 with sequence number `seq` (its checksum is not
        // looked at here).
        vec![0xFE, 9, seq, 1, 1, 0, 0, 0, 0, 0, 2, 3, 0x51, 4, 3, 0, 0]
    }

    #[test]
    fn loss_is_the_gap_between_the_sequence_expected_and_the_one_seen_across_the_wrap() {
        let mut s = Summary::default();
        for seq in [250, 251, 253, 255, 2, 3] {
            let bytes = frame(seq);
            let frame = Frame::new_checked(&bytes[..]).expect("a frame");
            s.add(&LogFrame {
                ts_us: Some(1_000_000 * u64::from(seq)),
                frame,
                known: true,
            });
        }
        let src = &s.sources[&(1, 1)];
        // 252, 254, 0 and 1 missing.
        assert_eq!((src.frames, src.lost), (6, 4));
        assert_eq!((s.v1, s.v2, s.signed), (6, 0, 0));
        assert_eq!(src.types[&0], 6);
    }
}
