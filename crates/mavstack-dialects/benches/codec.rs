#![allow(missing_docs)] // criterion_group! generates undocumented functions
//! Codec throughput: parse+validate, parse+validate+typed decode, encode, sign, verify, and
//! raw SHA-256 over the same bytes (the ceiling for verification).
//!
//! `cargo bench -p mavstack-dialects --features all --bench codec`. The stream is built here
//! from every message of the `all` dialect with pseudo-random payloads (seeded), ~10 % of the
//! frames MAVLink 1, ~5 % signed, and a little noise between frames; the side-by-side
//! comparison with the C library and rust-mavlink on pymavlink's corpus is
//! `scripts/bench-peers.sh`.

use criterion::{Criterion, Throughput, black_box, criterion_group, criterion_main};
use mavstack_core::parse::{Item, SliceParser};
use mavstack_core::signing::{SecretKey, append_signature, verify};
use mavstack_core::wire::{FrameHeader, MAX_FRAME_LEN, Version, emit, emit_message};
use mavstack_core::{MAX_PAYLOAD_LEN, MessageSet};
use mavstack_dialects::all::MavMessage;
use mavstack_dialects::common::{Attitude, GlobalPositionInt};
use mavstack_dialects::minimal::Heartbeat;
use sha2::{Digest, Sha256};

/// xorshift64*: a tiny seeded generator so the stream is the same every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
}

fn stream(bytes: usize, key: &SecretKey) -> (Vec<u8>, usize) {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let infos = MavMessage::all();
    let mut out = Vec::with_capacity(bytes + MAX_FRAME_LEN);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut frames = 0;
    while out.len() < bytes {
        let info = &infos[(rng.next() % infos.len() as u64) as usize];
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        for b in &mut payload[..usize::from(info.max_len)] {
            *b = rng.next() as u8;
        }
        let roll = rng.next() % 100;
        let version = if roll < 10 && info.id < 256 {
            Version::V1
        } else {
            Version::V2
        };
        let signed = version == Version::V2 && roll >= 95;
        let header = FrameHeader {
            version,
            seq: frames as u8,
            sysid: 1,
            compid: 1,
            signed,
        };
        let mut len = emit(
            &header,
            info,
            &payload[..usize::from(info.max_len)],
            &mut buf,
        )
        .expect("emits");
        if signed {
            len = append_signature(&mut buf, len, 0, frames as u64 + 1, key).expect("signs");
        }
        out.extend_from_slice(&buf[..len]);
        if roll.is_multiple_of(50) {
            out.extend_from_slice(&[0x11, 0x22, 0x33]);
        }
        frames += 1;
    }
    (out, frames)
}

fn lookup(id: u32) -> Option<u8> {
    MavMessage::info(id).map(|i| i.crc_extra)
}

fn benches(c: &mut Criterion) {
    let key = SecretKey::new([7; 32]);
    let (data, frames) = stream(8 << 20, &key);

    let mut g = c.benchmark_group("stream");
    g.throughput(Throughput::Bytes(data.len() as u64));
    g.bench_function("parse_validate", |b| {
        b.iter(|| SliceParser::new(black_box(&data), lookup).count());
    });
    g.bench_function("parse_validate_decode", |b| {
        b.iter(|| {
            let mut n = 0usize;
            for item in SliceParser::new(black_box(&data), lookup) {
                if let Item::Frame(f) = item
                    && let Ok(m) = MavMessage::decode(f.msg_id(), f.payload())
                {
                    black_box(&m);
                    n += 1;
                }
            }
            n
        });
    });
    g.finish();
    eprintln!("stream: {} bytes, {frames} frames", data.len());

    let mut g = c.benchmark_group("encode");
    g.throughput(Throughput::Elements(3));
    let hb = Heartbeat::default();
    let att = Attitude {
        roll: 0.1,
        pitch: 0.2,
        yaw: 0.3,
        ..Default::default()
    };
    let pos = GlobalPositionInt {
        lat: 473_977_420,
        lon: 85_455_940,
        alt: 500_000,
        ..Default::default()
    };
    let header = FrameHeader {
        version: Version::V2,
        seq: 0,
        sysid: 1,
        compid: 1,
        signed: false,
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    g.bench_function("heartbeat_attitude_position", |b| {
        b.iter(|| {
            let a = emit_message(&header, black_box(&hb), &mut buf).expect("emits");
            let b2 = emit_message(&header, black_box(&att), &mut buf).expect("emits");
            let c2 = emit_message(&header, black_box(&pos), &mut buf).expect("emits");
            a + b2 + c2
        });
    });
    let signed_header = FrameHeader {
        signed: true,
        ..header
    };
    g.bench_function("heartbeat_attitude_position_signed", |b| {
        b.iter(|| {
            let mut total = 0;
            let a = emit_message(&signed_header, black_box(&hb), &mut buf).expect("emits");
            total += append_signature(&mut buf, a, 0, 1, &key).expect("signs");
            let b2 = emit_message(&signed_header, black_box(&att), &mut buf).expect("emits");
            total += append_signature(&mut buf, b2, 0, 2, &key).expect("signs");
            let c2 = emit_message(&signed_header, black_box(&pos), &mut buf).expect("emits");
            total + append_signature(&mut buf, c2, 0, 3, &key).expect("signs")
        });
    });
    g.finish();

    // Verification against raw SHA-256 over exactly the bytes it hashes.
    let signed: Vec<Vec<u8>> = SliceParser::new(&data, lookup)
        .filter_map(|i| match i {
            Item::Frame(f) if f.is_signed() => Some(f.as_bytes().to_vec()),
            _ => None,
        })
        .collect();
    let hashed: u64 = signed.iter().map(|f| 32 + f.len() as u64 - 6).sum();
    let mut g = c.benchmark_group("signing");
    g.throughput(Throughput::Bytes(hashed));
    g.bench_function("verify", |b| {
        b.iter(|| {
            signed
                .iter()
                .filter(|f| {
                    let frame = mavstack_core::wire::Frame::new_unchecked(&f[..]);
                    verify(&frame, &key).is_ok()
                })
                .count()
        });
    });
    g.bench_function("raw_sha256_same_bytes", |b| {
        b.iter(|| {
            let mut acc = 0u8;
            for f in &signed {
                let mut h = Sha256::new();
                h.update(key.as_bytes());
                h.update(&f[..f.len() - 6]);
                acc ^= h.finalize()[0];
            }
            acc
        });
    });
    g.finish();
}

criterion_group! {
    name = codec;
    config = Criterion::default().sample_size(20).warm_up_time(core::time::Duration::from_secs(1)).measurement_time(core::time::Duration::from_secs(3));
    targets = benches
}
criterion_main!(codec);
