//! `mavstack decode` and `mavstack encode`: raw streams and tlogs ⇄ JSON lines.

use std::io::{self, BufRead, Read, Write};
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Args;
use mavstack_core::parse::{Item, Stats};
use mavstack_core::signing::{self, SecretKey};
use mavstack_core::wire::{Frame, MAX_FRAME_LEN};
use mavstack_transport::tlog;
use mavstack_xml::Message;
use mavstack_xml::codec;
use mavstack_xml::json::{self, EncodeDefaults, SignatureStatus};
use serde_json::Value as Json;

use crate::Failure;

#[derive(Debug, Args)]
pub(crate) struct DecodeArgs {
    /// A raw MAVLink stream or a .tlog (stdin when absent).
    file: Option<PathBuf>,
    /// A built-in dialect name or a path to an XML file.
    #[arg(long, default_value = "ardupilotmega")]
    dialect: String,
    /// Signing key (64 hex digits): report each signed frame's signature as valid or invalid.
    #[arg(long)]
    key: Option<String>,
    /// Also print frames of unknown message ids (`"name":null` and `"payload_hex"`).
    #[arg(long)]
    keep_unknown: bool,
    /// Print counts to stderr at the end.
    #[arg(long)]
    stats: bool,
    /// Parse, validate and decode every frame, but print only one JSON object of counts.
    #[arg(long)]
    count: bool,
    /// Read the input as a tlog (8-byte big-endian microsecond timestamp before each frame).
    /// Default: when the file name ends in `.tlog`.
    #[arg(long, conflicts_with = "raw")]
    tlog: bool,
    /// Read the input as a raw stream even if its name ends in `.tlog`.
    #[arg(long)]
    raw: bool,
    /// With `--count`: also print `frames=N bytes=B seconds=S` for the parse loop to stderr
    /// (the file's reading included, its opening and the dialect's loading not), the line
    /// the peers' benchmarks print: what `scripts/bench-peers.sh` compares
    /// (`docs/contracts/json-lines.md`).
    #[arg(long, requires = "count")]
    time: bool,
    /// With `--count` on a file: the threads that parse it, each a part of the file
    /// (default: one per processor). The counts are the same for any number.
    #[arg(long, requires = "count", value_parser = clap::value_parser!(u16).range(1..))]
    threads: Option<u16>,
}

#[derive(Debug, Args)]
pub(crate) struct EncodeArgs {
    /// JSON lines, one frame per line (stdin when absent).
    file: Option<PathBuf>,
    /// A built-in dialect name or a path to an XML file.
    #[arg(long, default_value = "ardupilotmega")]
    dialect: String,
    /// Sign every frame with this key (64 hex digits).
    #[arg(long)]
    key: Option<String>,
    /// Link id for signed frames whose object gives none.
    #[arg(long, default_value_t = 0)]
    link_id: u8,
    /// System id for objects that give none.
    #[arg(long, default_value_t = 255)]
    sysid: u8,
    /// Component id for objects that give none.
    #[arg(long, default_value_t = 190)]
    compid: u8,
    /// Write to this file instead of stdout.
    #[arg(long, short)]
    output: Option<PathBuf>,
}

/// The input as a stream (never read into memory whole) and its length when known.
fn open_input(file: Option<&Path>) -> Result<(Box<dyn Read>, u64), Failure> {
    match file {
        Some(path) => {
            let f = std::fs::File::open(path)
                .with_context(|| format!("cannot read {}", path.display()))
                .map_err(Failure::Input)?;
            let len = f.metadata().map_or(0, |m| m.len());
            Ok((Box::new(f), len))
        }
        None => Ok((Box::new(io::stdin().lock()), 0)),
    }
}

pub(crate) fn parse_key(key: Option<&str>) -> Result<Option<SecretKey>, Failure> {
    key.map(|k| crate::vehicle_cmd::secret_key(k, "--key"))
        .transpose()
}

/// Decoding counts (the JSON of `--count` and `--stats`).
#[derive(Default)]
pub(crate) struct Counts {
    pub(crate) parse: Stats,
    pub(crate) bad_signature: u64,
}

impl Counts {
    pub(crate) fn json(&self) -> String {
        let s = &self.parse;
        format!(
            "{{\"frames\":{},\"bytes\":{},\"bad_crc\":{},\"unknown_id\":{},\"bad_signature\":{},\"skipped_bytes\":{}}}",
            s.frames, s.bytes, s.bad_crc, s.unknown_id, self.bad_signature, s.skipped_bytes
        )
    }
}

/// A frame as one JSON line (appended to `out`), counting a signature that does not verify.
pub(crate) fn frame_line(
    out: &mut String,
    frame: &Frame<&[u8]>,
    message: Option<&Message>,
    ts_us: Option<u64>,
    key: Option<&SecretKey>,
    counts: &mut Counts,
) {
    if json::frame_line(out, frame, message, ts_us, key) == SignatureStatus::Invalid {
        counts.bad_signature += 1;
    }
}

pub(crate) fn decode(args: &DecodeArgs) -> Result<(), Failure> {
    let key = parse_key(args.key.as_deref())?;
    let (mut input, input_len) = open_input(args.file.as_deref())?;
    let cannot = |e: io::Error| {
        Failure::Input(anyhow::Error::new(e).context(match &args.file {
            Some(path) => format!("cannot read {}", path.display()),
            None => "cannot read stdin".to_owned(),
        }))
    };
    let is_tlog =
        args.tlog || (!args.raw && args.file.as_deref().is_some_and(crate::log_reader::is_tlog));
    // Counting a raw stream of a built-in dialect goes through the generated, typed code.
    let started = std::time::Instant::now();
    let source = match args.file.as_deref() {
        Some(path) => crate::fast_count::Source::File(path, args.threads.map(usize::from)),
        None => crate::fast_count::Source::Stream(&mut input),
    };
    if args.count
        && !is_tlog
        && let Some(counted) = crate::fast_count::count_builtin(&args.dialect, source, key.as_ref())
    {
        let (parse, bad_signature) = counted.map_err(cannot)?;
        let seconds = started.elapsed().as_secs_f64();
        if args.time {
            eprintln!(
                "frames={} bytes={} seconds={seconds:.6}",
                parse.frames, parse.bytes
            );
        }
        let counts = Counts {
            parse,
            bad_signature,
        };
        crate::json_line::to_stdout(&counts.json()).context("writing output")?;
        if args.stats {
            crate::json_line::to_stderr(&counts.json());
        }
        return Ok(());
    }
    let dialect = crate::dialect_cmd::load(&args.dialect)?;
    let table = dialect.message_table();
    let stdout = io::stdout();
    let mut sink = io::BufWriter::with_capacity(1 << 16, stdout.lock());
    let mut counts = Counts::default();
    let mut line = String::with_capacity(4096);
    let mut write_err: Option<io::Error> = None;
    let mut handle = |item: Item<'_>, ts: Option<u64>, counts: &mut Counts| {
        let (frame, known) = match item {
            Item::Frame(f) => (f, true),
            Item::Unknown(f) => (f, false),
        };
        if args.count {
            if let Some(m) = known.then(|| dialect.message(frame.msg_id())).flatten() {
                core::hint::black_box(codec::decode(m, frame.payload()));
            }
            if let Some(k) = key.as_ref().filter(|_| frame.is_signed())
                && signing::verify(&frame, k).is_err()
            {
                counts.bad_signature += 1;
            }
            return;
        }
        if !known && !args.keep_unknown {
            return;
        }
        line.clear();
        frame_line(
            &mut line,
            &frame,
            dialect.message(frame.msg_id()).filter(|_| known),
            ts,
            key.as_ref(),
            counts,
        );
        if write_err.is_none()
            && let Err(e) = sink.write_all(line.as_bytes())
        {
            write_err = Some(e);
        }
    };
    if is_tlog {
        let mut reader = tlog::Reader::new(input).with_crc_extra(table);
        if let Some(path) = &args.file {
            // A file is read as pymavlink opens one (its indexing walk first); stdin cannot be.
            let file = std::fs::File::open(path).map_err(cannot)?;
            reader = reader.indexed_as_pymavlink_opens(&file).map_err(cannot)?;
        }
        let mut stats = Stats::default();
        let mut progress = crate::progress::Progress::new("decoding", input_len);
        loop {
            if (stats.frames + stats.unknown_id) % 4096 == 0 {
                progress.set(reader.stats().bytes);
            }
            let Some((ts, bytes)) = reader.read_record().context("reading the tlog")? else {
                break;
            };
            let frame = Frame::new_unchecked(bytes);
            if table.info(frame.msg_id()).is_some() {
                stats.frames += 1;
                handle(Item::Frame(frame), Some(ts), &mut counts);
            } else {
                stats.unknown_id += 1;
                handle(Item::Unknown(frame), Some(ts), &mut counts);
            }
        }
        progress.finish();
        let read = reader.stats();
        (stats.bytes, stats.bad_crc, stats.skipped_bytes) =
            (read.bytes, read.bad_crc, read.skipped_bytes);
        counts.parse = stats;
    } else {
        let mut progress = crate::progress::Progress::new("decoding", input_len);
        let mut parse_counts = Counts::default();
        let stats = mavstack_transport::raw::read_items(
            &mut input,
            table,
            |item| handle(item, None, &mut parse_counts),
            |at| progress.set(at),
        )
        .map_err(cannot)?;
        progress.finish();
        counts.bad_signature = parse_counts.bad_signature;
        counts.parse = stats;
    }
    if let Some(e) = write_err {
        return Err(Failure::Other(
            anyhow::Error::new(e).context("writing output"),
        ));
    }
    if args.count {
        writeln!(sink, "{}", counts.json()).context("writing output")?;
    }
    sink.flush().context("writing output")?;
    if args.stats {
        crate::json_line::to_stderr(&counts.json());
    }
    Ok(())
}

pub(crate) fn encode(args: &EncodeArgs) -> Result<(), Failure> {
    let dialect = crate::dialect_cmd::load(&args.dialect)?;
    let key = parse_key(args.key.as_deref())?;
    let input: Box<dyn BufRead> = match &args.file {
        Some(path) => Box::new(io::BufReader::new(
            std::fs::File::open(path)
                .with_context(|| format!("cannot read {}", path.display()))
                .map_err(Failure::Input)?,
        )),
        None => Box::new(io::stdin().lock()),
    };
    let mut sink: Box<dyn Write> = match &args.output {
        Some(path) => Box::new(io::BufWriter::new(
            std::fs::File::create(path)
                .with_context(|| format!("cannot create {}", path.display()))?,
        )),
        None => Box::new(io::BufWriter::new(io::stdout().lock())),
    };
    let name = args
        .file
        .as_ref()
        .map_or_else(|| "stdin".to_owned(), |p| p.display().to_string());
    let defaults = EncodeDefaults {
        sysid: args.sysid,
        compid: args.compid,
        link_id: args.link_id,
        timestamp: None,
    };
    let mut seq = 0u8;
    let mut buf = [0u8; MAX_FRAME_LEN];
    for (n, line) in input.lines().enumerate() {
        let line = line.with_context(|| format!("reading {name}"))?;
        if line.trim().is_empty() {
            continue;
        }
        let at = |e: anyhow::Error| Failure::Input(e.context(format!("{name}:{}", n + 1)));
        let obj: serde_json::Map<String, Json> = serde_json::from_str(&line)
            .context("not a JSON object")
            .map_err(at)?;
        let len = json::encode_object(&obj, &dialect, &defaults, key.as_ref(), &mut seq, &mut buf)
            .map_err(|e| at(e.into()))?;
        sink.write_all(&buf[..len]).context("writing output")?;
    }
    sink.flush().context("writing output")?;
    Ok(())
}
