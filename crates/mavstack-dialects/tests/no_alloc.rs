//! Zero heap allocations per frame: parsing, checksum validation, typed decoding, encoding,
//! signing and verifying run under a global allocator that counts every allocation, and the
//! count must not move.
#![cfg(feature = "all")]

use mavstack_core::parse::{Deframer, Item, SliceParser};
use mavstack_core::signing::{SecretKey, append_signature, verify};
use mavstack_core::wire::{FrameHeader, MAX_FRAME_LEN, Version, emit_message};
use mavstack_core::{MAX_PAYLOAD_LEN, MessageSet};
use mavstack_dialects::all::MavMessage;
use mavstack_dialects::common::{Attitude, CommandLong, GlobalPositionInt, MavCmd};
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};

#[global_allocator]
static GLOBAL: &StatsAlloc<std::alloc::System> = &INSTRUMENTED_SYSTEM;

#[test]
fn no_allocation_per_frame() {
    // A stream of signed and unsigned frames, built before counting starts.
    let key = SecretKey::new([7; 32]);
    let mut stream = Vec::with_capacity(1 << 20);
    let mut buf = [0u8; MAX_FRAME_LEN];
    for i in 0..2000u32 {
        let signed = i % 3 == 0;
        let header = FrameHeader {
            version: Version::V2,
            seq: (i % 256) as u8,
            sysid: 1,
            compid: 1,
            signed,
        };
        let len = match i % 3 {
            0 => emit_message(
                &header,
                &Attitude {
                    time_boot_ms: i,
                    roll: 0.5,
                    ..Default::default()
                },
                &mut buf,
            ),
            1 => emit_message(
                &header,
                &GlobalPositionInt {
                    lat: 473_977_420,
                    alt: 500,
                    ..Default::default()
                },
                &mut buf,
            ),
            _ => emit_message(
                &header,
                &CommandLong {
                    command: MavCmd::REQUEST_MESSAGE,
                    param1: 300.0,
                    ..Default::default()
                },
                &mut buf,
            ),
        }
        .expect("emits");
        let len = if signed {
            append_signature(&mut buf, len, 1, u64::from(i) + 1, &key).expect("signs")
        } else {
            len
        };
        stream.extend_from_slice(&buf[..len]);
        stream.extend_from_slice(&[0x00, 0xfd, 0x11]);
    }
    let lookup = |id: u32| MavMessage::info(id).map(|i| i.crc_extra);

    let region = Region::new(GLOBAL);
    let mut frames = 0;
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    for item in SliceParser::new(&stream, lookup) {
        let Item::Frame(frame) = item else { continue };
        let message = MavMessage::decode(frame.msg_id(), frame.payload()).expect("known");
        let n = message.encode(&mut payload);
        assert!(n >= frame.payload().len());
        if frame.is_signed() {
            verify(&frame, &key).expect("valid signature");
        }
        frames += 1;
    }
    let mut deframer = Deframer::new();
    let mut rest = &stream[..];
    while !rest.is_empty() {
        let n = deframer.push(&rest[..rest.len().min(61)]);
        rest = &rest[n..];
        while let Some(Item::Frame(frame)) = deframer.next_item(&lookup) {
            core::hint::black_box(MavMessage::decode(frame.msg_id(), frame.payload()).ok());
            frames += 1;
        }
    }
    for i in 0..1000u32 {
        let header = FrameHeader {
            version: Version::V2,
            seq: 0,
            sysid: 1,
            compid: 1,
            signed: true,
        };
        let len = emit_message(
            &header,
            &Attitude {
                time_boot_ms: i,
                ..Default::default()
            },
            &mut buf,
        )
        .expect("emits");
        core::hint::black_box(
            append_signature(&mut buf, len, 1, u64::from(i), &key).expect("signs"),
        );
    }
    let change = region.change();
    assert_eq!(frames, 4000);
    assert_eq!(
        (change.allocations, change.reallocations),
        (0, 0),
        "allocations while parsing, decoding, encoding and signing"
    );
    // The instrument itself counts: one small vector is one allocation.
    let control = Region::new(GLOBAL);
    core::hint::black_box(vec![0u8; 16]);
    assert_eq!(
        control.change().allocations,
        1,
        "the allocation counter works"
    );
}
