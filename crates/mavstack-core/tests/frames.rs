//! Golden byte vectors for every frame kind (`docs/protocol-notes.md` §4, computed there
//! with pymavlink and the C library), and properties of the parser.

use mavstack_core::MessageInfo;
use mavstack_core::parse::{Deframer, Item, SliceParser};
use mavstack_core::signing::{SecretKey, SignatureError, append_signature, verify};
use mavstack_core::wire::{EmitError, Frame, FrameHeader, MAX_FRAME_LEN, Version, emit};
use proptest::prelude::*;

const fn info(id: u32, crc_extra: u8, min_len: u8, max_len: u8) -> MessageInfo {
    MessageInfo {
        id,
        name: "",
        crc_extra,
        min_len,
        max_len,
        target_system_offset: None,
        target_component_offset: None,
    }
}

const HEARTBEAT: MessageInfo = info(0, 50, 9, 9);
const COMMAND_LONG: MessageInfo = info(76, 152, 33, 33);
const PARAM_REQUEST_LIST: MessageInfo = info(21, 159, 2, 2);
const COMMAND_ACK: MessageInfo = info(77, 143, 3, 10);
const MISSION_COUNT: MessageInfo = info(44, 221, 4, 9);

fn hex(s: &str) -> Vec<u8> {
    let s: String = s.split_whitespace().collect();
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).expect("hex"))
        .collect()
}

fn lookup(id: u32) -> Option<u8> {
    [
        HEARTBEAT,
        COMMAND_LONG,
        PARAM_REQUEST_LIST,
        COMMAND_ACK,
        MISSION_COUNT,
    ]
    .iter()
    .find(|i| i.id == id)
    .map(|i| i.crc_extra)
}

const HB_PAYLOAD: [u8; 9] = [0, 0, 0, 0, 2, 12, 0x51, 4, 3];

fn key() -> SecretKey {
    SecretKey::new(core::array::from_fn(|i| u8::try_from(i).expect("small")))
}

fn header(version: Version, sysid: u8, compid: u8, signed: bool) -> FrameHeader {
    FrameHeader {
        version,
        seq: 0,
        sysid,
        compid,
        signed,
    }
}

fn emitted(h: &FrameHeader, i: &MessageInfo, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let len = emit(h, i, payload, &mut buf).expect("emits");
    buf[..len].to_vec()
}

/// One golden vector: name, bytes, header, message, full payload.
type Golden = (&'static str, Vec<u8>, FrameHeader, MessageInfo, Vec<u8>);

fn golden() -> Vec<Golden> {
    let mut cmd = vec![0x00, 0x00, 0x96, 0x43];
    cmd.extend([0u8; 24]);
    cmd.extend([0x00, 0x02, 0x01, 0x01, 0x00]);
    vec![
        (
            "v2",
            hex("fd 09 00 00 00 01 01 00 00 00 00 00 00 00 02 0c 51 04 03 1b 74"),
            header(Version::V2, 1, 1, false),
            HEARTBEAT,
            HB_PAYLOAD.to_vec(),
        ),
        (
            "v1",
            hex("fe 09 00 01 01 00 00 00 00 00 02 0c 51 04 03 81 b7"),
            header(Version::V1, 1, 1, false),
            HEARTBEAT,
            HB_PAYLOAD.to_vec(),
        ),
        (
            "v2 truncated",
            hex(
                "fd20000000ffbe4c000000009643000000000000000000000000000000000000000000000000000201016b39",
            ),
            header(Version::V2, 255, 190, false),
            COMMAND_LONG,
            cmd.clone(),
        ),
        (
            "v1 of the same",
            hex(
                "fe2100ffbe4c0000964300000000000000000000000000000000000000000000000000020101006caa",
            ),
            header(Version::V1, 255, 190, false),
            COMMAND_LONG,
            cmd,
        ),
        (
            "v2 all zero",
            hex("fd 01 00 00 00 ff be 15 00 00 00 a5 2e"),
            header(Version::V2, 255, 190, false),
            PARAM_REQUEST_LIST,
            vec![0, 0],
        ),
        (
            "v2 extensions present",
            hex("fd 0a 00 00 00 01 01 4d 00 00 00 02 00 00 00 00 00 00 ff be 5d c4"),
            header(Version::V2, 1, 1, false),
            COMMAND_ACK,
            vec![0, 2, 0, 0, 0, 0, 0, 0, 255, 190],
        ),
        (
            "v2 extensions absent",
            hex("fd 04 00 00 00 ff be 2c 00 00 03 00 01 01 07 4c"),
            header(Version::V2, 255, 190, false),
            MISSION_COUNT,
            vec![3, 0, 1, 1, 0, 0, 0, 0, 0],
        ),
    ]
}

#[test]
fn emit_matches_golden_bytes() {
    for (name, bytes, h, i, payload) in golden() {
        assert_eq!(emitted(&h, &i, &payload), bytes, "{name}");
    }
}

#[test]
fn views_read_golden_bytes() {
    for (name, bytes, h, i, payload) in golden() {
        let f = Frame::new_checked(&bytes[..]).expect(name);
        assert_eq!(
            (f.version(), f.sysid(), f.compid(), f.seq(), f.msg_id()),
            (h.version, h.sysid, h.compid, 0, i.id),
            "{name}"
        );
        assert!(f.check_crc(i.crc_extra), "{name}");
        assert!(!f.check_crc(i.crc_extra.wrapping_add(1)), "{name}");
        assert_eq!(f.frame_len(), bytes.len(), "{name}");
        // The payload on the wire is a prefix of the full one; the rest is zero.
        let p = f.payload();
        assert!(
            payload.starts_with(p) && payload[p.len()..].iter().all(|&b| b == 0)
                || h.version == Version::V1,
            "{name}"
        );
        assert_eq!(f.signature(), None);
    }
}

#[test]
fn parse_finds_every_golden_frame_in_one_stream() {
    let mut stream = Vec::new();
    for (_, bytes, ..) in golden() {
        stream.extend_from_slice(&[0x00, 0xfd, 0x13]); // noise with a false start
        stream.extend_from_slice(&bytes);
    }
    let frames: Vec<Vec<u8>> = SliceParser::new(&stream, lookup)
        .map(|item| match item {
            Item::Frame(f) => f.as_bytes().to_vec(),
            Item::Unknown(f) => panic!("unknown {f:?}"),
        })
        .collect();
    let expected: Vec<Vec<u8>> = golden().into_iter().map(|g| g.1).collect();
    assert_eq!(frames, expected);
}

#[test]
fn signed_golden_frame() {
    let golden = hex(
        "fd 09 01 00 00 01 01 00 00 00 00 00 00 00 02 0c 51 04 03 fc 8c 01 05 04 03 02 01 00 b6 81 a6 e1 10 5b",
    );
    let mut buf = [0u8; MAX_FRAME_LEN];
    let len = emit(
        &header(Version::V2, 1, 1, true),
        &HEARTBEAT,
        &HB_PAYLOAD,
        &mut buf,
    )
    .expect("emits");
    let len = append_signature(&mut buf, len, 1, 0x0102030405, &key()).expect("signs");
    assert_eq!(&buf[..len], &golden[..]);
    let f = Frame::new_checked(&golden[..]).expect("frame");
    assert!(f.is_signed() && f.check_crc(50));
    let sig = f.signature().expect("signed");
    assert_eq!((sig.link_id, sig.timestamp), (1, 0x0102030405));
    assert_eq!(verify(&f, &key()), Ok(()));
    assert_eq!(
        verify(&f, &SecretKey::new([7; 32])),
        Err(SignatureError::BadSignature)
    );
    let mut forged = golden.clone();
    forged[14] ^= 1; // payload changed: the signature no longer matches
    assert_eq!(
        verify(&Frame::new_checked(&forged[..]).expect("frame"), &key()),
        Err(SignatureError::BadSignature)
    );
    let unsigned = hex("fd 09 00 00 00 01 01 00 00 00 00 00 00 00 02 0c 51 04 03 1b 74");
    assert_eq!(
        verify(&Frame::new_checked(&unsigned[..]).expect("frame"), &key()),
        Err(SignatureError::Unsigned)
    );
}

#[test]
fn emit_errors() {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let big = info(300, 217, 22, 22);
    assert_eq!(
        emit(&header(Version::V1, 1, 1, false), &big, &[1; 22], &mut buf),
        Err(EmitError::IdTooLargeForV1 { id: 300 })
    );
    assert_eq!(
        emit(
            &header(Version::V1, 1, 1, true),
            &HEARTBEAT,
            &HB_PAYLOAD,
            &mut buf
        ),
        Err(EmitError::SignedV1)
    );
    assert_eq!(
        emit(
            &header(Version::V2, 1, 1, false),
            &HEARTBEAT,
            &HB_PAYLOAD,
            &mut buf[..20]
        ),
        Err(EmitError::BufferTooSmall {
            needed: 21,
            available: 20
        })
    );
    assert_eq!(
        emit(
            &header(Version::V2, 1, 1, false),
            &HEARTBEAT,
            &[1; 10],
            &mut buf
        ),
        Err(EmitError::PayloadTooLong { len: 10, max: 9 })
    );
    // MAVLink 1 never carries extensions: COMMAND_ACK goes out with its 3 base bytes.
    let v1 = emitted(
        &header(Version::V1, 1, 1, false),
        &COMMAND_ACK,
        &[0, 2, 0, 7, 0, 0, 0, 0, 255, 190],
    );
    assert_eq!(v1[1], 3);
}

#[test]
fn view_errors() {
    assert!(matches!(
        Frame::new_checked(&[0x55u8, 1, 2][..]),
        Err(mavstack_core::wire::Error::NotAFrame { byte: 0x55 })
    ));
    assert!(matches!(
        Frame::new_checked(&[0xfdu8, 9, 0][..]),
        Err(mavstack_core::wire::Error::Truncated {
            needed: 10,
            available: 3
        })
    ));
    let mut bad = hex("fd 09 00 00 00 01 01 00 00 00 00 00 00 00 02 0c 51 04 03 1b 74");
    bad[2] = 0x02;
    assert!(matches!(
        Frame::new_checked(&bad[..]),
        Err(mavstack_core::wire::Error::UnknownIncompatFlags { flags: 2 })
    ));
    // The parser drops it and counts it.
    let mut p = SliceParser::new(&bad, lookup);
    assert!(p.next().is_none());
    assert_eq!(p.stats().bad_incompat, 1);
}

#[test]
fn unknown_ids_are_reported_when_framed() {
    // HEARTBEAT with msgid 0xAB0000 and a random CRC, followed by a good frame.
    let mut unknown = hex("fd 09 00 00 00 01 01 00 00 ab 00 00 00 00 02 0c 51 04 03 12 34");
    let good = hex("fd 09 00 00 00 01 01 00 00 00 00 00 00 00 02 0c 51 04 03 1b 74");
    unknown.extend_from_slice(&good);
    let items: Vec<Item<'_>> = SliceParser::new(&unknown, lookup).collect();
    assert!(
        matches!(items[..], [Item::Unknown(u), Item::Frame(f)] if u.msg_id() == 0xAB0000 && f.msg_id() == 0)
    );
}

fn frame_strategy() -> impl Strategy<Value = (Vec<u8>, bool)> {
    (
        any::<bool>(),
        any::<u8>(),
        proptest::collection::vec(any::<u8>(), 33),
        any::<bool>(),
    )
        .prop_map(|(v1, seq, payload, signed)| {
            let version = if v1 { Version::V1 } else { Version::V2 };
            let signed = signed && !v1;
            let mut buf = [0u8; MAX_FRAME_LEN];
            let h = FrameHeader {
                version,
                seq,
                sysid: 7,
                compid: 9,
                signed,
            };
            let mut len = emit(&h, &COMMAND_LONG, &payload, &mut buf).expect("emits");
            if signed {
                len = append_signature(&mut buf, len, 3, 1_000_000, &key()).expect("signs");
            }
            (buf[..len].to_vec(), signed)
        })
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..2048)) {
        let mut p = SliceParser::new(&data, lookup);
        for item in p.by_ref() {
            let (Item::Frame(f) | Item::Unknown(f)) = item;
            let _ = (f.payload(), f.signature(), f.checksum());
        }
        prop_assert_eq!(p.stats().bytes, data.len() as u64);
        let mut d = Deframer::new();
        let mut rest = &data[..];
        while !rest.is_empty() {
            let n = d.push(rest);
            rest = &rest[n..];
            while d.next_item(&lookup).is_some() {}
        }
        while d.finish(&lookup).is_some() {}
    }

    /// A valid frame after any garbage (start markers and cut frames included) is found.
    #[test]
    fn a_frame_after_garbage_is_always_found(
        garbage in proptest::collection::vec(prop_oneof![Just(0xfdu8), Just(0xfeu8), any::<u8>()], 0..300),
        (frame, signed) in frame_strategy(),
    ) {
        let mut stream = garbage.clone();
        stream.extend_from_slice(&frame);
        let found: Vec<Vec<u8>> = SliceParser::new(&stream, lookup)
            .filter_map(|i| match i { Item::Frame(f) => Some(f.as_bytes().to_vec()), Item::Unknown(_) => None })
            .collect();
        prop_assert!(found.last() == Some(&frame), "not found after {} garbage bytes", garbage.len());
        if signed {
            let f = Frame::new_checked(&frame[..]).expect("frame");
            prop_assert_eq!(verify(&f, &key()), Ok(()));
        }
    }

    /// The streaming deframer finds the same frames as the slice parser, however the bytes
    /// are split.
    #[test]
    fn deframer_agrees_with_slice_parser(
        frames in proptest::collection::vec(frame_strategy(), 1..20),
        noise in proptest::collection::vec(any::<u8>(), 0..64),
        chunk in 1usize..400,
    ) {
        let mut stream = Vec::new();
        for (i, (f, _)) in frames.iter().enumerate() {
            stream.extend_from_slice(&noise[..noise.len().min(i * 3)]);
            stream.extend_from_slice(f);
        }
        let expected: Vec<Vec<u8>> = SliceParser::new(&stream, lookup)
            .map(|i| match i { Item::Frame(f) | Item::Unknown(f) => f.as_bytes().to_vec() })
            .collect();
        let mut got = Vec::new();
        let mut d = Deframer::new();
        for piece in stream.chunks(chunk) {
            let mut rest = piece;
            while !rest.is_empty() {
                let n = d.push(rest);
                rest = &rest[n..];
                while let Some(Item::Frame(f) | Item::Unknown(f)) = d.next_item(&lookup) {
                    got.push(f.as_bytes().to_vec());
                }
            }
        }
        while let Some(Item::Frame(f) | Item::Unknown(f)) = d.finish(&lookup) {
            got.push(f.as_bytes().to_vec());
        }
        prop_assert_eq!(&got, &expected);
        for (f, _) in &frames {
            prop_assert!(expected.contains(f));
        }
    }
}
