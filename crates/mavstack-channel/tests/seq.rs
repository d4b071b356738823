//! Sequence statistics (digest §1.3 rule 8): loss and duplicates per (sysid, compid),
//! compared with the faults the harness injected.

mod util;

use core::time::Duration;

use mavstack_channel::{Channel, Config, GroundPolicy, Role};
use mavstack_core::wire::Version;
use mavstack_dialects::common::Heartbeat;
use util::{Pair, T0, feed, frame};

#[test]
fn loss_and_duplicates_are_counted_and_match_the_injected_faults() {
    for seed in 0..5 {
        let mut p = Pair::default_pair().seed(seed);
        p.link.knobs.loss = 0.1;
        p.link.knobs.duplicate = 0.05;
        for _ in 0..1_000 {
            p.now += Duration::from_millis(10);
            p.vehicle_send(&Heartbeat::default());
            p.drive();
        }
        // A last frame over a perfect link closes any trailing gap.
        p.link.knobs = util::Knobs::default();
        p.vehicle_send(&Heartbeat::default());
        p.drive();
        let stats = p.gcs.stats();
        let source = p.gcs.sources()[0];
        assert_eq!((source.sysid, source.compid), (1, 1));
        assert_eq!(stats.lost, p.link.faults.lost, "seed {seed}");
        assert_eq!(stats.duplicates, p.link.faults.duplicated, "seed {seed}");
        assert_eq!(
            stats.received,
            1_001 - p.link.faults.lost + p.link.faults.duplicated
        );
        assert_eq!(source.received, stats.received);
    }
}

#[test]
fn sequence_is_tracked_per_source() {
    let mut config = Config::ground_station(255, 190);
    config.role = Role::GroundStation(GroundPolicy::Mavlink2);
    let mut g = Channel::new(config).unwrap();
    let mut stream = Vec::new();
    // Two components of system 1 interleaved, each with its own counter; one gap each.
    for seq in [0u8, 1, 2, 4] {
        stream.extend(frame(Version::V2, seq, 1, 1, &Heartbeat::default()));
        stream.extend(frame(
            Version::V2,
            seq.wrapping_mul(3),
            1,
            2,
            &Heartbeat::default(),
        ));
    }
    let _ = feed(&mut g, T0, &stream);
    let sources = g.sources();
    assert_eq!(sources.len(), 2);
    assert_eq!(
        (sources[0].received, sources[0].lost, sources[0].last_seq),
        (4, 1, 4)
    );
    assert_eq!(
        (sources[1].received, sources[1].lost, sources[1].last_seq),
        (4, 2 + 2 + 5, 12)
    );
}

#[test]
fn sequence_gaps_wrap_modulo_256() {
    let mut g = Channel::new(Config::ground_station(255, 190)).unwrap();
    let stream: Vec<u8> = [254u8, 255, 0, 1, 3]
        .iter()
        .flat_map(|&s| frame(Version::V1, s, 1, 1, &Heartbeat::default()))
        .collect();
    let _ = feed(&mut g, T0, &stream);
    let s = g.sources()[0];
    assert_eq!((s.received, s.lost, s.duplicates), (5, 1, 0));
}

#[test]
fn link_stats_expose_parser_counters_rejections_and_sent_frames() {
    let mut p = Pair::default_pair();
    p.heartbeats = Some(Duration::from_millis(100));
    p.drive_for(Duration::from_secs(1));
    p.heartbeats = None;
    p.drive(); // deliver what is still on the way
    let stats = p.gcs.stats();
    assert_eq!(stats.parser.frames, stats.accepted);
    assert_eq!(stats.sent, p.vehicle.stats().accepted);
    assert_eq!(
        stats.parser.bad_crc + stats.parser.skipped_bytes + stats.rejected.total(),
        0
    );
    assert_eq!(stats.untracked_frames + stats.control_dropped, 0);
    assert!(stats.parser.bytes > 0);
}
