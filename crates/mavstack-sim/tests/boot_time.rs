//! Every time field the simulator sends counts from the vehicle's start, as a flight stack's
//! count from its boot, whatever epoch the driver's clock has. `mavstack vehicle` runs on the
//! transport's clock, whose readings are microseconds since the Unix epoch: a vehicle that
//! took those readings for its time since boot sent `time_boot_ms` 4294967295 in every frame.

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{CommandLong, MavCmd, MavMessage, Timesync as TimesyncMsg};
use mavstack_services::Address;
use mavstack_sim::{Autopilot, SimConfig, Vehicle, params};

/// A reading of a Unix-epoch clock (November 2025), as the transport's clock gives.
const EPOCH_READING: Instant = Instant::from_secs(1_763_000_000);

/// How long the vehicle runs: long enough for every stream to send several times.
const RUN: Duration = Duration::from_secs(12);

/// The time steps of the run's driver.
const TICK: Duration = Duration::from_millis(10);

const GCS: Address = Address {
    system: 255,
    component: 190,
};

fn config(autopilot: Autopilot) -> SimConfig {
    SimConfig {
        own: Address {
            system: 1,
            component: 1,
        },
        autopilot,
        mavlink2: true,
        params: params::defaults(autopilot),
        // Arming is refused for a while: the PX4 flavour says why in EVENTs, which carry a
        // time.
        estimator_settle: Duration::from_secs(60),
        data_streams_only: false,
        streams_on_request: false,
        ftp: false,
        ftp_files: None,
        log_dir: None,
    }
}

fn command(command: MavCmd, param1: f32) -> MavMessage {
    MavMessage::CommandLong(CommandLong {
        target_system: 1,
        target_component: 1,
        command,
        param1,
        ..CommandLong::default()
    })
}

/// The time a message carries, as a duration since the sender's boot, and the field's name;
/// `None` for a message without one.
fn time_of(message: &MavMessage) -> Option<(&'static str, Duration)> {
    let ms = |v: u32| Duration::from_millis(u64::from(v));
    Some(match message {
        MavMessage::Attitude(m) => ("ATTITUDE.time_boot_ms", ms(m.time_boot_ms)),
        MavMessage::GlobalPositionInt(m) => {
            ("GLOBAL_POSITION_INT.time_boot_ms", ms(m.time_boot_ms))
        }
        MavMessage::GpsRawInt(m) => ("GPS_RAW_INT.time_usec", Duration::from_micros(m.time_usec)),
        MavMessage::HomePosition(m) => (
            "HOME_POSITION.time_usec",
            Duration::from_micros(m.time_usec),
        ),
        MavMessage::Timesync(m) => (
            "TIMESYNC.tc1",
            Duration::from_nanos(u64::try_from(m.tc1).ok()?),
        ),
        MavMessage::Event(m) => ("EVENT.event_time_boot_ms", ms(m.event_time_boot_ms)),
        MavMessage::ComponentMetadata(m) => ("COMPONENT_METADATA.time_boot_ms", ms(m.time_boot_ms)),
        _ => return None,
    })
}

/// Runs a vehicle started at [`EPOCH_READING`] for [`RUN`], asking now and then for what
/// is only sent on request (TIMESYNC, HOME_POSITION, arming refused, COMPONENT_METADATA);
/// returns every timed field it sent with the time since its start at which it was sent.
fn run(autopilot: Autopilot) -> Vec<(&'static str, Duration, Duration)> {
    let mut vehicle = Vehicle::new(config(autopilot), EPOCH_READING);
    let mut seen = Vec::new();
    let mut since = Duration::ZERO;
    while since <= RUN {
        let now = EPOCH_READING + since;
        if since.as_millis() % 1000 == 500 {
            let ts1 = i64::try_from(since.as_nanos()).unwrap_or(i64::MAX);
            let asks = [
                MavMessage::Timesync(TimesyncMsg { tc1: 0, ts1 }),
                command(MavCmd::REQUEST_MESSAGE, 242.0),
                command(MavCmd::COMPONENT_ARM_DISARM, 1.0),
                command(MavCmd::REQUEST_MESSAGE, 397.0),
            ];
            for ask in &asks {
                vehicle.handle_message(now, GCS, ask);
            }
        }
        vehicle.handle_timeout(now);
        while let Some(out) = vehicle.poll_transmit() {
            if let Some((field, value)) = time_of(&out.message) {
                seen.push((field, value, since));
            }
        }
        since += TICK;
    }
    seen
}

/// Each field reads the time since the vehicle's start at which it was sent (TIMESYNC to
/// the microsecond the driver's clock gives, the others to their unit), so every field
/// starts near 0 and rises with the time given.
fn check(autopilot: Autopilot, expected: &[&str]) {
    let seen = run(autopilot);
    for &(field, value, at) in &seen {
        let grain = if field.ends_with("_ms") {
            Duration::from_millis(1)
        } else {
            Duration::from_micros(1)
        };
        assert!(
            value <= at && at - value < grain,
            "{autopilot}: {field} read {value:?} in a message sent {at:?} after the start"
        );
    }
    for &field in expected {
        let sent: Vec<(Duration, Duration)> = seen
            .iter()
            .filter(|s| s.0 == field)
            .map(|s| (s.1, s.2))
            .collect();
        assert!(
            sent.len() >= 2,
            "{autopilot}: {field} sent {} times, expected at least 2",
            sent.len()
        );
        // Messages sent at the same instant (a request answered as the stream is due) may
        // read the same; a later message reads later.
        assert!(
            sent.windows(2).all(|w| w[0].1 == w[1].1 || w[0].0 < w[1].0),
            "{autopilot}: {field} does not rise from one message to the next (value, sent \
             at): {sent:?}"
        );
    }
}

#[test]
fn ardupilot_time_fields_count_from_its_start() {
    check(
        Autopilot::Ardupilot,
        &[
            "ATTITUDE.time_boot_ms",
            "GLOBAL_POSITION_INT.time_boot_ms",
            "GPS_RAW_INT.time_usec",
            "HOME_POSITION.time_usec",
            "TIMESYNC.tc1",
        ],
    );
}

#[test]
fn px4_time_fields_count_from_its_start() {
    check(
        Autopilot::Px4,
        &[
            "ATTITUDE.time_boot_ms",
            "GLOBAL_POSITION_INT.time_boot_ms",
            "GPS_RAW_INT.time_usec",
            "HOME_POSITION.time_usec",
            "TIMESYNC.tc1",
            "EVENT.event_time_boot_ms",
            "COMPONENT_METADATA.time_boot_ms",
        ],
    );
}
