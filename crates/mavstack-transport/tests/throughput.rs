//! UDP listener throughput: a sender pushes HEARTBEATs, one per datagram, at a fixed rate to
//! a `udpin` connection, which must receive every one.
//!
//! Ignored by default (it measures, and wants a release build):
//!
//! ```text
//! cargo test -p mavstack-transport --release --test throughput -- --ignored --nocapture
//! MAVSTACK_RATE=0 ...   # as fast as the sender can go, reporting loss instead of failing
//! MAVSTACK_RATE=300000 MAVSTACK_SECONDS=5 ...
//! ```

mod common;

use core::time::Duration;
use std::net::UdpSocket;
use std::time::Instant;

use common::{heartbeat, proto, spec};
use mavstack_transport::{FrameEvent, Options, blocking};

fn env(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The blocking API: the driver on its runtime thread, the consumer on the test's thread.
#[test]
#[ignore = "measures throughput; run with --release -- --ignored --nocapture"]
fn udp_listener_keeps_up_with_a_fast_sender() {
    let rate = env("MAVSTACK_RATE", 250_000);
    let seconds = env("MAVSTACK_SECONDS", 3);
    let total = if rate == 0 { 1_000_000 } else { rate * seconds };
    let options = Options::default();
    let mut conn = blocking::Connection::open_with(
        &spec("udpin:127.0.0.1:0"),
        proto().peer_events(false),
        &options,
    )
    .unwrap();
    let addr = conn.local_addr().unwrap();

    let sender = std::thread::spawn(move || send_paced(addr, rate, total));

    let mut received = 0u64;
    let mut batch = Vec::with_capacity(4096);
    let mut first: Option<Instant> = None;
    let mut last = Instant::now();
    while received < total {
        match conn.recv_timeout(Duration::from_secs(1)) {
            Ok(event) => batch.push(event),
            Err(_) => break, // a second without frames: the sender is done
        }
        conn.recv_many(&mut batch, 4096);
        first.get_or_insert_with(Instant::now);
        last = Instant::now();
        received += batch
            .drain(..)
            .filter(|e| matches!(e, FrameEvent::Frame(_)))
            .count() as u64;
    }
    let (sent, send_time) = sender.join().unwrap();
    let recv_time = first.map_or(Duration::ZERO, |f| last - f);
    let stats = conn.stats();
    println!(
        "udp: sent {sent} frames in {:.3} s ({:.0}/s); received {received} in {:.3} s ({:.0}/s); \
         lost {}; datagrams {} bad_crc {} skipped {}",
        send_time.as_secs_f64(),
        sent as f64 / send_time.as_secs_f64(),
        recv_time.as_secs_f64(),
        received as f64 / recv_time.as_secs_f64().max(1e-9),
        sent - received,
        stats.link.rx_chunks,
        stats.protocol.bad_crc,
        stats.protocol.skipped_bytes,
    );
    conn.close().unwrap();
    if rate != 0 {
        assert_eq!(received, sent, "frames lost at {rate} frames/s");
    }
}

/// The async API on a current-thread runtime: driver and consumer share one thread, so with
/// the sender there are two busy threads (this machine may have only two cores).
#[test]
#[ignore = "measures throughput; run with --release -- --ignored --nocapture"]
fn udp_listener_keeps_up_on_one_thread() {
    let rate = env("MAVSTACK_RATE", 250_000);
    let seconds = env("MAVSTACK_SECONDS", 3);
    let total = if rate == 0 { 1_000_000 } else { rate * seconds };
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        let mut conn = mavstack_transport::Connection::open(
            &spec("udpin:127.0.0.1:0"),
            proto().peer_events(false),
        )
        .await
        .unwrap();
        let addr = conn.local_addr().unwrap();
        let sender = std::thread::spawn(move || send_paced(addr, rate, total));
        let mut received = 0u64;
        let mut batch = Vec::with_capacity(4096);
        let mut first: Option<Instant> = None;
        let mut last = Instant::now();
        while received < total {
            let got = tokio::time::timeout(Duration::from_secs(1), conn.recv_many(&mut batch, 4096)).await;
            if !matches!(got, Ok(n) if n > 0) {
                break;
            }
            first.get_or_insert_with(Instant::now);
            last = Instant::now();
            received += batch
                .drain(..)
                .filter(|e| matches!(e, FrameEvent::Frame(_)))
                .count() as u64;
        }
        let (sent, send_time) = sender.join().unwrap();
        let recv_time = first.map_or(Duration::ZERO, |f| last - f);
        println!(
            "udp (one thread): sent {sent} frames in {:.3} s ({:.0}/s); received {received} in {:.3} s ({:.0}/s); lost {}",
            send_time.as_secs_f64(),
            sent as f64 / send_time.as_secs_f64(),
            recv_time.as_secs_f64(),
            received as f64 / recv_time.as_secs_f64().max(1e-9),
            sent - received,
        );
        conn.close().await.unwrap();
        if rate != 0 {
            assert_eq!(received, sent, "frames lost at {rate} frames/s");
        }
    });
}

/// Sends `total` HEARTBEATs to `addr`, one per datagram, at `rate` per second (0: at once).
fn send_paced(addr: core::net::SocketAddr, rate: u64, total: u64) -> (u64, Duration) {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.connect(addr).unwrap();
    let frames: Vec<_> = (0..=255u8).map(|seq| heartbeat(1, seq)).collect();
    let start = Instant::now();
    let mut sent = 0u64;
    while sent < total {
        let due = if rate == 0 {
            total
        } else {
            (start.elapsed().as_secs_f64() * rate as f64) as u64
        };
        while sent < due.min(total) {
            socket
                .send(frames[(sent % 256) as usize].as_bytes())
                .unwrap();
            sent += 1;
        }
        if rate != 0 {
            std::thread::sleep(Duration::from_micros(100));
        }
    }
    (sent, start.elapsed())
}
