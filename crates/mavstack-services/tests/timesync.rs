//! TIMESYNC between two components with different clocks, through the simulated link.

mod util;

use core::time::Duration;

use mavstack_dialects::common::{MavMessage, Timesync as Msg};
use mavstack_services::timesync::{Timesync, TimesyncConfig, TimesyncEvent};
use mavstack_services::{Address, Service};
use util::{Knobs, Pair, T0};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);
const VEHICLE_AHEAD_NS: i64 = 1_500_000_000;

fn pair(knobs: Knobs, seed: u64) -> Pair<Timesync, Timesync> {
    let gcs = Timesync::new(TimesyncConfig {
        interval: Some(Duration::from_millis(500)),
        ..Default::default()
    });
    let vehicle = Timesync::new(TimesyncConfig {
        interval: None,
        clock_offset_ns: VEHICLE_AHEAD_NS,
        ..Default::default()
    });
    Pair::new(gcs, GCS, vehicle, VEHICLE, knobs, seed)
}

#[test]
fn sim_offset_is_estimated_under_loss() {
    let knobs = Knobs {
        latency: Duration::from_millis(2),
        jitter: Duration::from_millis(4),
        ..Knobs::hostile()
    };
    for seed in [1, 2, 3] {
        let mut p = pair(knobs, seed);
        p.drive_for(Duration::from_secs(30));
        let samples = core::iter::from_fn(|| p.a.poll_event())
            .filter(|e| matches!(e, TimesyncEvent::Sample { .. }))
            .count();
        assert!(samples > 20, "{samples}");
        let err = (p.a.offset_ns().unwrap() - VEHICLE_AHEAD_NS).abs();
        // Asymmetric jitter bounds a single sample's error by half the RTT spread (±2 ms).
        assert!(err < 2_000_000, "seed {seed}: off by {err} ns");
    }
}

#[test]
fn slow_answers_are_discarded() {
    let knobs = Knobs {
        latency: Duration::from_millis(20),
        ..Knobs::clean()
    };
    let mut p = pair(knobs, 1);
    p.drive_for(Duration::from_secs(3));
    let events: Vec<_> = core::iter::from_fn(|| p.a.poll_event()).collect();
    assert!(!events.is_empty());
    assert!(events.iter().all(
        |e| matches!(e, TimesyncEvent::Discarded { rtt, .. } if *rtt == Duration::from_millis(40))
    ));
    assert_eq!(p.a.offset_ns(), None);
}

#[test]
fn requests_are_answered_and_foreign_answers_ignored() {
    let mut t = Timesync::new(TimesyncConfig {
        interval: None,
        ..Default::default()
    });
    assert!(t.handle_message(T0, GCS, &MavMessage::Timesync(Msg { tc1: 0, ts1: 42 })));
    let out = t.poll_transmit().unwrap();
    assert_eq!(out.target, GCS);
    assert_eq!(
        out.message,
        MavMessage::Timesync(Msg {
            tc1: T0.as_micros() as i64 * 1000,
            ts1: 42
        })
    );
    // An answer to a request we never sent.
    assert!(!t.handle_message(T0, GCS, &MavMessage::Timesync(Msg { tc1: 5, ts1: 42 })));
    assert_eq!(t.poll_timeout(), None);
}
