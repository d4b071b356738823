use alloc::string::String;
use alloc::vec;

use proptest::prelude::*;

use super::*;

fn n(s: &str) -> Name {
    Name::new(s).unwrap()
}

#[test]
fn entries_share_prefixes_with_the_previous_name() {
    let table = vec![
        (n("RTL_ALT"), Value::I32(1500)),
        (n("RTL_SPEED"), Value::I16(-2)),
        (n("RTL"), Value::I8(7)),
        (n("X"), Value::F32(1.5)),
    ];
    let bytes = encode_with(
        &table.iter().map(|&(a, b)| (a, b, None)).collect::<Vec<_>>(),
        EncodeOptions {
            block: 0,
            ..EncodeOptions::default()
        },
    )
    .unwrap();
    let mut want = vec![0x1b, 0x67, 4, 0, 4, 0];
    // RTL_ALT: int32, nothing shared, 7 bytes.
    want.extend_from_slice(&[3, 0x60]);
    want.extend_from_slice(b"RTL_ALT");
    want.extend_from_slice(&1500i32.to_le_bytes());
    // RTL_SPEED: int16, "RTL_" shared, "SPEED".
    want.extend_from_slice(&[2, 0x44]);
    want.extend_from_slice(b"SPEED");
    want.extend_from_slice(&(-2i16).to_le_bytes());
    // RTL, a prefix of the previous name: two shared, one byte follows.
    want.extend_from_slice(&[1, 0x02, b'L', 7]);
    want.extend_from_slice(&[4, 0x00, b'X']);
    want.extend_from_slice(&1.5f32.to_le_bytes());
    assert_eq!(bytes, want);
    assert_eq!(decode(&bytes).unwrap(), table);
}

#[test]
fn values_never_cross_a_read_block() {
    // Names chosen so records straddle 239-byte boundaries at every phase.
    let table: Vec<(Name, Value)> = (0..400)
        .map(|i| {
            let name = alloc::format!("P{}_{}", "ABCDEFGHIJKL".get(..i % 12).unwrap(), i);
            let v = if i % 2 == 0 {
                Value::F32(i as f32)
            } else {
                Value::I16(i as i16)
            };
            (n(&name), v)
        })
        .collect();
    let bytes = encode(&table).unwrap();
    assert_eq!(decode(&bytes).unwrap(), table);
    // Walk the records: every value ends in the block it starts in.
    let mut pos = HEADER;
    let mut padded = 0;
    while pos < bytes.len() {
        if bytes[pos] == 0 {
            pos += 1;
            padded += 1;
            continue;
        }
        let len = [0, 1, 2, 4, 4][usize::from(bytes[pos] & 0x0f)];
        let start = pos + 2 + usize::from(bytes[pos + 1] >> 4) + 1;
        assert_eq!(start / BLOCK, (start + len - 1) / BLOCK, "value at {start}");
        pos = start + len;
    }
    assert!(padded > 0, "some padding was needed");
}

#[test]
fn defaults_are_written_where_they_differ() {
    let entries = vec![
        (n("A"), Value::I8(1), Some(Value::I8(2))),
        (n("B"), Value::F32(1.0), Some(Value::F32(1.0))),
        (n("C"), Value::I16(5), None),
        (n("D"), Value::I32(5), Some(Value::F32(9.4))),
    ];
    let bytes = encode_with(
        &entries,
        EncodeOptions {
            with_defaults: true,
            ..EncodeOptions::default()
        },
    )
    .unwrap();
    assert_eq!(&bytes[..2], &MAGIC_WITH_DEFAULTS.to_le_bytes());
    assert_eq!(bytes[6], 0x11, "A: int8 with a default");
    let file = decode_file(&bytes).unwrap();
    assert!(file.with_defaults);
    assert_eq!(
        file.entries,
        vec![
            (n("A"), Value::I8(1), Some(Value::I8(2))),
            (n("B"), Value::F32(1.0), Some(Value::F32(1.0))),
            (n("C"), Value::I16(5), Some(Value::I16(5))),
            (n("D"), Value::I32(5), Some(Value::I32(9))),
        ]
    );
}

#[test]
fn unsigned_values_become_the_smallest_signed_type_holding_them() {
    let table = vec![
        (n("A"), Value::U8(100)),
        (n("B"), Value::U8(200)),
        (n("C"), Value::U16(40_000)),
        (n("D"), Value::U32(7)),
    ];
    let back = decode(&encode(&table).unwrap()).unwrap();
    assert_eq!(
        back,
        vec![
            (n("A"), Value::I8(100)),
            (n("B"), Value::I16(200)),
            (n("C"), Value::I32(40_000)),
            (n("D"), Value::I32(7)),
        ]
    );
    assert_eq!(
        encode(&[(n("E"), Value::U32(u32::MAX))]),
        Err(EncodeError::Unrepresentable(n("E")))
    );
}

#[test]
fn uploads_are_checked_as_ardupilot_checks_them() {
    // As MAVProxy's `param ftpload` packs: header, then entries without padding.
    let good = [
        0x1b, 0x67, 2, 0, 17, 0, 1, 0x00, b'A', 5, 4, 0x01, b'B', 0, 0, 0x80, 0x3f,
    ];
    assert_eq!(
        decode_upload(&good),
        Ok(vec![(n("A"), Value::I8(5)), (n("AB"), Value::F32(1.0))])
    );
    assert_eq!(
        decode_upload(&good[..16]),
        Err(DecodeError::WrongLength {
            found: 16,
            expected: 17
        })
    );
    let mut defaults = good;
    defaults[0] = 0x1c;
    assert_eq!(decode_upload(&defaults), Err(DecodeError::DefaultsInUpload));
    let mut flagged = good;
    flagged[6] |= 0x20;
    assert_eq!(decode_upload(&flagged), Err(DecodeError::DefaultsInUpload));
    // Padding, which a download may carry, is not an upload's.
    let padded = [0x1b, 0x67, 1, 0, 11, 0, 0, 1, 0x00, b'A', 5];
    assert!(matches!(
        decode_upload(&padded),
        Err(DecodeError::BadType { offset: 6, ty: 0 })
    ));
    let mut miscounted = good;
    miscounted[2] = 3;
    assert_eq!(
        decode_upload(&miscounted),
        Err(DecodeError::WrongCount {
            found: 2,
            expected: 3
        })
    );
    // Past 65,535 bytes an upload cannot say its length.
    let big: Vec<_> = (0..10_000)
        .map(|i| (n(&alloc::format!("PARAM_{i:010}")), Value::F32(1.0)))
        .collect();
    assert!(matches!(encode_upload(&big), Err(EncodeError::TooLarge(_))));
}

#[test]
fn bad_files_are_refused() {
    assert_eq!(decode(&[0x1b, 0x67]), Err(DecodeError::TooShort(2)));
    assert_eq!(decode(&[0, 0, 0, 0, 0, 0]), Err(DecodeError::BadMagic(0)));
    assert_eq!(
        decode(&[0x1b, 0x67, 2, 0, 1, 0]),
        Err(DecodeError::BadCount { count: 2, total: 1 })
    );
    assert_eq!(decode(&[0x1b, 0x67, 0, 0, 0, 0, 0, 0]), Ok(vec![]));
    let one = [0x1b, 0x67, 1, 0, 1, 0, 1, 0x00, b'A', 5];
    assert_eq!(decode(&one), Ok(vec![(n("A"), Value::I8(5))]));
    assert_eq!(decode(&one[..9]), Err(DecodeError::Truncated(6)));
    assert!(matches!(
        decode(&[0x1b, 0x67, 1, 0, 1, 0, 5, 0x00, b'A', 5]),
        Err(DecodeError::BadType { ty: 5, .. })
    ));
    assert_eq!(
        decode(&[0x1b, 0x67, 1, 0, 1, 0, 1, 0x01, b'A', 5]),
        Err(DecodeError::BadPrefix(6))
    );
    assert_eq!(
        decode(&[0x1b, 0x67, 1, 0, 1, 0, 1, 0x00, 0xff, 5]),
        Err(DecodeError::BadName(6))
    );
    assert_eq!(
        decode(&[0x1b, 0x67, 2, 0, 2, 0, 1, 0x00, b'A', 5]),
        Err(DecodeError::WrongCount {
            found: 1,
            expected: 2
        })
    );
    // 15 shared + 2 bytes: too long.
    let mut long = vec![0x1b, 0x67, 2, 0, 2, 0, 1, 0xf0];
    long.extend_from_slice(b"ABCDEFGHIJKLMNOP");
    long.extend_from_slice(&[1, 1, 0x1f, b'Q', b'R', 1]);
    assert_eq!(decode(&long), Err(DecodeError::BadName(25)));
}

#[test]
fn queries_name_the_packed_file() {
    assert_eq!(Query::parse("@PARAM/param.pck"), Some(Ok(Query::default())));
    assert_eq!(
        Query::parse("@PARAM/param.pck?withdefaults=1"),
        Some(Ok(Query {
            with_defaults: true,
            ..Query::default()
        }))
    );
    assert_eq!(
        Query::parse("@PARAM/param.pck?start=2&count=3&x=y"),
        Some(Ok(Query {
            with_defaults: false,
            start: 2,
            count: 3
        }))
    );
    assert_eq!(
        Query::parse("@PARAM/param.pck?withdefaults=2"),
        Some(Err(()))
    );
    assert_eq!(Query::parse("@PARAM/param.pckx"), None);
    assert_eq!(Query::parse("param.pck"), None);
    let table: Vec<_> = ["A", "B", "C", "D"]
        .iter()
        .enumerate()
        .map(|(i, s)| (n(s), Value::I8(i as i8), None))
        .collect();
    let q = Query {
        start: 1,
        count: 2,
        ..Query::default()
    };
    let file = decode_file(&q.encode(&table).unwrap()).unwrap();
    assert_eq!(file.total, 4);
    assert_eq!(
        file.table(),
        vec![(n("B"), Value::I8(1)), (n("C"), Value::I8(2))]
    );
    assert!(
        Query {
            start: 4,
            ..Query::default()
        }
        .encode(&table)
        .is_err()
    );
}

#[test]
fn a_client_reads_the_table_from_a_server_over_an_overlay() {
    use mavstack_core::time::Instant;

    use super::super::{
        ClientConfig, FtpClient, FtpEvent, FtpOutput, FtpServer, MemoryBackend, Overlay,
        ServerConfig,
    };
    use crate::{Address, Service};

    let (gcs, vehicle) = (Address::new(255, 190), Address::new(1, 1));
    let table: Vec<(Name, Value)> = (0..300)
        .map(|i| (n(&alloc::format!("PARAM_{i}")), Value::F32(i as f32)))
        .collect();
    let mut files = TableFile::new(&table);
    assert!(files.set(n("PARAM_7"), Value::F32(-1.0)));
    let mut server = FtpServer::new(
        vehicle,
        ServerConfig::default(),
        Overlay::new(MemoryBackend::new(), files),
    );
    let mut now = Instant::from_secs(1);
    let mut fetch = |path: &str| {
        let mut client = FtpClient::new(gcs, vehicle, ClientConfig::default());
        client.read(now, path).unwrap();
        loop {
            while let Some(out) = client.poll_transmit() {
                server.handle_message(now, gcs, &out.message);
            }
            while let Some(out) = server.poll_transmit() {
                client.handle_message(now, vehicle, &out.message);
            }
            if let Some(FtpEvent::Finished(r)) = core::iter::from_fn(|| client.poll_event()).last()
            {
                return r;
            }
            now += core::time::Duration::from_millis(1);
            client.handle_timeout(now);
            server.handle_timeout(now);
        }
    };
    let Ok(FtpOutput::Data(bytes)) = fetch("/@PARAM/param.pck") else {
        panic!("read");
    };
    let mut want = table.clone();
    want[7].1 = Value::F32(-1.0);
    assert_eq!(decode(&bytes).unwrap(), want);
    let Ok(FtpOutput::Data(bytes)) = fetch("@PARAM/param.pck?withdefaults=1") else {
        panic!("read with defaults");
    };
    let file = decode_file(&bytes).unwrap();
    assert!(file.with_defaults);
    assert_eq!(file.entries[7].2, Some(Value::F32(7.0)));
    assert!(fetch("@PARAM/param.pck?withdefaults=7").is_err());
}

fn value() -> impl Strategy<Value = Value> {
    prop_oneof![
        any::<i8>().prop_map(Value::I8),
        any::<i16>().prop_map(Value::I16),
        any::<i32>().prop_map(Value::I32),
        // Any bits, NaNs included: compared bit for bit below.
        any::<u32>().prop_map(|b| Value::F32(f32::from_bits(b))),
    ]
}

fn table() -> impl Strategy<Value = Vec<(Name, Value)>> {
    let name = "[A-Z_][A-Z0-9_]{0,15}".prop_map(|s: String| Name::new(&s).unwrap());
    proptest::collection::vec((name, value()), 0..300)
}

fn same(a: &[(Name, Value)], b: &[(Name, Value)]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.0 == y.0 && x.1.same_as(y.1))
}

proptest! {
    #[test]
    fn tables_round_trip(table in table(), block in prop_oneof![Just(0usize), Just(BLOCK), 1usize..64]) {
        let entries: Vec<_> = table.iter().map(|&(a, b)| (a, b, None)).collect();
        let bytes = encode_with(&entries, EncodeOptions { block, ..EncodeOptions::default() }).unwrap();
        let back = decode(&bytes).unwrap();
        prop_assert!(same(&back, &table), "{:?} != {:?}", back, table);
    }

    #[test]
    fn uploads_round_trip(table in table()) {
        let bytes = encode_upload(&table).unwrap();
        prop_assert_eq!(usize::from(u16::from_le_bytes([bytes[4], bytes[5]])), bytes.len());
        let back = decode_upload(&bytes).unwrap();
        prop_assert!(same(&back, &table), "{:?} != {:?}", back, table);
    }

    #[test]
    fn any_upload_bytes_decode_without_panicking(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let _ = decode_upload(&bytes);
    }

    #[test]
    fn tables_with_defaults_round_trip(
        entries in proptest::collection::vec(
            ("[A-Z]{1,16}".prop_map(|s: String| Name::new(&s).unwrap()), value(), any::<bool>()),
            0..100,
        )
    ) {
        // Defaults of the value's own type, here its negation where it has one.
        let entries: Vec<_> = entries
            .into_iter()
            .map(|(name, v, d)| {
                let default = match v {
                    Value::I8(x) => Value::I8(x.wrapping_add(1)),
                    Value::I16(x) => Value::I16(x.wrapping_add(1)),
                    Value::I32(x) => Value::I32(x.wrapping_add(1)),
                    other => other,
                };
                (name, v, d.then_some(default))
            })
            .collect();
        let options = EncodeOptions { with_defaults: true, ..EncodeOptions::default() };
        let file = decode_file(&encode_with(&entries, options).unwrap()).unwrap();
        prop_assert_eq!(file.entries.len(), entries.len());
        for ((n1, v1, d1), (n2, v2, d2)) in file.entries.iter().zip(&entries) {
            prop_assert_eq!(n1, n2);
            prop_assert!(v1.same_as(*v2));
            prop_assert!(d1.unwrap().same_as(d2.unwrap_or(*v2)));
        }
    }

    #[test]
    fn any_bytes_decode_without_panicking(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = decode_file(&bytes);
    }

    #[test]
    fn any_body_after_a_good_header_decodes_without_panicking(
        magic in prop_oneof![Just(MAGIC), Just(MAGIC_WITH_DEFAULTS)],
        count in 0u16..20,
        body in proptest::collection::vec(
            prop_oneof![3 => 0u8..6, 1 => any::<u8>(), 1 => Just(0x11u8), 1 => 0x20u8..0x40],
            0..300,
        ),
    ) {
        let mut bytes = magic.to_le_bytes().to_vec();
        bytes.extend_from_slice(&count.to_le_bytes());
        bytes.extend_from_slice(&u16::MAX.to_le_bytes());
        bytes.extend_from_slice(&body);
        if let Ok(file) = decode_file(&bytes) {
            prop_assert_eq!(file.entries.len(), usize::from(count));
        }
    }
}
