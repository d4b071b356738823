//! `mavstack decode` and `mavstack encode`: raw streams and tlogs ⇄ JSON lines.

use core::fmt::Write as _;
use std::io::{self, BufRead, Read, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow};
use clap::Args;
use mavstack_core::MAX_PAYLOAD_LEN;
use mavstack_core::parse::{Item, SliceParser, Stats};
use mavstack_core::signing::{self, SecretKey};
use mavstack_core::wire::{Frame, FrameHeader, MAX_FRAME_LEN, Version, emit};
use mavstack_dialect::codec::{self, Value};
use mavstack_dialect::{Dialect, Message};
use serde_json::Value as Json;

use crate::Failure;
use crate::json_frames::{push_fields, push_json_str, value_from_json};

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
    /// With `--count`: also print `frames=N bytes=B seconds=S` for the parse loop alone to
    /// stderr, the line the peer benchmarks of shared/peers print (file reading excluded).
    #[arg(long, requires = "count")]
    time: bool,
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

fn read_input(file: Option<&Path>) -> Result<Vec<u8>, Failure> {
    let mut data = Vec::new();
    match file {
        Some(path) => {
            data = std::fs::read(path)
                .map_err(|e| Failure::Input(anyhow!("cannot read {}: {e}", path.display())))?;
        }
        None => {
            io::stdin()
                .lock()
                .read_to_end(&mut data)
                .context("reading stdin")?;
        }
    }
    Ok(data)
}

pub(crate) fn parse_key(key: Option<&str>) -> Result<Option<SecretKey>, Failure> {
    key.map(|k| SecretKey::from_hex(k).map_err(|e| Failure::Input(anyhow!("--key: {e}"))))
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

/// A frame as one JSON line, or `None` for an unknown id without `--keep-unknown`.
pub(crate) fn frame_line(
    out: &mut String,
    frame: &Frame<&[u8]>,
    message: Option<&Message>,
    ts_us: Option<u64>,
    key: Option<&SecretKey>,
    counts: &mut Counts,
) {
    out.push('{');
    if let Some(ts) = ts_us {
        let _ = write!(out, "\"ts_us\":{ts},");
    }
    let _ = write!(
        out,
        "\"version\":{},\"seq\":{},\"sysid\":{},\"compid\":{},\"msgid\":{},\"name\":",
        frame.version().number(),
        frame.seq(),
        frame.sysid(),
        frame.compid(),
        frame.msg_id()
    );
    match message {
        Some(m) => {
            push_json_str(out, &m.name);
            out.push(',');
            let values = codec::decode(m, frame.payload());
            push_fields(out, m, &values);
        }
        None => {
            out.push_str("null,\"payload_hex\":\"");
            for b in frame.payload() {
                let _ = write!(out, "{b:02x}");
            }
            out.push('"');
        }
    }
    if let Some(sig) = frame.signature() {
        let status = match key {
            None => "unchecked",
            Some(k) => match signing::verify(frame, k) {
                Ok(()) => "valid",
                Err(_) => {
                    counts.bad_signature += 1;
                    "invalid"
                }
            },
        };
        let _ = write!(
            out,
            ",\"signature\":{{\"link_id\":{},\"timestamp\":{},\"status\":\"{status}\"}}",
            sig.link_id, sig.timestamp
        );
    }
    out.push_str("}\n");
}

/// The frames of a tlog: each record is an 8-byte big-endian timestamp and one frame. A
/// record that does not hold a frame is skipped byte by byte until one does.
fn tlog_frames<'a>(
    data: &'a [u8],
    lookup: &impl Fn(u32) -> Option<u8>,
    stats: &mut Stats,
    mut each: impl FnMut(Item<'a>, u64),
) {
    stats.bytes = data.len() as u64;
    let mut pos = 0;
    while pos + 8 < data.len() {
        let mut ts = [0u8; 8];
        ts.copy_from_slice(&data[pos..pos + 8]);
        let ts = u64::from_be_bytes(ts);
        let rest = &data[pos + 8..];
        if let Ok(frame) = Frame::new_checked(rest) {
            let len = frame.frame_len();
            let frame = Frame::new_unchecked(&rest[..len]);
            match lookup(frame.msg_id()) {
                Some(extra) if frame.check_crc(extra) => {
                    stats.frames += 1;
                    each(Item::Frame(frame), ts);
                    pos += 8 + len;
                    continue;
                }
                Some(_) => stats.bad_crc += 1,
                None => {
                    stats.unknown_id += 1;
                    each(Item::Unknown(frame), ts);
                    pos += 8 + len;
                    continue;
                }
            }
        }
        stats.skipped_bytes += 1;
        pos += 1;
    }
    stats.skipped_bytes += (data.len() - pos) as u64;
}

pub(crate) fn decode(args: &DecodeArgs) -> Result<(), Failure> {
    let key = parse_key(args.key.as_deref())?;
    let data = read_input(args.file.as_deref())?;
    let is_tlog = args.tlog
        || (!args.raw
            && args.file.as_ref().is_some_and(|f| {
                f.extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("tlog"))
            }));
    // Counting a raw stream of a built-in dialect goes through the generated, typed code.
    let started = std::time::Instant::now();
    if args.count
        && !is_tlog
        && let Some((parse, bad_signature)) =
            crate::fast_count::count_builtin(&args.dialect, &data, key.as_ref())
    {
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
        println!("{}", counts.json());
        if args.stats {
            eprintln!("{}", counts.json());
        }
        return Ok(());
    }
    let dialect = crate::dialect_cmd::load(&args.dialect)?;
    let lookup = |id: u32| dialect.message(id).map(|m| m.crc_extra);
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
        let mut stats = Stats::default();
        tlog_frames(&data, &lookup, &mut stats, |item, ts| {
            handle(item, Some(ts), &mut counts)
        });
        counts.parse = stats;
    } else {
        let mut parser = SliceParser::new(&data, lookup);
        let mut progress = Progress::new(data.len());
        while let Some(item) = parser.next() {
            handle(item, None, &mut counts);
            progress.update(parser.position());
        }
        progress.finish();
        counts.parse = *parser.stats();
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
        eprintln!("{}", counts.json());
    }
    Ok(())
}

/// A one-line progress report on stderr for inputs of 16 MB or more, only when stderr is a
/// terminal (never when piped or in tests).
struct Progress {
    total: usize,
    shown: Option<std::time::Instant>,
    started: std::time::Instant,
}

impl Progress {
    fn new(total: usize) -> Self {
        use std::io::IsTerminal as _;
        let on = total >= 16 << 20 && io::stderr().is_terminal();
        let now = std::time::Instant::now();
        Self {
            total,
            shown: on.then_some(now),
            started: now,
        }
    }

    fn update(&mut self, done: usize) {
        let Some(last) = self.shown else { return };
        if last.elapsed() < core::time::Duration::from_millis(200) {
            return;
        }
        self.shown = Some(std::time::Instant::now());
        let mb = |n: usize| n as f64 / 1e6;
        let rate = mb(done) / self.started.elapsed().as_secs_f64().max(1e-9);
        eprint!(
            "\rdecoding: {:>3}% ({:.1} of {:.1} MB, {rate:.0} MB/s)",
            done * 100 / self.total.max(1),
            mb(done),
            mb(self.total)
        );
    }

    fn finish(&self) {
        if self.shown.is_some() {
            eprint!("\r\x1b[2K");
        }
    }
}

fn field_of<'o>(obj: &'o serde_json::Map<String, Json>, key: &str) -> Option<&'o Json> {
    obj.get(key).filter(|v| !v.is_null())
}

fn small(obj: &serde_json::Map<String, Json>, key: &str, max: u64) -> Result<Option<u64>, String> {
    match field_of(obj, key) {
        None => Ok(None),
        Some(v) => v
            .as_u64()
            .filter(|&n| n <= max)
            .map(Some)
            .ok_or_else(|| format!("{key}: {v} is not a number from 0 to {max}")),
    }
}

/// Encodes one JSON object into `buf`; returns the frame length.
fn encode_object(
    obj: &serde_json::Map<String, Json>,
    dialect: &Dialect,
    args: &EncodeArgs,
    key: Option<&SecretKey>,
    seq: &mut u8,
    buf: &mut [u8; MAX_FRAME_LEN],
) -> Result<usize, String> {
    let message = match (field_of(obj, "msgid"), field_of(obj, "name")) {
        (Some(id), _) => {
            let id = id
                .as_u64()
                .and_then(|i| u32::try_from(i).ok())
                .ok_or_else(|| format!("msgid: {id} is not a message id"))?;
            dialect
                .message(id)
                .ok_or_else(|| format!("message id {id} is not in dialect {}", dialect.name))?
        }
        (None, Some(Json::String(name))) => dialect
            .message_by_name(name)
            .ok_or_else(|| format!("message {name} is not in dialect {}", dialect.name))?,
        _ => return Err("no \"msgid\" or \"name\"".to_owned()),
    };
    let version = match small(obj, "version", 2)? {
        None | Some(2) => Version::V2,
        Some(1) => Version::V1,
        Some(v) => return Err(format!("version: {v} is neither 1 nor 2")),
    };
    let fields = match field_of(obj, "fields") {
        None => serde_json::Map::new(),
        Some(Json::Object(f)) => f.clone(),
        Some(other) => return Err(format!("fields: expected an object, got {other}")),
    };
    if let Some(unknown) = fields.keys().find(|k| message.field(k).is_none()) {
        return Err(format!("message {} has no field {unknown:?}", message.name));
    }
    let values: Vec<Value> = message
        .fields
        .iter()
        .map(|f| {
            fields
                .get(&f.name)
                .map_or_else(|| Ok(Value::zero(&f.ty)), |j| value_from_json(f, j))
        })
        .collect::<Result<_, _>>()?;
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    let len = codec::encode(message, &values, &mut payload).map_err(|e| e.to_string())?;
    let this_seq = match small(obj, "seq", 255)? {
        Some(s) => u8::try_from(s).unwrap_or(u8::MAX),
        None => *seq,
    };
    *seq = this_seq.wrapping_add(1);
    let header = FrameHeader {
        version,
        seq: this_seq,
        sysid: small(obj, "sysid", 255)?.map_or(args.sysid, |v| u8::try_from(v).unwrap_or(u8::MAX)),
        compid: small(obj, "compid", 255)?
            .map_or(args.compid, |v| u8::try_from(v).unwrap_or(u8::MAX)),
        signed: key.is_some() && version == Version::V2,
    };
    // MAVLink 1 carries the base fields only (as the C library sends them). An object whose
    // extension fields are not all zero cannot be said that way: it goes out with the whole
    // payload, as pymavlink sends it, so that decode(encode(x)) == x still holds.
    let v1_len = if payload[message.min_len..len].iter().any(|&b| b != 0) {
        message.max_len
    } else {
        message.min_len
    };
    let info = mavstack_core::MessageInfo {
        id: message.id,
        name: "",
        crc_extra: message.crc_extra,
        min_len: u8::try_from(v1_len).unwrap_or(u8::MAX),
        max_len: u8::try_from(message.max_len).unwrap_or(u8::MAX),
        target_system_offset: None,
        target_component_offset: None,
    };
    let frame_len = emit(&header, &info, &payload[..len], buf).map_err(|e| e.to_string())?;
    match key.filter(|_| header.signed) {
        None => Ok(frame_len),
        Some(k) => {
            let sig = field_of(obj, "signature").and_then(Json::as_object);
            let link_id = match sig.map(|s| small(s, "link_id", 255)).transpose()?.flatten() {
                Some(l) => u8::try_from(l).unwrap_or(u8::MAX),
                None => args.link_id,
            };
            let timestamp = match sig
                .map(|s| small(s, "timestamp", signing::MAX_TIMESTAMP))
                .transpose()?
                .flatten()
            {
                Some(t) => t,
                None => {
                    let now = std::time::SystemTime::now()
                        .duration_since(std::time::UNIX_EPOCH)
                        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX));
                    signing::timestamp_from_unix_micros(now)
                }
            };
            signing::append_signature(buf, frame_len, link_id, timestamp, k)
                .map_err(|e| e.to_string())
        }
    }
}

pub(crate) fn encode(args: &EncodeArgs) -> Result<(), Failure> {
    let dialect = crate::dialect_cmd::load(&args.dialect)?;
    let key = parse_key(args.key.as_deref())?;
    let input: Box<dyn BufRead> = match &args.file {
        Some(path) => Box::new(io::BufReader::new(
            std::fs::File::open(path)
                .map_err(|e| Failure::Input(anyhow!("cannot read {}: {e}", path.display())))?,
        )),
        None => Box::new(io::stdin().lock()),
    };
    let mut sink: Box<dyn Write> = match &args.output {
        Some(path) => Box::new(io::BufWriter::new(std::fs::File::create(path).map_err(
            |e| Failure::Other(anyhow!("cannot create {}: {e}", path.display())),
        )?)),
        None => Box::new(io::BufWriter::new(io::stdout().lock())),
    };
    let name = args
        .file
        .as_ref()
        .map_or_else(|| "stdin".to_owned(), |p| p.display().to_string());
    let mut seq = 0u8;
    let mut buf = [0u8; MAX_FRAME_LEN];
    for (n, line) in input.lines().enumerate() {
        let line = line.with_context(|| format!("reading {name}"))?;
        if line.trim().is_empty() {
            continue;
        }
        let at = |e: String| Failure::Input(anyhow!("{name}:{}: {e}", n + 1));
        let obj: serde_json::Map<String, Json> =
            serde_json::from_str(&line).map_err(|e| at(format!("not a JSON object: {e}")))?;
        let len =
            encode_object(&obj, &dialect, args, key.as_ref(), &mut seq, &mut buf).map_err(at)?;
        sink.write_all(&buf[..len]).context("writing output")?;
    }
    sink.flush().context("writing output")?;
    Ok(())
}
