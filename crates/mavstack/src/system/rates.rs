//! Telemetry rates: asked for (SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM where that is
//! refused or ignored), checked by the message's arrival, and kept: a vehicle that restarts
//! forgets the rates it was asked for (ArduPilot then streams nothing again), so a message
//! that came and then stays away for five of its intervals (at least 3 s) while the
//! vehicle's HEARTBEAT still comes is asked for anew.

use core::time::Duration;
use std::sync::{Arc, Weak};

use mavstack_dialects::common::{MavDataStream, MavMessage};
use tokio::time::Instant;

use super::{Inner, System, SystemError, lock};

/// How often the keeper looks at the kept rates.
const KEEPER_TICK: Duration = Duration::from_secs(1);

/// A HEARTBEAT this recent says the vehicle is alive.
const ALIVE: Duration = Duration::from_secs(3);

/// How [`Telemetry::request_rate`](super::Telemetry::request_rate) got the message going.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RateMethod {
    /// MAV_CMD_SET_MESSAGE_INTERVAL, accepted.
    MessageInterval,
    /// REQUEST_DATA_STREAM for this group, after SET_MESSAGE_INTERVAL was refused or ignored.
    DataStream(MavDataStream),
}

/// What [`Telemetry::request_rate`](super::Telemetry::request_rate) did and saw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RateRequest {
    /// The request that was made last.
    pub how: RateMethod,
    /// Whether the message then arrived.
    pub arrived: bool,
}

/// A rate asked for.
#[derive(Clone, Copy, Debug)]
struct KeptRate {
    id: u32,
    hz: f32,
    asked: Instant,
}

/// The rates asked for, and whether their keeper runs.
#[derive(Debug, Default)]
pub(super) struct Kept {
    rates: Vec<KeptRate>,
    keeper: bool,
}

/// A rate as asked: finite, within 0.01–1,000 Hz.
fn sane(hz: f32) -> f32 {
    if hz.is_finite() {
        hz.clamp(0.01, 1000.0)
    } else {
        1.0
    }
}

/// How long a message may stay away before it counts as stopped.
fn stall(hz: f32) -> Duration {
    Duration::from_secs_f32(5.0 / hz).max(Duration::from_secs(3))
}

impl System {
    /// Asks for message `msg_id` at `hz` and checks that it comes (see
    /// [`Telemetry::request_rate`](super::Telemetry::request_rate)).
    pub(super) async fn ask_rate(&self, msg_id: u32, hz: f32) -> Result<RateRequest, SystemError> {
        let hz = sane(hz);
        let interval = Duration::from_secs_f32(1.0 / hz);
        let wait = (interval * 3).max(Duration::from_millis(1500));
        let answer = self
            .commands()
            .set_message_interval(msg_id, Some(interval))
            .await;
        let accepted = match answer {
            Ok(_) => true,
            Err(SystemError::Stopped) => return Err(SystemError::Stopped),
            Err(_) => false,
        };
        if accepted && self.comes(msg_id, wait).await {
            return Ok(RateRequest {
                how: RateMethod::MessageInterval,
                arrived: true,
            });
        }
        let Some(group) = mavstack_services::stream::data_stream_of(msg_id) else {
            return Ok(RateRequest {
                how: RateMethod::MessageInterval,
                arrived: false,
            });
        };
        let request = mavstack_services::stream::request_data_stream(self.target(), group, hz);
        self.send(&MavMessage::RequestDataStream(request)).await?;
        let arrived = self.comes(msg_id, wait).await;
        Ok(RateRequest {
            how: RateMethod::DataStream(group),
            arrived,
        })
    }

    /// Remembers the rate of `msg_id` (replacing an earlier one) and starts the keeper if
    /// it does not run yet.
    pub(super) fn keep_rate(&self, msg_id: u32, hz: f32) {
        let start = {
            let mut kept = lock(&self.inner.rates);
            kept.rates.retain(|r| r.id != msg_id);
            kept.rates.push(KeptRate {
                id: msg_id,
                hz: sane(hz),
                asked: Instant::now(),
            });
            !core::mem::replace(&mut kept.keeper, true)
        };
        if start {
            self.spawn(keep(Arc::downgrade(&self.inner)));
        }
    }

    /// Forgets the rate of `msg_id` (it is not asked for again after a restart).
    pub(super) fn forget_rate(&self, msg_id: u32) {
        lock(&self.inner.rates).rates.retain(|r| r.id != msg_id);
    }
}

/// The keeper: every second, asks again for each kept message that stopped while the
/// vehicle lives on.
async fn keep(inner: Weak<Inner>) {
    loop {
        tokio::time::sleep(KEEPER_TICK).await;
        let Some(inner) = inner.upgrade() else { return };
        let system = System { inner };
        let now = Instant::now();
        let due: Vec<KeptRate> = {
            let state = system.state();
            if state.stopped {
                return;
            }
            let alive = state
                .heartbeat
                .as_ref()
                .is_some_and(|(_, at)| now.duration_since(*at) < ALIVE);
            if !alive {
                continue;
            }
            lock(&system.inner.rates)
                .rates
                .iter()
                .filter(|r| {
                    let limit = stall(r.hz);
                    let quiet = state
                        .last_seen
                        .get(&r.id)
                        .is_none_or(|&t| now.duration_since(t) > limit);
                    quiet && now.duration_since(r.asked) > limit
                })
                .copied()
                .collect()
        };
        for rate in due {
            tracing::info!(
                target: "mavstack::system",
                "{} stopped sending {}: asking for {} Hz again",
                system.target(),
                crate::message_name(rate.id),
                rate.hz
            );
            if let Some(r) = lock(&system.inner.rates)
                .rates
                .iter_mut()
                .find(|r| r.id == rate.id)
            {
                r.asked = Instant::now();
            }
            if matches!(
                system.ask_rate(rate.id, rate.hz).await,
                Err(SystemError::Stopped)
            ) {
                return;
            }
        }
    }
}
