//! [`Telemetry`]: what a system sends — typed streams of its messages, rates asked for and
//! kept across its restarts, and what the latest messages say (home, position, armed, in
//! the air).

use core::marker::PhantomData;
use core::time::Duration;

use mavstack_core::Message;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{GlobalPositionInt, HomePosition, MavLandedState};
use mavstack_services::Address;

use super::{RateRequest, System, SystemError};
use crate::node::Subscription;

/// Where a system is, from its GLOBAL_POSITION_INT.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct Position {
    /// Latitude (degrees).
    pub lat_deg: f64,
    /// Longitude (degrees).
    pub lon_deg: f64,
    /// Height above home (m).
    pub height_m: f32,
    /// Altitude above mean sea level (m).
    pub alt_m: f32,
}

impl Position {
    /// The position a GLOBAL_POSITION_INT gives.
    #[must_use]
    pub fn of(p: &GlobalPositionInt) -> Self {
        Self {
            lat_deg: f64::from(p.lat) * 1e-7,
            lon_deg: f64::from(p.lon) * 1e-7,
            height_m: p.relative_alt as f32 / 1000.0,
            alt_m: p.alt as f32 / 1000.0,
        }
    }
}

/// The telemetry of a system (from [`System::telemetry`]).
#[derive(Clone, Debug)]
pub struct Telemetry {
    system: System,
}

impl Telemetry {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// Messages `T` from this system from now on, decoded (see [`TelemetryStream`]).
    pub async fn subscribe<T: Message>(&self) -> TelemetryStream<T> {
        TelemetryStream {
            frames: self.system.frames().await,
            system: self.system.target().system,
            message: PhantomData,
        }
    }

    /// Asks the system to send message `msg_id` `hz` times a second, and checks that it
    /// comes: SET_MESSAGE_INTERVAL first; where the system refuses it, or accepts it and the
    /// message still does not come within a few of its intervals (at least 1.5 s), the older
    /// REQUEST_DATA_STREAM for the group that carries it (ArduPilot before 4.0, some links).
    /// The rate is kept: when the message stops while the system lives on (it restarted
    /// and forgot), it is asked for again, as long as a handle of the system lives.
    ///
    /// # Errors
    /// [`SystemError::Stopped`]; a system that sends the message neither way is not an error
    /// ([`RateRequest::arrived`] is false).
    pub async fn request_rate(&self, msg_id: u32, hz: f32) -> Result<RateRequest, SystemError> {
        self.system.keep_rate(msg_id, hz);
        self.system.ask_rate(msg_id, hz).await
    }

    /// Stops message `msg_id` (SET_MESSAGE_INTERVAL -1) and forgets its kept rate.
    ///
    /// # Errors
    /// As [`Commands::send`](super::Commands::send).
    pub async fn stop_rate(&self, msg_id: u32) -> Result<(), SystemError> {
        self.system.forget_rate(msg_id);
        self.system
            .commands()
            .set_message_interval(msg_id, None)
            .await
            .map(drop)
    }

    /// Its home: the HOME_POSITION seen, or else asked for once with REQUEST_MESSAGE and
    /// awaited up to `wait`; `None` when it never came.
    pub async fn home(&self, wait: Duration) -> Option<HomePosition> {
        if let Some(home) = self.system.state().home {
            return Some(home);
        }
        self.system.request_once(HomePosition::ID).await;
        self.system.wait_state(wait, |s| s.home.is_some()).await;
        self.system.state().home
    }

    /// Its home altitude above mean sea level (m): the known one (HOME_POSITION, or
    /// GLOBAL_POSITION_INT's altitude less its height above home), or else HOME_POSITION and
    /// GLOBAL_POSITION_INT asked for once and awaited up to `wait`; `None` when neither
    /// came. A vehicle that streams nothing until asked (ArduPilot) still answers.
    pub async fn home_amsl(&self, wait: Duration) -> Option<f32> {
        if let Some(h) = self.system.state().home_amsl {
            return Some(h);
        }
        for id in [HomePosition::ID, GlobalPositionInt::ID] {
            self.system.request_once(id).await;
        }
        self.system
            .wait_state(wait, |s| s.home_amsl.is_some())
            .await;
        self.system.state().home_amsl
    }

    /// Where it is: its latest GLOBAL_POSITION_INT, or else one asked for and awaited up to
    /// `wait`; `None` when none came.
    pub async fn position(&self, wait: Duration) -> Option<Position> {
        if self.system.state().position.is_none() {
            self.system.request_once(GlobalPositionInt::ID).await;
            self.system.wait_state(wait, |s| s.position.is_some()).await;
        }
        self.system.state().position.as_ref().map(Position::of)
    }

    /// Its latest GLOBAL_POSITION_INT as a [`Position`], without asking.
    #[must_use]
    pub fn last_position(&self) -> Option<Position> {
        self.system.state().position.as_ref().map(Position::of)
    }

    /// Whether its latest HEARTBEAT says it is armed.
    #[must_use]
    pub fn armed(&self) -> bool {
        self.system.armed()
    }

    /// Whether it is in the air: EXTENDED_SYS_STATE's landed state where it sends one, else
    /// armed and more than 0.5 m above home.
    #[must_use]
    pub fn in_air(&self) -> bool {
        let state = self.system.state();
        match state.landed {
            Some(l) if l != MavLandedState::UNDEFINED => {
                matches!(
                    l,
                    MavLandedState::IN_AIR | MavLandedState::TAKEOFF | MavLandedState::LANDING
                )
            }
            _ => {
                state.armed().unwrap_or(false)
                    && state.position.is_some_and(|p| p.relative_alt > 500)
            }
        }
    }
}

/// One message of a [`TelemetryStream`].
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct Sample<T> {
    /// The sending component.
    pub from: Address,
    /// Its framing.
    pub version: Version,
    /// Its sequence number.
    pub seq: u8,
    /// The message.
    pub message: T,
}

/// Messages of type `T` from one system (from [`Telemetry::subscribe`]): a bounded queue
/// like the node's subscriptions, read with [`recv`](Self::recv) or as a
/// [`Stream`](futures_core::Stream) of [`Sample`]s; dropping it unsubscribes.
#[derive(Debug)]
pub struct TelemetryStream<T> {
    frames: Subscription,
    system: u8,
    message: PhantomData<fn() -> T>,
}

impl<T: Message> TelemetryStream<T> {
    /// The next one; `None` once the node has stopped.
    pub async fn recv(&mut self) -> Option<Sample<T>> {
        core::future::poll_fn(|cx| self.poll_sample(cx)).await
    }

    fn poll_sample(
        &mut self,
        cx: &mut core::task::Context<'_>,
    ) -> core::task::Poll<Option<Sample<T>>> {
        use core::task::Poll;
        loop {
            let incoming = match self.frames.poll_recv(cx) {
                Poll::Ready(Some(incoming)) => incoming,
                Poll::Ready(None) => return Poll::Ready(None),
                Poll::Pending => return Poll::Pending,
            };
            let f = incoming.frame.frame.view();
            if f.msg_id() == T::ID && f.sysid() == self.system {
                return Poll::Ready(Some(Sample {
                    from: Address::new(f.sysid(), f.compid()),
                    version: f.version(),
                    seq: f.seq(),
                    message: T::decode(f.payload()),
                }));
            }
        }
    }
}

impl<T: Message> futures_core::Stream for TelemetryStream<T> {
    type Item = Sample<T>;

    fn poll_next(
        self: core::pin::Pin<&mut Self>,
        cx: &mut core::task::Context<'_>,
    ) -> core::task::Poll<Option<Sample<T>>> {
        self.get_mut().poll_sample(cx)
    }
}
