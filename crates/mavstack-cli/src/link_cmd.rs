//! `mavstack listen`, `record` and `replay`: live links to JSON lines or a table, links to
//! tlogs, and tlogs (or raw captures) back onto links with their original timing.

use std::collections::BTreeMap;
use std::io::{self, IsTerminal as _, Write as _};
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context as _, anyhow};
use clap::Args;
use core::time::Duration;
use mavstack::modes::Flavour;
use mavstack_core::Message as _;
use mavstack_core::parse::{Item, SliceParser};
use mavstack_core::wire::Frame;
use mavstack_dialects::common::{Heartbeat, MavAutopilot, MavModeFlag};
use mavstack_transport::conn::FileFormat;
use mavstack_transport::frame::FrameStats;
use mavstack_transport::{
    ConnSpec, Connection, FileMode, FrameBuf, FrameCommand, FrameEvent, FrameProtocol, Options,
    tlog,
};
use mavstack_xml::Dialect;
use tokio::time::Instant;

use crate::codec_cmd::{Counts, frame_line, parse_key};
use crate::{Failure, fail};
use mavstack::LinkSpec;

/// The options every link command shares.
#[derive(Debug, Args)]
pub(crate) struct DialectArg {
    /// A built-in dialect name or a path to an XML file.
    #[arg(long, default_value = "ardupilotmega")]
    dialect: String,
}

#[derive(Debug, Args)]
pub(crate) struct ListenArgs {
    /// Where to listen: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT,
    /// serial:/dev/ttyUSB0:57600, file:PATH, or the URL forms (udp://:14550, ...).
    conn: String,
    #[command(flatten)]
    dialect: DialectArg,
    /// Signing key (64 hex digits): report each signed frame's signature as valid or invalid.
    #[arg(long)]
    key: Option<String>,
    /// Also print frames of unknown message ids (`"name":null` and `"payload_hex"`).
    #[arg(long)]
    pub(crate) keep_unknown: bool,
    /// A live table of the messages seen, with counts and rates, instead of JSON lines.
    #[arg(long)]
    table: bool,
    /// Only these messages (names, comma-separated).
    #[arg(long, value_delimiter = ',')]
    filter: Vec<String>,
    /// Ask the first autopilot heard for these rates (`NAME:HZ`, comma-separated, e.g.
    /// `ATTITUDE:10,GLOBAL_POSITION_INT:5`): SET_MESSAGE_INTERVAL, and REQUEST_DATA_STREAM
    /// where that is refused or ignored.
    #[arg(long, value_delimiter = ',', value_name = "NAME:HZ")]
    rate: Vec<String>,
    /// Only frames from this system id.
    #[arg(long)]
    sysid: Option<u8>,
    /// Print counts to stderr at the end.
    #[arg(long)]
    stats: bool,
    /// Stop after this many frames (after filtering).
    #[arg(long)]
    count: Option<u64>,
    /// Stop after this many seconds (more than 0, at most a year: 31536000).
    #[arg(long, value_parser = duration_arg)]
    duration: Option<f64>,
}

#[derive(Debug, Args)]
pub(crate) struct RecordArgs {
    /// The link to record (as for `listen`).
    conn: String,
    /// The tlog to write (created or truncated).
    file: PathBuf,
    #[command(flatten)]
    dialect: DialectArg,
    /// Stop after this many frames.
    #[arg(long)]
    count: Option<u64>,
    /// Stop after this many seconds (more than 0, at most a year: 31536000).
    #[arg(long, value_parser = duration_arg)]
    duration: Option<f64>,
}

#[derive(Debug, Args)]
pub(crate) struct ReplayArgs {
    /// A tlog (original timing) or a raw capture (`--raw`, or a name not ending in .tlog:
    /// sent as fast as the link takes it).
    file: PathBuf,
    /// Where to send it (as for `listen`; udpout:HOST:PORT to reach a listener).
    conn: String,
    #[command(flatten)]
    dialect: DialectArg,
    /// Playback speed: 2 plays twice as fast; 0 sends as fast as possible (else from 0.001
    /// to 1000000).
    #[arg(long, default_value_t = 1.0, value_parser = speed_arg)]
    speed: f64,
    /// Start again from the beginning at the end, until interrupted.
    #[arg(long = "loop")]
    repeat: bool,
    /// Read the file as a raw stream even if its name ends in `.tlog`.
    #[arg(long)]
    raw: bool,
}

/// Opens `conn` with the frame protocol over `dialect`'s message table.
async fn open(
    spec: &ConnSpec,
    dialect: &Dialect,
    keep_unknown: bool,
    mode: FileMode,
) -> Result<Connection<FrameProtocol>, Failure> {
    let protocol = FrameProtocol::new(dialect.message_table())
        .keep_unknown(keep_unknown)
        .peer_events(false);
    let mut options = Options::default();
    options.file_mode = mode;
    Connection::open_with(spec, protocol, &options)
        .await
        .map_err(fail)
}

fn load_dialect(name: &str) -> Result<Arc<Dialect>, Failure> {
    crate::dialect_cmd::load(name).map(Arc::new)
}

/// Two workers: the link's driver reads on one while the command formats or writes on the
/// other, so a busy consumer does not stall the socket.
pub(crate) fn runtime() -> Result<tokio::runtime::Runtime, Failure> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the async runtime")
        .map_err(Failure::Other)
}

/// Resolves when the process is asked to stop (SIGINT or SIGTERM). The handlers are in
/// place when this returns, before the future is first polled: a signal right after a daemon
/// says it is ready stops it as one, not by the signal's default action. Call it inside the
/// runtime.
pub(crate) fn interrupted() -> impl Future<Output = ()> {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        let term = signal(SignalKind::terminate()).ok();
        let int = signal(SignalKind::interrupt()).ok();
        async move {
            match (term, int) {
                (Some(mut term), Some(mut int)) => {
                    tokio::select! {
                        _ = term.recv() => {}
                        _ = int.recv() => {}
                    }
                }
                _ => {
                    let _ = tokio::signal::ctrl_c().await;
                }
            }
        }
    }
    #[cfg(not(unix))]
    {
        async {
            let _ = tokio::signal::ctrl_c().await;
        }
    }
}

/// A link (a connection string and its link options, the one grammar of every command), or
/// a bad-input failure naming what is wrong with it. Options that change nothing for a
/// command that only reads or writes frames (`version`, `secure`, `trusted`, filters) are
/// accepted and have no effect there; `name` names the link in messages, `key` checks
/// signatures (`listen`).
pub(crate) fn parse_link(text: &str, dialect: &Dialect) -> Result<LinkSpec, Failure> {
    LinkSpec::parse_in(text, &dialect.message_table()).map_err(|e| Failure::Input(e.into()))
}

/// The longest wait any option gives, in seconds (a year): far enough for any use, near
/// enough that a deadline `now + wait` is never out of the clock's range.
pub(crate) const MAX_SECONDS: f64 = 31_536_000.0;

/// A number within `min..=max` (a clap value parser's body): NaN, infinities and anything out
/// of range are refused with the range in the message (clap names the option and exits 2).
pub(crate) fn number_within(text: &str, min: f64, max: f64, unit: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v >= min && v <= max => Ok(v),
        _ => Err(format!("not a number of {unit} from {min} to {max}")),
    }
}

/// A timeout in seconds: from 0.001 to 86400 (a day).
pub(crate) fn timeout_arg(text: &str) -> Result<f64, String> {
    number_within(text, 0.001, 86_400.0, "seconds")
}

/// A period in seconds (`--interval`, `--stats`, `--route-ttl`): from 0.01 to 86400.
pub(crate) fn period_arg(text: &str) -> Result<f64, String> {
    number_within(text, 0.01, 86_400.0, "seconds")
}

/// How long a command runs (`--duration`): more than 0, at most a year.
pub(crate) fn duration_arg(text: &str) -> Result<f64, String> {
    number_within(text, 0.001, MAX_SECONDS, "seconds")
}

/// `replay --speed`: 0 (as fast as possible) or from 0.001 to 1000000.
fn speed_arg(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v == 0.0 || (0.001..=1e6).contains(&v) => Ok(v),
        _ => Err("not 0 (as fast as possible) nor a speed from 0.001 to 1000000".to_owned()),
    }
}

/// A number of seconds given as option `what`, as a duration: the one conversion every
/// command uses (its parser has checked the option's own range; this refuses what is not a
/// wait at all: not finite, negative, zero or beyond [`MAX_SECONDS`]).
pub(crate) fn seconds(s: f64, what: &str) -> Result<Duration, Failure> {
    if !(s > 0.0 && s <= MAX_SECONDS) {
        return Err(Failure::Input(anyhow!(
            "{what}: {s} is not a number of seconds from 0 to {MAX_SECONDS}"
        )));
    }
    Duration::try_from_secs_f64(s)
        .map_err(|_| Failure::Input(anyhow!("{what}: {s} is not a number of seconds")))
}

/// When a command with `--duration` must stop.
fn deadline(duration: Option<f64>) -> Result<Option<Instant>, Failure> {
    duration
        .map(|s| seconds(s, "--duration").map(|d| Instant::now() + d))
        .transpose()
}

async fn sleep_until_opt(at: Option<Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => core::future::pending().await,
    }
}

/// Why [`next_batch`] returned.
enum Wake {
    /// Events are in the batch.
    Batch,
    /// The ticker ticked.
    Tick,
    /// Stop: interrupted, out of time, or the link ended.
    Done,
}

/// Waits for the next batch of events, a tick, or a reason to stop.
async fn next_batch<P: mavstack_transport::Protocol>(
    conn: &mut Connection<P>,
    batch: &mut Vec<P::Event>,
    stop: core::pin::Pin<&mut impl Future<Output = ()>>,
    until: Option<Instant>,
    ticker: &mut tokio::time::Interval,
) -> Wake {
    tokio::select! {
        n = conn.recv_many(batch, 1024) => if n == 0 { Wake::Done } else { Wake::Batch },
        () = stop => Wake::Done,
        () = sleep_until_opt(until) => Wake::Done,
        _ = ticker.tick() => Wake::Tick,
    }
}

fn counts_of(stats: &FrameStats, bad_signature: u64) -> Counts {
    let mut counts = Counts::default();
    counts.parse.frames = stats.frames;
    counts.parse.bytes = stats.bytes;
    counts.parse.bad_crc = stats.bad_crc;
    counts.parse.unknown_id = stats.unknown_id;
    counts.parse.skipped_bytes = stats.skipped_bytes;
    counts.parse.bad_incompat = stats.bad_incompat;
    counts.bad_signature = bad_signature;
    counts
}

/// One row of the `--table` view.
#[derive(Default)]
struct Row {
    count: u64,
    /// The count when the table was last drawn, for the rate.
    shown: u64,
    rate: f64,
    version: u8,
}

/// The messages seen, by (sysid, compid, msgid).
struct Table {
    rows: BTreeMap<(u8, u8, u32), Row>,
    /// Each autopilot's mode by name and whether it is armed, from its latest HEARTBEAT.
    states: BTreeMap<(u8, u8), (String, bool)>,
    drawn: Instant,
    terminal: bool,
}

impl Table {
    fn new() -> Self {
        Self {
            rows: BTreeMap::new(),
            states: BTreeMap::new(),
            drawn: Instant::now(),
            terminal: io::stdout().is_terminal(),
        }
    }

    fn add(&mut self, frame: &Frame<&[u8]>) {
        let row = self
            .rows
            .entry((frame.sysid(), frame.compid(), frame.msg_id()))
            .or_default();
        row.count += 1;
        row.version = frame.version().number();
        if frame.msg_id() == Heartbeat::ID {
            let hb = Heartbeat::decode(frame.payload());
            if hb.autopilot != MavAutopilot::INVALID {
                let mode = Flavour::of(hb.autopilot, hb.r#type)
                    .and_then(|f| mavstack::modes::name_of(f, hb.custom_mode))
                    .map_or_else(|| format!("custom mode {}", hb.custom_mode), str::to_owned);
                let armed = hb.base_mode.contains(MavModeFlag::SAFETY_ARMED);
                self.states
                    .insert((frame.sysid(), frame.compid()), (mode, armed));
            }
        }
    }

    fn draw(&mut self, dialect: &Dialect, out: &mut impl io::Write) -> io::Result<()> {
        let elapsed = self.drawn.elapsed().as_secs_f64().max(1e-3);
        self.drawn = Instant::now();
        let mut text = String::new();
        if self.terminal {
            text.push_str("\x1b[H\x1b[2J");
        }
        for (&(sysid, compid), (mode, armed)) in &self.states {
            text.push_str(&format!(
                "{sysid:>5} {compid:>6}  mode {mode}, {}\n",
                if *armed { "armed" } else { "disarmed" }
            ));
        }
        text.push_str(
            "sysid compid  msgid name                              v     count    rate/s\n",
        );
        for (&(sysid, compid, msgid), row) in &mut self.rows {
            row.rate = (row.count - row.shown) as f64 / elapsed;
            row.shown = row.count;
            let name = dialect.message(msgid).map_or("?", |m| m.name.as_str());
            text.push_str(&format!(
                "{sysid:>5} {compid:>6} {msgid:>6} {name:<33} {} {:>9} {:>9.1}\n",
                row.version, row.count, row.rate
            ));
        }
        if !self.terminal {
            text.push('\n');
        }
        out.write_all(text.as_bytes())?;
        out.flush()
    }
}

/// What `listen` prints, and how much it has printed.
pub(crate) struct Printer<'a> {
    args: &'a ListenArgs,
    dialect: &'a Dialect,
    key: Option<mavstack_core::signing::SecretKey>,
    filter: Vec<u32>,
    sink: io::BufWriter<io::StdoutLock<'static>>,
    counts: Counts,
    line: String,
    table: Option<Table>,
    printed: u64,
}

impl<'a> Printer<'a> {
    pub(crate) fn new(
        args: &'a ListenArgs,
        dialect: &'a Dialect,
        key: Option<mavstack_core::signing::SecretKey>,
    ) -> Result<Self, Failure> {
        let filter = args
            .filter
            .iter()
            .filter(|n| !n.is_empty())
            .map(|name| message_id(dialect, name, "--filter"))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            args,
            dialect,
            key,
            filter,
            sink: io::BufWriter::with_capacity(1 << 16, io::stdout().lock()),
            counts: Counts::default(),
            line: String::with_capacity(4096),
            table: args.table.then(Table::new),
            printed: 0,
        })
    }

    /// Prints (or counts into the table) one frame; whether `--count` is reached.
    pub(crate) fn frame(
        &mut self,
        frame: &Frame<&[u8]>,
        known: bool,
        ts: Option<u64>,
    ) -> Result<bool, Failure> {
        if self.args.sysid.is_some_and(|s| s != frame.sysid())
            || (!self.filter.is_empty() && !self.filter.contains(&frame.msg_id()))
        {
            return Ok(false);
        }
        if let Some(t) = self.table.as_mut() {
            t.add(frame);
        } else {
            self.line.clear();
            frame_line(
                &mut self.line,
                frame,
                self.dialect.message(frame.msg_id()).filter(|_| known),
                ts,
                self.key.as_ref(),
                &mut self.counts,
            );
            self.sink
                .write_all(self.line.as_bytes())
                .context("writing output")?;
        }
        self.printed += 1;
        Ok(self.args.count.is_some_and(|c| self.printed >= c))
    }

    /// Writes out what is buffered (JSON lines), or redraws the table on `tick`.
    pub(crate) fn flush(&mut self, tick: bool) -> Result<(), Failure> {
        match self.table.as_mut() {
            Some(t) if tick => t
                .draw(self.dialect, &mut self.sink)
                .context("writing output")?,
            Some(_) => {}
            None => self.sink.flush().context("writing output")?,
        }
        Ok(())
    }

    /// The last table and everything buffered.
    pub(crate) fn finish(&mut self) -> Result<(), Failure> {
        if let Some(t) = self.table.as_mut() {
            t.draw(self.dialect, &mut self.sink)
                .context("writing output")?;
        }
        self.sink.flush().context("writing output")?;
        Ok(())
    }
}

/// The id of message `name` in `dialect`, or a bad-input failure naming option `what`.
fn message_id(dialect: &Dialect, name: &str, what: &str) -> Result<u32, Failure> {
    dialect
        .message_by_name(&name.to_ascii_uppercase())
        .map(|m| m.id)
        .ok_or_else(|| {
            Failure::Input(anyhow!(
                "{what}: no message {name} in dialect {}",
                dialect.name
            ))
        })
}

/// `--rate`'s `NAME:HZ` items as (message id, Hz).
fn rates_of(args: &ListenArgs, dialect: &Dialect) -> Result<Vec<(u32, f32)>, Failure> {
    args.rate
        .iter()
        .filter(|r| !r.is_empty())
        .map(|r| {
            let bad = || {
                Failure::Input(anyhow!(
                    "--rate: {r:?} is not NAME:HZ (HZ from 0.01 to 1000)"
                ))
            };
            let (name, hz) = r.split_once(':').ok_or_else(bad)?;
            let hz: f32 = hz.parse().map_err(|_| bad())?;
            if !(0.01..=1000.0).contains(&hz) {
                return Err(bad());
            }
            Ok((message_id(dialect, name, "--rate")?, hz))
        })
        .collect()
}

/// The signing key to check signatures with: `--key`, else the link's `key` option.
fn check_key(
    args_key: Option<&str>,
    spec: &LinkSpec,
) -> Result<Option<mavstack_core::signing::SecretKey>, Failure> {
    if args_key.is_some() {
        return parse_key(args_key);
    }
    Ok(spec
        .config
        .signing
        .as_ref()
        .map(|s| s.primary_key().clone()))
}

pub(crate) fn listen(args: &ListenArgs) -> Result<(), Failure> {
    let dialect = load_dialect(&args.dialect.dialect)?;
    let rates = rates_of(args, &dialect)?;
    let until = deadline(args.duration)?;
    let spec = parse_link(&args.conn, &dialect)?;
    let key = check_key(args.key.as_deref(), &spec)?;
    if !rates.is_empty() {
        return crate::listen_rates::listen(args, &dialect, spec, key, &rates, until);
    }
    let with_ts = matches!(
        spec.conn,
        ConnSpec::File {
            format: FileFormat::Tlog,
            ..
        }
    );
    runtime()?.block_on(async {
        let mut conn = open(&spec.conn, &dialect, args.keep_unknown, FileMode::Read).await?;
        let mut printer = Printer::new(args, &dialect, key)?;
        let mut batch = Vec::with_capacity(1024);
        let mut redraw = tokio::time::interval(Duration::from_secs(1));
        let stop = interrupted();
        tokio::pin!(stop);
        'run: loop {
            match next_batch(&mut conn, &mut batch, stop.as_mut(), until, &mut redraw).await {
                Wake::Batch => {}
                Wake::Done => break 'run,
                Wake::Tick => {
                    printer.flush(true)?;
                    continue;
                }
            }
            for event in batch.drain(..) {
                let (received, known) = match event {
                    FrameEvent::Frame(f) => (f, true),
                    FrameEvent::Unknown(f) => (f, false),
                    _ => continue,
                };
                let ts = with_ts.then(|| received.time.as_micros());
                if printer.frame(&received.frame.frame(), known, ts)? {
                    break 'run;
                }
            }
            printer.flush(false)?;
        }
        printer.finish()?;
        let stats = conn.stats();
        if args.stats {
            let counts = counts_of(&stats.protocol, printer.counts.bad_signature);
            crate::json_line::to_stderr(&counts.json());
        }
        conn.close().await.map_err(fail)?;
        Ok(())
    })
}

pub(crate) fn record(args: &RecordArgs) -> Result<(), Failure> {
    let dialect = load_dialect(&args.dialect.dialect)?;
    let link = parse_link(&args.conn, &dialect)?;
    let spec = &link.conn;
    let until = deadline(args.duration)?;
    let file = std::fs::File::create(&args.file)
        .with_context(|| format!("cannot create {}", args.file.display()))
        .map_err(Failure::Other)?;
    let mut writer = tlog::Writer::new(io::BufWriter::with_capacity(1 << 16, file));
    runtime()?.block_on(async {
        // Unknown ids are recorded too: a recorder keeps everything that frames correctly.
        let mut conn = open(spec, &dialect, true, FileMode::Read).await?;
        eprintln!("recording {} to {}", link.redacted(), args.file.display());
        let mut batch = Vec::with_capacity(1024);
        let mut flush = tokio::time::interval(Duration::from_millis(500));
        let mut status = crate::progress::Progress::counter("recording");
        let stop = interrupted();
        tokio::pin!(stop);
        let mut recorded = 0u64;
        let write_failed = |e: io::Error| {
            Failure::Other(
                anyhow::Error::new(e).context(format!("writing {}", args.file.display())),
            )
        };
        'run: loop {
            match next_batch(&mut conn, &mut batch, stop.as_mut(), until, &mut flush).await {
                Wake::Batch => {}
                Wake::Done => break 'run,
                Wake::Tick => {
                    writer.flush_if_due().map_err(write_failed)?;
                    continue;
                }
            }
            for event in batch.drain(..) {
                let (FrameEvent::Frame(f) | FrameEvent::Unknown(f)) = event else {
                    continue;
                };
                writer
                    .write_record(f.time.as_micros(), f.frame.as_bytes())
                    .map_err(write_failed)?;
                recorded += 1;
                if args.count.is_some_and(|c| recorded >= c) {
                    break 'run;
                }
            }
            writer.flush_if_due().map_err(write_failed)?;
            status.set(recorded);
        }
        writer.flush().map_err(write_failed)?;
        status.finish();
        eprintln!("recorded {recorded} frames to {}", args.file.display());
        conn.close().await.map_err(fail)?;
        Ok(())
    })
}

/// The frames of the file to replay, with their timestamps (none for a raw capture).
fn replay_frames(
    args: &ReplayArgs,
    dialect: &Arc<Dialect>,
) -> Result<Vec<(Option<u64>, FrameBuf)>, Failure> {
    let data = std::fs::read(&args.file)
        .with_context(|| format!("cannot read {}", args.file.display()))
        .map_err(Failure::Input)?;
    let is_tlog = !args.raw && FileFormat::from_path(&args.file) == FileFormat::Tlog;
    let mut frames = Vec::new();
    if is_tlog {
        let mut reader = tlog::Reader::new(&data[..]).with_crc_extra(dialect.message_table());
        while let Some((ts, bytes)) = reader.read_record().context("reading the tlog")? {
            if let Ok(frame) = FrameBuf::new(bytes) {
                frames.push((Some(ts), frame));
            }
        }
    } else {
        for item in SliceParser::new(&data, dialect.message_table()) {
            let (Item::Frame(f) | Item::Unknown(f)) = item;
            if let Ok(frame) = FrameBuf::new(f.as_bytes()) {
                frames.push((None, frame));
            }
        }
    }
    Ok(frames)
}

pub(crate) fn replay(args: &ReplayArgs) -> Result<(), Failure> {
    if !(args.speed >= 0.0 && args.speed.is_finite()) {
        return Err(Failure::Input(anyhow!(
            "--speed: {} is not a speed (0 or more)",
            args.speed
        )));
    }
    let dialect = load_dialect(&args.dialect.dialect)?;
    let link = parse_link(&args.conn, &dialect)?;
    let spec = &link.conn;
    let frames = replay_frames(args, &dialect)?;
    if frames.is_empty() {
        return Err(Failure::Input(anyhow!(
            "{}: no frames to replay",
            args.file.display()
        )));
    }
    runtime()?.block_on(async {
        let conn = open(spec, &dialect, false, FileMode::Write).await?;
        let mut status = crate::progress::Progress::frames("replaying", frames.len() as u64);
        let stop = interrupted();
        tokio::pin!(stop);
        // A server (udpin, tcpin) has no one to send to until a peer shows up.
        let server = matches!(spec, ConnSpec::UdpIn { .. } | ConnSpec::TcpIn { .. });
        if server && conn.peers().is_empty() {
            eprintln!("waiting for a peer on {}", link.redacted());
            while conn.peers().is_empty() {
                tokio::select! {
                    () = tokio::time::sleep(Duration::from_millis(20)) => {}
                    () = &mut stop => return Ok(()),
                }
            }
        }
        let mut sent = 0u64;
        'run: loop {
            let started = Instant::now();
            let first = frames.iter().find_map(|(ts, _)| *ts);
            for (i, (ts, frame)) in frames.iter().enumerate() {
                if let (Some(ts), Some(first)) = (ts, first)
                    && args.speed > 0.0
                {
                    // A timestamp so far ahead that it is out of the clock's range is sent
                    // without waiting (the log's clock jumped; the file is outside input).
                    let offset = ts.saturating_sub(first) as f64 / 1e6 / args.speed;
                    let at = Duration::try_from_secs_f64(offset)
                        .ok()
                        .and_then(|d| started.checked_add(d))
                        .unwrap_or(started);
                    tokio::select! {
                        () = tokio::time::sleep_until(at) => {}
                        () = &mut stop => break 'run,
                    }
                }
                tokio::select! {
                    r = conn.send(FrameCommand::to_all(*frame)) => {
                        r.map_err(fail)?;
                    }
                    () = &mut stop => break 'run,
                }
                sent += 1;
                status.set(i as u64 + 1);
            }
            if !args.repeat {
                break;
            }
        }
        status.finish();
        conn.close().await.map_err(fail)?;
        eprintln!("replayed {sent} frames");
        Ok(())
    })
}
