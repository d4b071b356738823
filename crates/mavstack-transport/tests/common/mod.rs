//! Helpers shared by the link tests.
#![allow(dead_code, unreachable_pub)]

use core::time::Duration;

use mavstack_core::wire::{FrameHeader, Version};
use mavstack_dialects::common::{Heartbeat, MavMessage};
use mavstack_transport::frame::{FrameBuf, FrameEvent, FrameProtocol, MessageTable, ReceivedFrame};
use mavstack_transport::{ConnSpec, Connection, PeerId, PeerInfo};

pub type Proto = FrameProtocol;
pub type Conn = Connection<Proto>;

/// How long a test waits for anything before failing.
pub const WAIT: Duration = Duration::from_secs(5);

pub fn proto() -> Proto {
    FrameProtocol::new(MessageTable::of::<MavMessage>())
}

pub fn spec(s: &str) -> ConnSpec {
    s.parse().unwrap()
}

/// A HEARTBEAT from `sysid`/1 with sequence number `seq`.
pub fn heartbeat(sysid: u8, seq: u8) -> FrameBuf {
    let header = FrameHeader {
        version: Version::V2,
        seq,
        sysid,
        compid: 1,
        signed: false,
    };
    FrameBuf::from_message(&header, &Heartbeat::default()).unwrap()
}

pub async fn open(s: &str) -> Conn {
    Connection::open(&spec(s), proto()).await.unwrap()
}

/// The next event, or a test failure after [`WAIT`].
pub async fn event(conn: &mut Conn) -> FrameEvent {
    match tokio::time::timeout(WAIT, conn.recv()).await {
        Ok(Some(e)) => e,
        Ok(None) => panic!("connection ended"),
        Err(_) => panic!("no event within {WAIT:?}"),
    }
}

/// The next frame, skipping peer events.
pub async fn frame(conn: &mut Conn) -> ReceivedFrame {
    loop {
        if let FrameEvent::Frame(f) = event(conn).await {
            return f;
        }
    }
}

/// The next peer that appears, skipping frames.
pub async fn peer_added(conn: &mut Conn) -> PeerInfo {
    loop {
        if let FrameEvent::PeerAdded(p) = event(conn).await {
            return p;
        }
    }
}

/// Waits for the next peer to go away, skipping frames.
pub async fn peer_removed(conn: &mut Conn) -> PeerId {
    loop {
        if let FrameEvent::PeerRemoved(p) = event(conn).await {
            return p;
        }
    }
}

/// Waits until `cond` holds, checking every few milliseconds, failing after [`WAIT`].
pub async fn until(what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = tokio::time::Instant::now() + WAIT;
    while !cond() {
        assert!(tokio::time::Instant::now() < deadline, "timed out: {what}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}
