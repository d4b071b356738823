#![allow(missing_docs)] // criterion_group! generates undocumented functions
//! The router core's cost per frame, without sockets: one MAVLink 2 ATTITUDE from a vehicle
//! link forwarded to two links (byte for byte; one of them converting to MAVLink 1; one of
//! them signing), the frame parsed, checked, routed, queued and taken out again.
//!
//! `forward/local`: the same frame delivered to the router's own component instead
//! (a ground station's node with one link, as `mavstack.mavutil` runs it), taken out with
//! `take_local` in batches of 32 as the node's driver does.
//!
//! `cargo bench -p mavstack-router --bench forward`

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use mavstack_channel::SigningConfig;
use mavstack_core::signing::SecretKey;
use mavstack_core::time::Instant;
use mavstack_core::wire::{self, FrameHeader, MAX_FRAME_LEN, Version};
use mavstack_dialects::ardupilotmega::MavMessage;
use mavstack_dialects::common::Attitude;
use mavstack_router::{
    LinkConfig, LocalDelivery, LocalFrames, MessageTable, Router, RouterConfig, VersionMode,
};

/// One MAVLink 2 ATTITUDE from system 1 (its sequence number and checksum are updated in
/// place by [`next_frame`]).
fn attitude_frame() -> ([u8; MAX_FRAME_LEN], usize) {
    let att = Attitude {
        time_boot_ms: 1,
        roll: 0.1,
        pitch: 0.2,
        yaw: 0.3,
        ..Attitude::default()
    };
    let mut frame = [0u8; MAX_FRAME_LEN];
    let header = FrameHeader {
        version: Version::V2,
        seq: 0,
        sysid: 1,
        compid: 1,
        signed: false,
    };
    let len = wire::emit_message(&header, &att, &mut frame).unwrap();
    (frame, len)
}

/// Makes `frame` a new frame: the next sequence number, the checksum recomputed.
fn next_frame(frame: &mut [u8]) {
    frame[4] = frame[4].wrapping_add(1);
    let mut f = wire::Frame::new_unchecked(frame);
    f.fill_checksum(<Attitude as mavstack_core::Message>::CRC_EXTRA);
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("forward");
    group.throughput(Throughput::Elements(1));
    {
        let mut config = RouterConfig::default();
        config.local = LocalDelivery::Addressed;
        let mut router = Router::new(config, MessageTable::of::<MavMessage>());
        let vehicle = router.add_link(LinkConfig::new("vehicle")).unwrap();
        let (mut frame, len) = attitude_frame();
        let mut local = LocalFrames::new();
        let mut now = Instant::from_secs(1_767_225_600);
        let mut fed = 0u32;
        group.bench_function("local", |b| {
            b.iter(|| {
                next_frame(&mut frame[..len]);
                now += core::time::Duration::from_micros(10);
                router.handle_datagram(now, vehicle, &frame[..len]);
                fed += 1;
                if fed.is_multiple_of(32) {
                    router.take_local(&mut local);
                }
                local.len()
            });
        });
    }
    for (name, out1) in [
        ("plain", LinkConfig::new("out1")),
        ("to_mavlink1", {
            let mut l = LinkConfig::new("out1");
            l.version = VersionMode::Mavlink1;
            l
        }),
        ("signed", {
            let mut l = LinkConfig::new("out1");
            l.signing = Some(SigningConfig::new(SecretKey::new([7; 32]), 1));
            l
        }),
    ] {
        let mut router = Router::new(RouterConfig::default(), MessageTable::of::<MavMessage>());
        let mut vehicle = LinkConfig::new("vehicle");
        vehicle.trusted = true;
        let vehicle = router.add_link(vehicle).unwrap();
        router.add_link(out1).unwrap();
        router.add_link(LinkConfig::new("out2")).unwrap();
        let (mut frame, len) = attitude_frame();
        let mut buf = [0u8; MAX_FRAME_LEN];
        let mut now = Instant::from_secs(1_767_225_600);
        group.bench_function(name, |b| {
            b.iter(|| {
                next_frame(&mut frame[..len]);
                now += core::time::Duration::from_micros(10);
                router.handle_datagram(now, vehicle, &frame[..len]);
                let mut n = 0;
                while let Some(t) = router.poll_transmit(&mut buf) {
                    n += t.len;
                }
                n
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
