//! Properties: arbitrary input never panics a channel or a radio, and valid frames mixed
//! with arbitrary noise in arbitrary pieces are all delivered.

mod util;

use mavstack_channel::{Channel, Config, Event, EventRef, GroundPolicy, Role};
use mavstack_core::wire::Version;
use mavstack_dialects::common::{Attitude, Heartbeat};
use proptest::prelude::*;
use util::{T0, frame};

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[cfg(feature = "fuzzing")]
    #[test]
    fn arbitrary_bytes_never_panic_the_channel(data in proptest::collection::vec(any::<u8>(), 0..2048)) {
        mavstack_channel::fuzz_channel(&data);
    }

    #[cfg(feature = "fuzzing")]
    #[test]
    fn arbitrary_bytes_around_valid_frames_never_panic(
        noise in proptest::collection::vec(any::<u8>(), 0..300),
        cut in 0usize..300,
    ) {
        let hb = frame(Version::V2, 0, 1, 1, &Heartbeat::default());
        let cut = cut.min(noise.len());
        let data = [&[0x40u8][..], &noise[..cut], &hb, &noise[cut..], &hb].concat();
        mavstack_channel::fuzz_channel(&data);
    }

    /// Every frame is delivered, and a twin channel drained through `poll_event_ref` gives
    /// the same frames byte for byte (frames of two lengths, so that a frame written over a
    /// longer one in the twin's reused places must not keep the longer one's bytes).
    #[test]
    fn valid_frames_in_noise_are_all_delivered(
        noise in proptest::collection::vec(any::<u8>().prop_filter("no start marker", |b| *b != 0xfd && *b != 0xfe), 0..64),
        piece in 1usize..64,
        count in 1u8..40,
    ) {
        let mut config = Config::ground_station(255, 190);
        config.role = Role::GroundStation(GroundPolicy::Mavlink2);
        let mut g = Channel::new(config.clone()).unwrap();
        let mut twin = Channel::new(config).unwrap();
        let mut stream = Vec::new();
        let mut sent = Vec::new();
        for seq in 0..count {
            stream.extend_from_slice(&noise[..usize::from(seq) % (noise.len() + 1)]);
            let v = if seq % 3 == 0 { Version::V1 } else { Version::V2 };
            let f = if seq % 2 == 0 {
                frame(v, seq, 1, 1, &Heartbeat::default())
            } else {
                frame(v, seq, 1, 1, &Attitude { roll: 1.0, ..Attitude::default() })
            };
            stream.extend_from_slice(&f);
            sent.push(f);
        }
        let (mut frames, mut lent) = (Vec::new(), Vec::new());
        for chunk in stream.chunks(piece) {
            let mut rest = chunk;
            loop {
                let n = g.handle_input(T0, rest);
                prop_assert_eq!(n, twin.handle_input(T0, rest));
                rest = &rest[n..];
                while let Some(e) = g.poll_event() {
                    if let Event::Frame(f) = e {
                        frames.push(f.frame.as_bytes().to_vec());
                    }
                }
                while let Some(e) = twin.poll_event_ref() {
                    match e {
                        EventRef::Frame(f) => lent.push(f.frame.as_bytes().to_vec()),
                        _ => prop_assert!(twin.poll_event().is_some()),
                    }
                }
                if rest.is_empty() {
                    break;
                }
            }
        }
        prop_assert_eq!(&frames, &sent);
        prop_assert_eq!(&lent, &sent);
        prop_assert_eq!(g.stats().lost, 0);
    }
}

#[cfg(feature = "fuzzing")]
#[test]
fn fuzz_entry_point_handles_edge_inputs() {
    mavstack_channel::fuzz_channel(&[]);
    mavstack_channel::fuzz_channel(&[0xff; 4096]);
    mavstack_channel::fuzz_channel(&[0xfd; 1000]);
    mavstack_channel::fuzz_channel(&[0xfe; 1000]);
    let hb = frame(Version::V2, 0, 1, 1, &Heartbeat::default());
    let mut data = vec![0x3f];
    data.extend(hb.iter().cycle().take(63));
    mavstack_channel::fuzz_channel(&data.repeat(20));
}
