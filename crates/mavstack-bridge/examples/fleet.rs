//! The fleet test's two processes (`tests-interop/fleet_test.py` runs them with mosquitto):
//!
//! ```text
//! fleet vehicles --port P --count N --start-us T0 --telemetry-s S --run-s R
//! fleet watch    --port P --count N --start-us T0 --run-s R --commands-at A,B --slow-from C
//! ```
//!
//! `vehicles`: N simulated vehicles in this process, each a `mavstack::Node` (the router
//! core) with one MQTT bridge link (`fleet=load`, `vid=vNNNN`, sysid `1 + i % 100`, so many
//! share one): HEARTBEAT 1 Hz, ATTITUDE 10 Hz, GLOBAL_POSITION_INT 5 Hz, SYS_STATUS 1 Hz for
//! the first S seconds, each carrying its send time (µs since T0) in a u32 field; every
//! vehicle answers COMMAND_LONG with COMMAND_ACK ACCEPTED. Prints one JSON object: frames
//! sent per message and per second, CPU seconds and peak RSS.
//!
//! `watch`: one wildcard subscriber (`mav/load/+/+/+/+`), ten per-vehicle ones, a slow one
//! (10 ms per message from C s on), and ten command clients that send one MQTT 5 request per
//! vehicle between them at each time of `--commands-at`. Prints one JSON object: frames received per
//! message and per send second, latency percentiles per lane (of frames sent before
//! `--steady-until`), command reply latencies.

use core::sync::atomic::{AtomicU64, Ordering};
use core::time::Duration;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{SystemTime, UNIX_EPOCH};

use mavstack::core::{Message as _, MessageSet as _};
use mavstack::dialects::common::{
    Attitude, CommandAck, CommandLong, GlobalPositionInt, Heartbeat, MavAutopilot, MavCmd,
    MavMessage, MavResult, MavState, MavType, SysStatus,
};
use mavstack::node::Node;
use mavstack::router::MessageTable;
use mavstack_bridge::BridgeSpec;
use rumqttc::v5::mqttbytes::QoS;
use rumqttc::v5::mqttbytes::v5::{Packet, PublishProperties};
use rumqttc::v5::{AsyncClient, Event, MqttOptions};

type Failure = Box<dyn core::error::Error + Send + Sync>;

fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX))
}

struct Args {
    role: String,
    port: u16,
    count: usize,
    start_us: u64,
    telemetry_s: f64,
    run_s: f64,
    commands_at: Vec<f64>,
    slow_from: f64,
    steady_until: f64,
}

fn args() -> Result<Args, Failure> {
    let mut it = std::env::args().skip(1);
    let role = it
        .next()
        .ok_or("usage: fleet vehicles|watch --port P ...")?;
    let mut a = Args {
        role,
        port: 1883,
        count: 1000,
        start_us: now_us(),
        telemetry_s: 40.0,
        run_s: 55.0,
        commands_at: vec![],
        slow_from: f64::INFINITY,
        steady_until: f64::INFINITY,
    };
    while let Some(flag) = it.next() {
        let v = it.next().ok_or_else(|| format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--port" => a.port = v.parse()?,
            "--count" => a.count = v.parse()?,
            "--start-us" => a.start_us = v.parse()?,
            "--telemetry-s" => a.telemetry_s = v.parse()?,
            "--run-s" => a.run_s = v.parse()?,
            "--commands-at" => {
                a.commands_at = v.split(',').map(str::parse).collect::<Result<_, _>>()?;
            }
            "--slow-from" => a.slow_from = v.parse()?,
            "--steady-until" => a.steady_until = v.parse()?,
            _ => return Err(format!("unknown option {flag}").into()),
        }
    }
    Ok(a)
}

fn sysid_of(i: usize) -> u8 {
    u8::try_from(1 + i % 100).unwrap_or(1)
}

/// Sleeps until `t` seconds after the start.
async fn until(start_us: u64, t: f64) {
    let at = start_us + (t * 1e6) as u64;
    let now = now_us();
    if at > now {
        tokio::time::sleep(Duration::from_micros(at - now)).await;
    }
}

fn dialect() -> MessageTable {
    MessageTable::of::<MavMessage>()
}

/// Frames sent, per message name and per send second.
#[derive(Default)]
struct Sent {
    by_msg: Mutex<HashMap<&'static str, u64>>,
    by_second: Mutex<HashMap<(&'static str, u64), u64>>,
}

impl Sent {
    fn count(&self, name: &'static str, t_us: u32) {
        let s = u64::from(t_us) / 1_000_000;
        *self
            .by_msg
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .entry(name)
            .or_default() += 1;
        *self
            .by_second
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .entry((name, s))
            .or_default() += 1;
    }
}

async fn vehicles(a: Args) -> Result<(), Failure> {
    let sent = Arc::new(Sent::default());
    let acks = Arc::new(AtomicU64::new(0));
    let mut nodes = Vec::new();
    let mut handles = Vec::new();
    for i in 0..a.count {
        let spec = BridgeSpec::parse(&format!(
            "mqtt://127.0.0.1:{}?fleet=load&vid=v{i:04}",
            a.port
        ))?;
        let bridge = mavstack_bridge::open(&spec, dialect())?;
        let sysid = sysid_of(i);
        let node = Node::builder()
            .identity(sysid, 1)
            .opened_link(bridge.config, bridge.link)
            .start()
            .await?;
        let handle = node.handle();
        let mut incoming = handle.subscribe().await;
        // The command responder.
        let responder = handle.clone();
        let acks2 = Arc::clone(&acks);
        tokio::spawn(async move {
            while let Some(m) = incoming.recv().await {
                let view = m.frame.frame.view();
                if view.msg_id() != CommandLong::ID {
                    continue;
                }
                let Ok(MavMessage::CommandLong(c)) =
                    MavMessage::decode(view.msg_id(), view.payload())
                else {
                    continue;
                };
                let ack = MavMessage::CommandAck(CommandAck {
                    command: c.command,
                    result: MavResult::ACCEPTED,
                    target_system: view.sysid(),
                    target_component: view.compid(),
                    ..Default::default()
                });
                responder
                    .send_answer((view.sysid(), view.compid()), &ack)
                    .await;
                acks2.fetch_add(1, Ordering::Relaxed);
            }
        });
        // The telemetry: a tick every 100 ms, phases spread over the tick.
        let sent2 = Arc::clone(&sent);
        let (start_us, telemetry_s) = (a.start_us, a.telemetry_s);
        tokio::spawn(async move {
            let offset = Duration::from_micros((i as u64 * 100_000) / 1000 % 100_000);
            tokio::time::sleep(offset).await;
            let mut tick = tokio::time::interval(Duration::from_millis(100));
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
            let mut n: u64 = 0;
            loop {
                tick.tick().await;
                let t = now_us().saturating_sub(start_us);
                if t as f64 / 1e6 >= telemetry_s {
                    return;
                }
                let t32 = u32::try_from(t).unwrap_or(u32::MAX);
                handle
                    .send(&Attitude {
                        time_boot_ms: t32,
                        roll: 0.1,
                        ..Default::default()
                    })
                    .await;
                sent2.count("ATTITUDE", t32);
                if n.is_multiple_of(2) {
                    handle
                        .send(&GlobalPositionInt {
                            time_boot_ms: t32,
                            lat: -353_632_610,
                            lon: 1_491_652_380,
                            ..Default::default()
                        })
                        .await;
                    sent2.count("GLOBAL_POSITION_INT", t32);
                }
                if n.is_multiple_of(10) {
                    handle
                        .send(&Heartbeat {
                            r#type: MavType::QUADROTOR,
                            autopilot: MavAutopilot::ARDUPILOTMEGA,
                            system_status: MavState::ACTIVE,
                            custom_mode: t32,
                            mavlink_version: 3,
                            ..Default::default()
                        })
                        .await;
                    sent2.count("HEARTBEAT", t32);
                    handle
                        .send(&SysStatus {
                            onboard_control_sensors_present:
                                mavstack::dialects::common::MavSysStatusSensor(t32),
                            voltage_battery: 12_000,
                            ..Default::default()
                        })
                        .await;
                    sent2.count("SYS_STATUS", t32);
                }
                n += 1;
            }
        });
        nodes.push(node);
        handles.push(bridge.handle);
    }
    until(a.start_us, a.run_s).await;
    let mut stats = (0u64, 0u64, 0u64, 0u64);
    for h in &handles {
        let s = &h.stats;
        stats.0 += s.published.load(Ordering::Relaxed);
        stats.1 += s.replaced.load(Ordering::Relaxed);
        stats.2 += s.dropped_telemetry.load(Ordering::Relaxed);
        stats.3 += s.connections.load(Ordering::Relaxed);
    }
    let by_msg = sent
        .by_msg
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone();
    let by_second: Vec<serde_json::Value> = sent
        .by_second
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .iter()
        .map(|((m, s), n)| serde_json::json!([m, s, n]))
        .collect();
    let (cpu_s, rss_kb) = usage();
    println!(
        "{}",
        serde_json::json!({
            "role": "vehicles", "count": a.count, "sent": by_msg, "sent_by_second": by_second,
            "acks_sent": acks.load(Ordering::Relaxed), "published": stats.0,
            "replaced": stats.1, "dropped_telemetry": stats.2, "connections": stats.3,
            "cpu_s": cpu_s, "peak_rss_mb": rss_kb as f64 / 1024.0,
        })
    );
    // Exit without waiting for 1,000 clean disconnects.
    std::process::exit(0);
}

/// (CPU seconds, peak RSS in KiB) of this process.
fn usage() -> (f64, u64) {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map(|(_, r)| r.split_whitespace().collect())
        .unwrap_or_default();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // utime and stime are fields 14 and 15 (1-based), 11 and 12 after the ')'.
    let cpu = (ticks(11) + ticks(12)) / 100.0;
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let rss = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    (cpu, rss)
}

/// What a subscriber saw.
#[derive(Default)]
struct Seen {
    by_msg: HashMap<String, u64>,
    by_second: HashMap<(String, u64), u64>,
    /// Latencies in µs per lane ("telemetry", "control") of frames sent before
    /// `--steady-until` (the broker's outage and the backlog after it are apart).
    latency: HashMap<&'static str, Vec<u64>>,
    /// µs since start of every frame received (for the recovery time).
    arrivals: Vec<u64>,
}

fn embedded_time(name: &str, payload: &[u8]) -> Option<u32> {
    let u32_at = |o: usize| {
        payload
            .get(o..o + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    match name {
        // time_boot_ms first in ATTITUDE and GLOBAL_POSITION_INT, custom_mode first in
        // HEARTBEAT, onboard_control_sensors_present first in SYS_STATUS (wire order);
        // a truncated MAVLink 2 payload reads as zeros.
        "ATTITUDE" | "GLOBAL_POSITION_INT" | "HEARTBEAT" | "SYS_STATUS" => {
            Some(u32_at(0).unwrap_or(0))
        }
        _ => None,
    }
}

fn frame_parts(payload: &[u8]) -> Option<(u8, &[u8])> {
    let f = mavstack::core::wire::Frame::new_checked(payload).ok()?;
    let len = f.payload_len();
    let start = f.version().header_len();
    Some((f.sysid(), payload.get(start..start + len)?))
}

async fn subscriber(
    port: u16,
    id: String,
    filter: String,
    start_us: u64,
    slow_from: Option<f64>,
    steady_until: f64,
    seen: Arc<Mutex<Seen>>,
) {
    let mut opts = MqttOptions::new(id, "127.0.0.1", port);
    opts.set_keep_alive(Duration::from_secs(5));
    opts.set_outgoing_inflight_upper_limit(256);
    let mut network = rumqttc::NetworkOptions::new();
    network.set_tcp_nodelay(true);
    opts.set_network_options(network);
    let (client, mut events) = AsyncClient::new(opts, 1024);
    loop {
        match events.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                let _ = client.subscribe(filter.clone(), QoS::AtLeastOnce).await;
            }
            Ok(Event::Incoming(Packet::Publish(p))) => {
                let t = now_us().saturating_sub(start_us);
                let topic = String::from_utf8_lossy(&p.topic).into_owned();
                let name = topic.rsplit('/').next().unwrap_or_default().to_owned();
                if let Some((_, payload)) = frame_parts(&p.payload)
                    && let Some(sent) = embedded_time(&name, payload)
                {
                    let mut s = seen
                        .lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner);
                    *s.by_msg.entry(name.clone()).or_default() += 1;
                    *s.by_second
                        .entry((name.clone(), u64::from(sent) / 1_000_000))
                        .or_default() += 1;
                    let lane = if name == "HEARTBEAT" {
                        "control"
                    } else {
                        "telemetry"
                    };
                    if f64::from(sent) / 1e6 < steady_until {
                        s.latency
                            .entry(lane)
                            .or_default()
                            .push(t.saturating_sub(u64::from(sent)));
                    }
                    s.arrivals.push(t);
                }
                if slow_from.is_some_and(|from| t as f64 / 1e6 >= from) {
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
            }
            Ok(_) => {}
            Err(_) => tokio::time::sleep(Duration::from_millis(200)).await,
        }
    }
}

/// Command clients of `watch`.
const COMMAND_CLIENTS: usize = 10;

/// Command client `k`: its replies (on `replies/c{k}/#`) recorded by correlation data.
fn command_client(
    port: u16,
    k: usize,
    replies: Arc<Mutex<HashMap<Vec<u8>, u64>>>,
    start_us: u64,
) -> AsyncClient {
    let mut opts = MqttOptions::new(format!("watch-commands-{k}"), "127.0.0.1", port);
    opts.set_keep_alive(Duration::from_secs(5));
    opts.set_outgoing_inflight_upper_limit(1024);
    let mut network = rumqttc::NetworkOptions::new();
    network.set_tcp_nodelay(true);
    opts.set_network_options(network);
    let (client, mut events) = AsyncClient::new(opts, 4096);
    let resubscribe = client.clone();
    tokio::spawn(async move {
        loop {
            match events.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => {
                    // A clean session after each (re)connection: subscribe again.
                    let _ = resubscribe.try_subscribe(format!("replies/c{k}/#"), QoS::AtLeastOnce);
                }
                Ok(Event::Incoming(Packet::Publish(p))) => {
                    if let Some(c) = p.properties.and_then(|pr| pr.correlation_data) {
                        replies
                            .lock()
                            .unwrap_or_else(std::sync::PoisonError::into_inner)
                            .insert(c.to_vec(), now_us().saturating_sub(start_us));
                    }
                }
                Ok(_) => {}
                Err(_) => tokio::time::sleep(Duration::from_millis(200)).await,
            }
        }
    });
    client
}

fn percentiles(v: &mut [u64]) -> serde_json::Value {
    if v.is_empty() {
        return serde_json::Value::Null;
    }
    v.sort_unstable();
    let q = |p: f64| v[((v.len() - 1) as f64 * p) as usize];
    serde_json::json!({"n": v.len(), "p50_us": q(0.5), "p99_us": q(0.99), "max_us": q(1.0)})
}

async fn watch(a: Args) -> Result<(), Failure> {
    let wild = Arc::new(Mutex::new(Seen::default()));
    tokio::spawn(subscriber(
        a.port,
        "watch-wild".into(),
        "mav/load/+/+/+/+".into(),
        a.start_us,
        None,
        a.steady_until,
        Arc::clone(&wild),
    ));
    let per_vehicle = Arc::new(Mutex::new(Seen::default()));
    for k in 0..10 {
        let i = k * a.count / 10;
        tokio::spawn(subscriber(
            a.port,
            format!("watch-v{i:04}"),
            format!("mav/load/v{i:04}/#"),
            a.start_us,
            None,
            a.steady_until,
            Arc::clone(&per_vehicle),
        ));
    }
    let slow = Arc::new(Mutex::new(Seen::default()));
    tokio::spawn(subscriber(
        a.port,
        "watch-slow".into(),
        "mav/load/+/+/+/+".into(),
        a.start_us,
        Some(a.slow_from),
        a.steady_until,
        Arc::clone(&slow),
    ));
    // The command clients: ten, each sending a tenth of every burst, as a fleet's back end
    // would (one client alone serializes 1,000 requests on its one connection).
    let replies: Arc<Mutex<HashMap<Vec<u8>, u64>>> = Arc::default();
    let clients: Vec<AsyncClient> = (0..COMMAND_CLIENTS)
        .map(|k| command_client(a.port, k, Arc::clone(&replies), a.start_us))
        .collect();
    let mut bursts = Vec::new();
    for (b, &at) in a.commands_at.iter().enumerate() {
        until(a.start_us, at).await;
        let mut sent_at = HashMap::new();
        let mut mav_seq = 0u8;
        for i in 0..a.count {
            let sysid = sysid_of(i);
            let cmd = CommandLong {
                target_system: sysid,
                target_component: 1,
                command: MavCmd::COMPONENT_ARM_DISARM,
                param1: 1.0,
                ..Default::default()
            };
            let header = mavstack::core::wire::FrameHeader {
                version: mavstack::core::wire::Version::V2,
                seq: mav_seq,
                sysid: 255,
                compid: 190,
                signed: false,
            };
            mav_seq = mav_seq.wrapping_add(1);
            let mut buf = [0u8; 280];
            let n = mavstack::core::wire::emit_message(&header, &cmd, &mut buf)?;
            let corr = format!("b{b}-v{i:04}").into_bytes();
            let k = i % COMMAND_CLIENTS;
            let props = PublishProperties {
                response_topic: Some(format!("replies/c{k}/v{i:04}")),
                correlation_data: Some(corr.clone().into()),
                ..Default::default()
            };
            sent_at.insert(corr, now_us().saturating_sub(a.start_us));
            clients[k]
                .publish_with_properties(
                    format!("mav/load/v{i:04}/{sysid}/1/@cmd"),
                    QoS::AtLeastOnce,
                    false,
                    buf[..n].to_vec(),
                    props,
                )
                .await?;
        }
        bursts.push((at, sent_at));
    }
    until(a.start_us, a.run_s).await;
    let replies = replies
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .clone();
    let mut commands = Vec::new();
    for (at, sent_at) in bursts {
        let mut lat: Vec<u64> = sent_at
            .iter()
            .filter_map(|(c, s)| replies.get(c).map(|r| r.saturating_sub(*s)))
            .collect();
        let answered = lat.len();
        commands.push(serde_json::json!({
            "at_s": at, "sent": sent_at.len(), "answered": answered, "latency": percentiles(&mut lat),
        }));
    }
    let report = |s: &Arc<Mutex<Seen>>| {
        let mut s = s.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let by_second: Vec<serde_json::Value> = s
            .by_second
            .iter()
            .map(|((m, sec), n)| serde_json::json!([m, sec, n]))
            .collect();
        let mut lanes = serde_json::Map::new();
        for (lane, v) in &mut s.latency {
            lanes.insert((*lane).to_owned(), percentiles(v));
        }
        serde_json::json!({
            "received": s.by_msg, "received_by_second": by_second, "latency": lanes,
            "arrivals_s": s.arrivals.iter().map(|t| t / 100_000).collect::<std::collections::BTreeSet<_>>()
                .into_iter().map(|d| d as f64 / 10.0).collect::<Vec<_>>(),
        })
    };
    println!(
        "{}",
        serde_json::json!({
            "role": "watch", "wildcard": report(&wild), "per_vehicle": report(&per_vehicle),
            "slow": report(&slow), "commands": commands,
        })
    );
    std::process::exit(0);
}

fn main() -> Result<(), Failure> {
    let a = args()?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(async move {
        match a.role.as_str() {
            "vehicles" => vehicles(a).await,
            "watch" => watch(a).await,
            other => Err(format!("unknown role {other}").into()),
        }
    })
}
