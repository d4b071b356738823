//! # mavstack-router
//!
//! The sans-IO core of a MAVLink router: many links, each a
//! [`mavstack_channel::Channel`] with its own version (MAVLink 1, MAVLink 2, signed MAVLink 2)
//! and signing keys; routes learned from accepted frames; forwarding that converts between
//! framings where links differ and keeps signed links signed; dedup, filters, rate limits
//! and bounded queues per link.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! ```text
//!  link A bytes ─► handle_datagram(now, A, ..) ─► channel A: parse, CRC, signature, replay
//!                                                   │ accepted frame
//!                                                   ▼
//!                  in-filters ─► learn route (src → A) ─► dedup ─► targets (dialect offsets)
//!                                                   │ destinations: where the target was seen,
//!                                                   │ or every link but A for a broadcast
//!                                                   ▼
//!   per out-link:  out-filters ─► rate limits ─► plan: as is │ → MAVLink 1 │ → MAVLink 2 │
//!                                                   strip signature │ sign with its key
//!                                                   ▼
//!                  control queue │ telemetry queue (bounded) ─► poll_transmit(buf) ─► link B
//! ```
//!
//! It never reads a clock, sleeps, or touches a socket; the transport driver in the
//! `mavstack` crate does. See the [`manual`] for the routing rules and why they depart from
//! "forward unchanged" where the versions documents ask it to.
//!
//! ## Features
//! - `std` (default): links `std` (host conveniences only).
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (`fuzz_router`, `fuzz_link_options`).
//!
//! MSRV: Rust 1.95.
#![no_std]
#![forbid(unsafe_code)]

extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

pub mod config;
mod convert;
mod dedup;
pub mod dialect;
mod limit;
pub mod local;
pub mod log_readers;
pub mod manual;
pub mod options;
mod queue;
pub mod route;
pub mod router;
pub mod stats;
pub mod systems;

pub use config::{
    DirectionFilters, IdFilter, LinkConfig, LinkRole, LocalDelivery, ProtocolVersionSupport,
    RateLimits, RouterConfig, VersionMode,
};
pub use dialect::{is_control, target_of};
pub use local::{LocalFrame, LocalFrames};
pub use mavstack_core::MessageTable;
pub use options::OptionError;
pub use route::Route;
pub use router::{Event, LinkId, Router, SendTo, Transmit};
pub use stats::{Conversions, Counters, DropReason, Drops, LinkMode, LinkStatus};

/// Fuzzing entry point for link options: any text is parsed (message names resolve to
/// nothing) and either gives a link or an error naming an option; never a panic.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_link_options(data: &[u8]) {
    let text = alloc::string::String::from_utf8_lossy(data);
    match options::parse(&text, "fuzz", &|name| (name == "ATTITUDE").then_some(30)) {
        Ok(link) => assert!(!(link.signing.is_some() && link.version == VersionMode::Mavlink1)),
        Err(e) => assert!(
            !e.option.is_empty()
                || text.contains("&&")
                || text.starts_with('&')
                || e.reason.contains("expected")
        ),
    }
}

/// Fuzzing entry point for the router: the data itself picks, piece by piece, which of six
/// links (MAVLink 1, 2, auto, signed, a second signed key, trusted) a piece arrives on,
/// whether as a datagram or a stream, and how far time moves; everything emitted is drained
/// and the router's invariants are checked on every frame written: a `version=1` link gets
/// only MAVLink 1 frames with ids up to 255, a signed link only frames that verify with its
/// key, other links no signed frames; and no frame goes back to the only link it came in on
/// (a frame is known by its seq, sysid, compid and message id, which conversions keep: one
/// written to link L whose header is in L's input and in no other link's input came back).
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_router(data: &[u8]) {
    use mavstack_channel::SigningConfig;
    use mavstack_core::signing::{SecretKey, verify};
    use mavstack_core::time::Instant;
    use mavstack_core::wire::{Frame, MAX_FRAME_LEN, Version};

    let dialect = MessageTable::of::<mavstack_dialects::common::MavMessage>();
    let config = RouterConfig {
        dedup: Some(core::time::Duration::from_millis(50)),
        local: LocalDelivery::All,
        ..RouterConfig::default()
    };
    let mut router = Router::new(config, dialect);
    let key_a = SecretKey::new([0x42; 32]);
    let key_b = SecretKey::new([0x24; 32]);
    let mut links = alloc::vec::Vec::new();
    for i in 0..6u8 {
        let mut c = LinkConfig::new(alloc::format!("l{i}"));
        match i {
            0 => c.version = VersionMode::Mavlink1,
            1 => c.version = VersionMode::Mavlink2,
            3 => c.signing = Some(SigningConfig::new(key_a.clone(), 1)),
            4 => c.signing = Some(SigningConfig::new(key_b.clone(), 2)),
            5 => c.trusted = true,
            _ => {}
        }
        c.queue_frames = 64;
        let Ok(id) = router.add_link(c) else { return };
        links.push(id);
    }
    let mut now = Instant::from_secs(1_767_225_600);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut local = LocalFrames::new();
    let mut rest = data;
    let mut inputs = alloc::vec![alloc::vec::Vec::new(); links.len()];
    while let Some((&control, tail)) = rest.split_first() {
        let (piece, after) = tail.split_at(usize::from(control >> 3).min(tail.len()));
        rest = after;
        let from = usize::from(control & 7) % links.len();
        inputs[from].extend_from_slice(piece);
        let link = links[from];
        if control & 0x80 == 0 {
            router.handle_datagram(now, link, piece);
        } else {
            router.handle_input(now, link, piece);
        }
        now += core::time::Duration::from_millis(u64::from(control & 3) * 400);
        router.handle_timeout(now);
        while router.poll_event().is_some() {}
        router.take_local(&mut local);
        for f in local.iter() {
            assert!(
                Frame::new_checked(f.bytes).is_ok_and(|v| v.frame_len() == f.bytes.len()),
                "a local frame is not exactly one frame"
            );
        }
        while let Some(t) = router.poll_transmit(&mut buf) {
            let frame = Frame::new_checked(&buf[..t.len]);
            assert!(
                frame.is_ok(),
                "the router wrote something that is not a frame"
            );
            let Ok(frame) = frame else { continue };
            let index = links
                .iter()
                .position(|&l| l == t.link)
                .unwrap_or(usize::MAX);
            match index {
                0 => assert!(frame.version() == Version::V1 && frame.msg_id() <= 255),
                3 => assert!(
                    verify(&frame, &key_a).is_ok(),
                    "unverifiable frame on a signed link"
                ),
                4 => assert!(
                    verify(&frame, &key_b).is_ok(),
                    "unverifiable frame on a signed link"
                ),
                _ => assert!(!frame.is_signed(), "a signature on a link without a key"),
            }
            let id = (frame.seq(), frame.sysid(), frame.compid(), frame.msg_id());
            if let Some(own) = inputs.get(index) {
                let elsewhere = inputs
                    .iter()
                    .enumerate()
                    .any(|(i, input)| i != index && carries(input, id));
                assert!(
                    elsewhere || !carries(own, id),
                    "a frame went back to the link it came from"
                );
            }
        }
        let _ = router.poll_timeout();
    }
}

/// Whether `input` holds a MAVLink 1 or 2 header with this seq, sysid, compid and message
/// id anywhere (lengths and checksums aside: more than the router accepts, never less).
#[cfg(feature = "fuzzing")]
fn carries(input: &[u8], (seq, sysid, compid, msg_id): (u8, u8, u8, u32)) -> bool {
    let id = msg_id.to_le_bytes();
    input.windows(10).any(|w| {
        w[0] == mavstack_core::wire::STX_V2 && w[4..10] == [seq, sysid, compid, id[0], id[1], id[2]]
    }) || input.windows(6).any(|w| {
        w[0] == mavstack_core::wire::STX_V1
            && msg_id <= 255
            && w[2..6] == [seq, sysid, compid, id[0]]
    })
}
