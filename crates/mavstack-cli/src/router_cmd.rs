//! `mavstack router`: forwards between many links, each with its own MAVLink version and
//! signing, converting where they differ (`docs/contracts/router.md`). A thin shell over
//! [`mavstack::Node`]: argument parsing, the mavlink-router configuration file, `--stats`
//! JSON lines (the object of `mavstack::status`).

use core::time::Duration;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context as _, anyhow};
use clap::Args;
use mavstack::router::{MessageTable, RouterConfig};
use mavstack::{InputModeration, LinkSpec, Node, NodeReport, router_conf};
use mavstack_bridge::BridgeStats;

use crate::Failure;
use crate::link_cmd::{interrupted, seconds};

/// `mavstack router` arguments.
#[derive(Debug, Args)]
pub(crate) struct RouterArgs {
    /// Links: connection strings with options, e.g. 'udpin:0.0.0.0:14550?version=1&name=legacy'.
    links: Vec<String>,
    /// A mavlink-router configuration file (main.conf), read as it is; its links come
    /// before the ones on the command line. As with mavlink-router, a TCP server listens on
    /// 5760 unless the file's TcpServerPort says otherwise (0: none) or --tcp-server is given.
    #[arg(long, value_name = "FILE")]
    conf: Option<PathBuf>,
    /// A TCP server port for dynamic clients (each client a link of its own).
    #[arg(long, value_name = "PORT")]
    tcp_server: Option<u16>,
    /// Write a tlog of all traffic into this directory.
    #[arg(long, value_name = "DIR")]
    log: Option<PathBuf>,
    /// Drop a frame whose exact bytes passed within this many milliseconds (off by default;
    /// 0 to 3600000, 0 = off).
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(0..=3_600_000))]
    dedup: Option<u64>,
    /// Forget a route after this many seconds of silence (from 0.01 to 86400).
    #[arg(long, value_name = "S", default_value_t = 30.0, value_parser = crate::link_cmd::period_arg)]
    route_ttl: f64,
    /// Print one JSON object of statistics every S seconds on stdout (from 0.01 to 86400).
    #[arg(long, value_name = "S", value_parser = crate::link_cmd::period_arg)]
    stats: Option<f64>,
    /// Dialect for CRC_EXTRA, lengths, target offsets and the message names of filters and
    /// rates: a built-in name or an XML file (includes resolved relative to it).
    #[arg(long, default_value = "ardupilotmega")]
    dialect: String,
    /// Announce the router as a component of its own: a HEARTBEAT (an onboard computer's,
    /// MAV_TYPE_ONBOARD_CONTROLLER) once a second on every link, each in the link's version
    /// and signing.
    #[arg(long)]
    heartbeat: bool,
    /// The router's own system id (its HEARTBEAT's; frames addressed to it are not
    /// forwarded to a link).
    #[arg(long, default_value_t = 1)]
    sysid: u8,
    /// The router's own component id.
    #[arg(long, default_value_t = 191)]
    compid: u8,
    /// How to read under a steady stream (above 5,000 datagrams a second): `sleep` (the
    /// router's thread sleeps 1 ms after each small burst: the least CPU), `timer` (sleeps
    /// 1 ms on the wake-up that starts a burst), `off` (every datagram as it comes: the
    /// least latency).
    #[arg(long, value_enum, default_value = "sleep")]
    input_moderation: ModerationArg,
    #[command(flatten)]
    http: HttpArgs,
}

/// `--http ADDR`, `--http-token` and `--http-public`, on `router` and `vehicle`.
#[derive(Debug, Args)]
pub(crate) struct HttpArgs {
    /// Serve a live status page and mavlink2rest 1.0.2's REST and WebSocket API on ADDR
    /// (`127.0.0.1:8080`): `/` the page, `/api/status` the `--stats` object as JSON,
    /// `/api/events` it once a second (server-sent events), `/mavlink`, `/ws/mavlink`,
    /// `/helper/mavlink`, `/info`, `/docs.json`, the same under `/v1/`.
    #[arg(long, value_name = "ADDR")]
    http: Option<String>,
    /// Require TOKEN on every `--http` request and WebSocket (`Authorization: Bearer
    /// TOKEN`, or `?token=TOKEN`); with it, ADDR may be any address.
    #[arg(long, value_name = "TOKEN", requires = "http")]
    http_token: Option<String>,
    /// Allow a `--http` address other than loopback without `--http-token` (no
    /// authentication).
    #[arg(long, requires = "http")]
    http_public: bool,
}

impl HttpArgs {
    /// The status page's address, if one was asked for: a usage error for an address that
    /// does not parse, or is not loopback without `--http-public`.
    pub(crate) fn addr(&self) -> Result<Option<core::net::SocketAddr>, Failure> {
        let Some(text) = &self.http else {
            return Ok(None);
        };
        let addr: core::net::SocketAddr = text.parse().map_err(|_| {
            Failure::Input(anyhow!(
                "--http {text}: expected an address and port such as 127.0.0.1:8080"
            ))
        })?;
        if !addr.ip().is_loopback() && !self.http_public && self.http_token.is_none() {
            return Err(Failure::Input(anyhow!(
                "--http {text}: not a loopback address; give --http-token, or add \
                 --http-public to serve it there without authentication"
            )));
        }
        if self.http_token.as_ref().is_some_and(String::is_empty) {
            return Err(Failure::Input(anyhow!("--http-token: empty")));
        }
        Ok(Some(addr))
    }

    /// `builder` serving `--http` (if given) with the API's messages in `dialect`.
    pub(crate) fn apply(
        &self,
        mut builder: mavstack::NodeBuilder,
        dialect: &str,
    ) -> Result<mavstack::NodeBuilder, Failure> {
        let Some(addr) = self.addr()? else {
            return Ok(builder);
        };
        let mapping = if dialect.eq_ignore_ascii_case("ardupilotmega") {
            mavstack::web::default_mapping()
        } else {
            let dialect = crate::dialect_cmd::load(dialect)?;
            Arc::new(mavstack::web::json::JsonMapping::new(dialect))
        };
        let mut options = mavstack::web::WebOptions::default().mapping(mapping);
        if let Some(token) = &self.http_token {
            options = options.token(token.clone());
        }
        builder = builder.http(addr).web(options);
        Ok(builder)
    }
}

/// `--input-moderation`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ModerationArg {
    /// The thread sleeps between bursts.
    Sleep,
    /// A pause when a burst starts.
    Timer,
    /// Every datagram as it comes.
    Off,
}

/// The router's message table: a dialect compiled into the binary by its name, any other
/// built-in name or an XML file through the run-time model (`docs/contracts/json-lines.md`,
/// "Dialect names").
fn dialect(name: &str) -> Result<MessageTable, Failure> {
    match crate::dialect_cmd::compiled_table(name) {
        Some(table) => Ok(table),
        None => crate::dialect_cmd::load(name).map(|d| d.message_table()),
    }
}

pub(crate) fn router(args: &RouterArgs) -> Result<(), Failure> {
    let mut specs = Vec::new();
    let mut config = RouterConfig::default();
    config.system_id = args.sysid;
    config.component_id = args.compid;
    let heartbeat = args.heartbeat;
    let moderation = match args.input_moderation {
        ModerationArg::Sleep => InputModeration::Sleep,
        ModerationArg::Timer => InputModeration::Timer,
        ModerationArg::Off => InputModeration::Off,
    };
    config.route_ttl = seconds(args.route_ttl, "--route-ttl")?;
    config.dedup = args
        .dedup
        .map(Duration::from_millis)
        .filter(|d| !d.is_zero());
    let mut tcp_server = args.tcp_server;
    let mut log = args.log.clone();
    let mut dialect_name = args.dialect.clone();
    let mut conf_links = Vec::new();
    let mut report_stats = false;
    if let Some(path) = &args.conf {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))
            .map_err(Failure::Input)?;
        let conf = router_conf::parse(&text)
            .map_err(|e| Failure::Input(anyhow!("{}:{}: {}", path.display(), e.line, e.message)))?;
        for (line, key) in &conf.general.ignored {
            eprintln!(
                "warning: {}:{line}: {key} has no effect in mavstack",
                path.display()
            );
        }
        if tcp_server.is_none() {
            // As mavlink-router: a TCP server on 5760 unless the file says otherwise (0: none).
            tcp_server = Some(conf.general.tcp_server_port.unwrap_or(5760)).filter(|&p| p != 0);
        }
        if config.dedup.is_none() {
            config.dedup = conf
                .general
                .dedup_ms
                .map(Duration::from_millis)
                .filter(|d| !d.is_zero());
        }
        if log.is_none() {
            log.clone_from(&conf.general.log_dir);
        }
        if let Some(d) = conf.general.dialect.filter(|d| d != "auto") {
            dialect_name = d;
        }
        report_stats = conf.general.report_stats;
        conf_links = conf.links;
    }
    // Filters and rates given by message name resolve in the router's own dialect.
    let dialect = dialect(&dialect_name)?;
    if let Some(path) = &args.conf {
        for link in conf_links {
            let spec = LinkSpec::parse_in(&link.link, &dialect)
                .with_context(|| format!("{}:{}", path.display(), link.line))
                .map_err(Failure::Input)?;
            specs.push(spec);
        }
    }
    let mut bridges = Vec::new();
    for text in &args.links {
        if mavstack_bridge::is_bridge_link(text) {
            bridges.push(
                mavstack_bridge::BridgeSpec::parse(text).map_err(|e| Failure::Input(e.into()))?,
            );
            continue;
        }
        specs.push(LinkSpec::parse_in(text, &dialect).map_err(|e| Failure::Input(e.into()))?);
    }
    if let Some(port) = tcp_server {
        let text = format!("tcpin:0.0.0.0:{port}?name=tcp-server");
        specs.push(LinkSpec::parse_in(&text, &dialect).map_err(|e| Failure::Input(e.into()))?);
    }
    if specs.is_empty() && bridges.is_empty() {
        return Err(Failure::Input(anyhow!(
            "no links: give connection strings, --conf FILE or --tcp-server PORT"
        )));
    }
    // The file's ReportStats prints the statistics as --stats does, once a second as
    // mavlink-router does, unless --stats gives the period.
    let stats_every = args
        .stats
        .map(|s| seconds(s, "--stats"))
        .transpose()?
        .or_else(|| report_stats.then_some(Duration::from_secs(1)));
    // A bad --http is a usage error before anything opens.
    args.http.addr()?;
    // The node runs on a thread of its own, waiting on its UDP sockets directly (no
    // scheduler between a datagram's wake-up and the forwarded frames); one runtime thread
    // beside it runs the TCP and serial links' tasks, signals and statistics.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async move {
        let mut builder = Node::builder()
            .router(config)
            .dialect(dialect)
            .input_moderation(moderation)
            .own_thread(true);
        if heartbeat {
            let hb = mavstack::dialects::common::Heartbeat {
                r#type: mavstack::dialects::common::MavType::ONBOARD_CONTROLLER,
                autopilot: mavstack::dialects::common::MavAutopilot::INVALID,
                system_status: mavstack::dialects::common::MavState::ACTIVE,
                mavlink_version: 3,
                ..Default::default()
            };
            builder = builder.heartbeat(&hb, Duration::from_secs(1));
        }
        for spec in specs {
            builder = builder.link(spec);
        }
        let mut handles = Vec::new();
        let mut bridge_stats = Vec::new();
        for spec in &bridges {
            let bridge =
                mavstack_bridge::open(spec, dialect).map_err(|e| Failure::Input(e.into()))?;
            builder = builder.opened_link(bridge.config, bridge.link);
            bridge_stats.push((spec.name.clone(), Arc::clone(&bridge.handle.stats)));
            handles.push(bridge.handle);
        }
        if let Some(dir) = &log {
            builder = builder.log_dir(dir);
        }
        builder = args.http.apply(builder, &dialect_name)?;
        let node = builder.start().await.map_err(crate::fail)?;
        if let Some(addr) = node.http_addr() {
            eprintln!("mavstack router: status page on http://{addr}/");
        }
        // The signal handlers first: a SIGTERM right after "ready" is a clean stop.
        let stop = interrupted();
        tokio::pin!(stop);
        eprintln!("mavstack router: ready");
        // Until a signal, or until the node stops on its own (a link failed, the log could
        // not be written): then the daemon exits 1 with the reason, for its supervisor to
        // see and restart it (`docs/operations.md`).
        let mut tick = stats_every.map(tokio::time::interval);
        if let Some(tick) = &mut tick {
            tick.tick().await;
        }
        loop {
            tokio::select! {
                () = &mut stop => break,
                () = node.closed() => break,
                () = next_tick(&mut tick) => {
                    if let Some(report) = node.report().await {
                        print_stats(&report, &bridge_stats);
                    }
                }
            }
        }
        let result = node.shutdown().await;
        for handle in handles {
            handle.finish().await;
        }
        let report = result.context("the router stopped")?;
        if stats_every.is_some() {
            print_stats(&report, &bridge_stats);
        }
        Ok(())
    })
}

/// The next tick of `--stats`, never without it.
async fn next_tick(tick: &mut Option<tokio::time::Interval>) {
    match tick {
        Some(tick) => {
            tick.tick().await;
        }
        None => core::future::pending().await,
    }
}

/// One `--stats` line (`docs/contracts/router.md`).
fn print_stats(report: &NodeReport, bridges: &[(String, Arc<BridgeStats>)]) {
    let mut line = mavstack::status::status_json(report);
    if !bridges.is_empty()
        && let Some(obj) = line.as_object_mut()
    {
        let list = bridges
            .iter()
            .map(|(name, stats)| {
                let c = stats.snapshot();
                serde_json::json!({
                    "name": name, "published": c.published, "received": c.received,
                    "replaced": c.replaced, "replaced_by_key": c.replaced_by_key,
                    "dropped": {"control": c.dropped_control, "telemetry": c.dropped_telemetry},
                    "replies": c.replies, "connections": c.connections,
                    "bad_crc": c.bad_crc, "vehicles_refused": c.vehicles_refused,
                })
            })
            .collect();
        obj.insert("bridges".to_owned(), serde_json::Value::Array(list));
    }
    write_line(&line);
}

/// Writes a stats line to stdout whole (a reader of the file it goes to never finds half a
/// line). The first line that cannot be written is said; the router goes on routing.
fn write_line(line: &serde_json::Value) {
    use core::sync::atomic::{AtomicBool, Ordering};
    static WARNED: AtomicBool = AtomicBool::new(false);
    if let Err(e) = crate::json_line::to_stdout(line)
        && !WARNED.swap(true, Ordering::Relaxed)
    {
        tracing::warn!(
            "router: a stats line could not be written to stdout ({e}); later failures are not said"
        );
    }
}
