use mavstack_core::Crc16;
use mavstack_core::parse::Item;
use mavstack_core::testing::Rng;
use mavstack_core::wire::MAX_FRAME_LEN;

use super::*;
use crate::raw::read_items;

/// Ids 0 to 9 are known, with these CRC_EXTRAs; the rest are not.
fn lookup(id: u32) -> Option<u8> {
    (id < 10).then(|| (id as u8).wrapping_mul(37).wrapping_add(11))
}

/// `n` random bytes.
fn bytes(rng: &mut Rng, n: usize) -> Vec<u8> {
    (0..n).map(|_| rng.next_u64() as u8).collect()
}

/// A MAVLink 2 frame of `id` with `payload`, its checksum right for `lookup` (for a known
/// id), signed with a made-up signature if `signed`.
fn v2(id: u32, payload: &[u8], signed: bool) -> Vec<u8> {
    let mut f = vec![0xfd, payload.len() as u8, u8::from(signed), 0, 7, 1, 1];
    f.extend_from_slice(&id.to_le_bytes()[..3]);
    f.extend_from_slice(payload);
    let mut crc = Crc16::new();
    crc.update(&f[1..]);
    crc.update_byte(lookup(id).unwrap_or(0));
    f.extend_from_slice(&crc.value().to_le_bytes());
    if signed {
        f.extend_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13]);
    }
    f
}

/// A MAVLink 1 frame of known `id`.
fn v1(id: u8, payload: &[u8]) -> Vec<u8> {
    let mut f = vec![0xfe, payload.len() as u8, 3, 1, 1, id];
    f.extend_from_slice(payload);
    let mut crc = Crc16::new();
    crc.update(&f[1..]);
    crc.update_byte(lookup(u32::from(id)).unwrap_or(0));
    f.extend_from_slice(&crc.value().to_le_bytes());
    f
}

/// A stream of every kind of item and damage: frames of both versions, signed ones, bad
/// checksums, unknown ids, bad incompatibility flags, noise full of start markers, cut
/// frames, and frames whose payload holds another valid frame.
fn stream(rng: &mut Rng, items: usize) -> Vec<u8> {
    let mut out = Vec::new();
    for _ in 0..items {
        let id = rng.below(10) as u32;
        let len = rng.below(256) as usize;
        let payload = bytes(rng, len);
        match rng.below(12) {
            0..=3 => out.extend(v2(id, &payload, false)),
            4 => out.extend(v2(id, &payload, true)),
            5 => out.extend(v1(id as u8, &payload)),
            6 => {
                let mut f = v2(id, &payload, false);
                let i = rng.below(f.len() as u64) as usize;
                f[i] ^= 0x10;
                out.extend(f);
            }
            7 => out.extend(v2(200 + id, &payload, false)),
            8 => {
                let n = rng.below(40) as usize;
                let mut noise = bytes(rng, n);
                for b in noise.iter_mut() {
                    if rng.below(4) == 0 {
                        *b = if rng.below(2) == 0 { 0xfd } else { 0xfe };
                    }
                }
                out.extend(noise);
            }
            9 => {
                let f = v2(id, &payload, false);
                out.extend_from_slice(&f[..rng.below(f.len() as u64) as usize]);
            }
            10 => {
                let mut f = v2(id, &payload, false);
                f[2] = 0x40;
                out.extend(f);
            }
            _ => {
                // A frame inside another's payload.
                let n = rng.below(120) as usize;
                let inner_payload = bytes(rng, n);
                let inner = v2(id, &inner_payload, rng.below(2) == 0);
                let mut payload = bytes(rng, 255);
                let at = rng.below((255 - inner.len()) as u64) as usize;
                payload[at..at + inner.len()].copy_from_slice(&inner);
                out.extend(v2(rng.below(10) as u32, &payload, false));
            }
        }
    }
    out
}

/// A pure count of items: signed frames, other frames and unknown ones weigh differently.
fn tally(item: Item<'_>) -> u64 {
    match item {
        Item::Frame(f) if f.is_signed() => 1_000,
        Item::Frame(_) => 1,
        Item::Unknown(_) => 1_000_000,
    }
}

/// What one parse in order gives.
fn in_order(data: &[u8]) -> (Stats, u64) {
    let mut sum = 0;
    let stats = read_items(data, lookup, |item| sum += tally(item), |_| {}).unwrap();
    (stats, sum)
}

#[test]
fn parts_give_what_one_parse_in_order_gives() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("capture.bin");
    let mut fallbacks = 0;
    for seed in 1..=30u64 {
        let mut rng = Rng::new(seed);
        let data = stream(&mut rng, 200 + 20 * seed as usize);
        std::fs::write(&path, &data).unwrap();
        let want = in_order(&data);
        assert!(want.0.frames > 50 && want.0.bad_crc > 0 && want.0.unknown_id > 0);
        let len = data.len() as u64;
        for parts in 1..=6 {
            for chunk_len in [2 * MAX_FRAME_LEN, 1000, 1 << 16] {
                for window in [0, 40, 600, 8192] {
                    let got = split_in(&path, len, parts, chunk_len, window, lookup, &tally);
                    assert_eq!(
                        got.unwrap(),
                        want,
                        "seed {seed}, {parts} parts, chunks of {chunk_len}, window {window}"
                    );
                    if window == 0 && parts > 1 {
                        fallbacks += 1;
                    }
                }
            }
        }
    }
    assert!(fallbacks > 0);
}

#[test]
fn tiny_and_empty_files_count_as_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("capture.bin");
    let heartbeat = v2(0, &[1, 2, 3, 4, 5, 6, 7, 8, 9], false);
    for data in [
        Vec::new(),
        vec![0xfd],
        heartbeat.clone(),
        heartbeat.repeat(3),
    ] {
        std::fs::write(&path, &data).unwrap();
        for parts in 1..=8 {
            let got = split_in(&path, data.len() as u64, parts, 1000, 600, lookup, &tally);
            assert_eq!(
                got.unwrap(),
                in_order(&data),
                "{} bytes, {parts} parts",
                data.len()
            );
        }
    }
}

#[test]
fn the_public_call_counts_a_file_and_names_a_missing_one() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("capture.bin");
    let data = stream(&mut Rng::new(7), 400);
    std::fs::write(&path, &data).unwrap();
    assert_eq!(
        count_items_split(&path, 2, lookup, tally).unwrap(),
        in_order(&data)
    );
    let missing = dir.path().join("nothing.bin");
    let err = count_items_split(&missing, 2, lookup, tally).unwrap_err();
    assert_eq!(err.kind(), io::ErrorKind::NotFound);
}
