//! UDP listener throughput, a benchmark (never part of the test suite): a sender thread pushes
//! HEARTBEATs, one per datagram, at a fixed rate to a `udpin` connection on loopback, and the
//! receiver counts what arrives. Prints one line per run: frames sent and received, each side's
//! rate, and the loss.
//!
//! ```text
//! udp_throughput blocking|one-thread RATE SECONDS   (RATE 0: as fast as the sender can go)
//! ```
//!
//! `blocking`: the blocking API, the driver on its runtime thread and the consumer on this
//! one. `one-thread`: the async API on a current-thread runtime, driver and consumer on one
//! thread (with the sender, two busy threads). Run by `scripts/bench-throughput.sh`, in a
//! release build.

use core::net::SocketAddr;
use core::time::Duration;
use std::net::UdpSocket;
use std::time::Instant;

use mavstack_core::wire::{FrameHeader, Version};
use mavstack_dialects::common::{Heartbeat, MavMessage};
use mavstack_transport::frame::{FrameBuf, FrameEvent, FrameProtocol, MessageTable};
use mavstack_transport::{ConnSpec, Options, blocking};

type Error = Box<dyn core::error::Error + Send + Sync>;

/// A second without frames: the sender is done.
const QUIET: Duration = Duration::from_secs(1);

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [api, rate, seconds] = args.as_slice() else {
        eprintln!("usage: udp_throughput blocking|one-thread RATE SECONDS");
        std::process::exit(2);
    };
    let rate: u64 = rate.parse()?;
    let seconds: u64 = seconds.parse()?;
    let total = if rate == 0 { 1_000_000 } else { rate * seconds };
    let run = match api.as_str() {
        "blocking" => blocking_api(rate, total)?,
        "one-thread" => one_thread(rate, total)?,
        other => return Err(format!("no API {other:?}: blocking or one-thread").into()),
    };
    println!(
        "udp {api}: offered {rate}/s; sent {} frames in {:.3} s ({:.0}/s); received {} in {:.3} s \
         ({:.0}/s); lost {}",
        run.sent,
        run.send_time.as_secs_f64(),
        run.sent as f64 / run.send_time.as_secs_f64().max(1e-9),
        run.received,
        run.recv_time.as_secs_f64(),
        run.received as f64 / run.recv_time.as_secs_f64().max(1e-9),
        run.sent.saturating_sub(run.received),
    );
    Ok(())
}

/// What one run counted.
struct Run {
    sent: u64,
    send_time: Duration,
    received: u64,
    recv_time: Duration,
}

fn protocol() -> FrameProtocol {
    FrameProtocol::new(MessageTable::of::<MavMessage>()).peer_events(false)
}

fn listen_spec() -> Result<ConnSpec, Error> {
    Ok("udpin:127.0.0.1:0".parse()?)
}

/// Counts the frames among `batch` and empties it.
fn frames(batch: &mut Vec<FrameEvent>) -> u64 {
    batch
        .drain(..)
        .filter(|e| matches!(e, FrameEvent::Frame(_)))
        .count() as u64
}

fn blocking_api(rate: u64, total: u64) -> Result<Run, Error> {
    let mut conn =
        blocking::Connection::open_with(&listen_spec()?, protocol(), &Options::default())?;
    let addr = conn
        .local_addr()
        .ok_or("the listener has no local address")?;
    let sender = std::thread::spawn(move || send_paced(addr, rate, total));
    let mut received = 0u64;
    let mut batch = Vec::with_capacity(4096);
    let mut first: Option<Instant> = None;
    let mut last = Instant::now();
    while received < total {
        match conn.recv_timeout(QUIET) {
            Ok(event) => batch.push(event),
            Err(_) => break,
        }
        // What else is waiting, without blocking (`recv_many` waits for one more, which
        // never comes once the last frame is in).
        while batch.len() < 4096 {
            match conn.try_recv() {
                Ok(event) => batch.push(event),
                Err(_) => break,
            }
        }
        first.get_or_insert_with(Instant::now);
        last = Instant::now();
        received += frames(&mut batch);
    }
    let (sent, send_time) = sender.join().map_err(|_| "the sender panicked")??;
    conn.close()?;
    Ok(Run {
        sent,
        send_time,
        received,
        recv_time: first.map_or(Duration::ZERO, |f| last - f),
    })
}

fn one_thread(rate: u64, total: u64) -> Result<Run, Error> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let mut conn = mavstack_transport::Connection::open(&listen_spec()?, protocol()).await?;
        let addr = conn
            .local_addr()
            .ok_or("the listener has no local address")?;
        let sender = std::thread::spawn(move || send_paced(addr, rate, total));
        let mut received = 0u64;
        let mut batch = Vec::with_capacity(4096);
        let mut first: Option<Instant> = None;
        let mut last = Instant::now();
        while received < total {
            let got = tokio::time::timeout(QUIET, conn.recv_many(&mut batch, 4096)).await;
            if !matches!(got, Ok(n) if n > 0) {
                break;
            }
            first.get_or_insert_with(Instant::now);
            last = Instant::now();
            received += frames(&mut batch);
        }
        let (sent, send_time) = sender.join().map_err(|_| "the sender panicked")??;
        conn.close().await?;
        Ok(Run {
            sent,
            send_time,
            received,
            recv_time: first.map_or(Duration::ZERO, |f| last - f),
        })
    })
}

/// Sends `total` HEARTBEATs to `addr`, one per datagram, at `rate` per second (0: at once).
fn send_paced(addr: SocketAddr, rate: u64, total: u64) -> Result<(u64, Duration), Error> {
    let socket = UdpSocket::bind("127.0.0.1:0")?;
    socket.connect(addr)?;
    let frames = (0..=255u8)
        .map(|seq| {
            let header = FrameHeader {
                version: Version::V2,
                seq,
                sysid: 1,
                compid: 1,
                signed: false,
            };
            FrameBuf::from_message(&header, &Heartbeat::default())
        })
        .collect::<Result<Vec<_>, _>>()?;
    let start = Instant::now();
    let mut sent = 0u64;
    while sent < total {
        let due = if rate == 0 {
            total
        } else {
            (start.elapsed().as_secs_f64() * rate as f64) as u64
        };
        while sent < due.min(total) {
            socket.send(frames[(sent % 256) as usize].as_bytes())?;
            sent += 1;
        }
        if rate != 0 {
            std::thread::sleep(Duration::from_micros(100));
        }
    }
    Ok((sent, start.elapsed()))
}
