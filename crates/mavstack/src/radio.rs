//! [`RadioBridge`]: a semi-transparent radio between two connections, in-process — what a
//! SiK or RFD900 pair does between a ground station and a vehicle: every frame forwarded
//! unchanged in both directions, and the radio's own RADIO_STATUS injected, in MAVLink 1
//! until the first MAVLink 2 frame has passed it, in MAVLink 2 from then on (the versions
//! document's rule for semi-transparent radios).
//!
//! A radio is a bump in the wire, not a MAVLink component: it has no routes, no versions of
//! its own per link and no services, so it is not a [`Node`](crate::Node); the sans-IO state
//! is [`mavstack_channel::Radio`], and this task only moves its bytes.
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::channel::RadioConfig;
//! use mavstack::radio::{RadioBridge, RadioNotice};
//! let ground = "udpin:127.0.0.1:14550".parse()?;
//! let vehicle = "udpout:127.0.0.1:14555".parse()?;
//! let radio = RadioBridge::start(&ground, &vehicle, RadioConfig::default(), |n: &RadioNotice| {
//!     println!("{n}");
//! })
//! .await?;
//! // ... the ground station and the vehicle talk through it ...
//! let stats = radio.stop().await?;
//! println!("{} RADIO_STATUS injected", stats.injected);
//! # Ok(()) }
//! ```

use core::fmt;
use core::net::SocketAddr;
use core::time::Duration;

use mavstack_channel::{Radio, RadioConfig, RadioEvent, RadioStats, Side};
use mavstack_core::wire::{MAX_FRAME_LEN, Version};
use mavstack_dialects::common::MavMessage;
use mavstack_transport::{
    ConnSpec, Connection, FrameBuf, FrameCommand, FrameEvent, FrameProtocol, LinkError, OpenError,
    SendError, clock,
};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// One side of the radio: frames of any id, forwarded as they are.
type RadioSide = Connection<FrameProtocol>;

/// What a [`RadioBridge`] reports as it runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum RadioNotice {
    /// The first MAVLink 2 frame passed, from side `from` (A: the ground station's).
    FirstMavlink2 {
        /// The side it came from.
        from: Side,
    },
    /// The radio's RADIO_STATUS goes out in `version` from now on (its first one, then the
    /// switch), every `interval`.
    StatusFraming {
        /// The framing.
        version: Version,
        /// The time between two RADIO_STATUS.
        interval: Duration,
    },
}

impl fmt::Display for RadioNotice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::FirstMavlink2 { from } => write!(
                f,
                "radio: first MAVLink 2 frame (from side {from:?}); RADIO_STATUS in MAVLink 2 from now on"
            ),
            Self::StatusFraming { version, interval } => write!(
                f,
                "radio → RADIO_STATUS ({}), every {interval:?}",
                match version {
                    Version::V1 => "MAVLink 1",
                    Version::V2 => "MAVLink 2",
                }
            ),
        }
    }
}

/// Why a [`RadioBridge`] could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RadioError {
    /// A side's connection could not be opened.
    #[error("radio side {side:?}: {source}")]
    Open {
        /// The side.
        side: Side,
        /// The transport's reason.
        #[source]
        source: OpenError,
    },
    /// Writing to a side failed.
    #[error("radio side {side:?}: {source}")]
    Send {
        /// The side.
        side: Side,
        /// The transport's reason.
        #[source]
        source: SendError,
    },
    /// Closing a side failed.
    #[error("radio side {side:?}: {source}")]
    Link {
        /// The side.
        side: Side,
        /// The transport's reason.
        #[source]
        source: LinkError,
    },
    /// The radio's task ended abnormally.
    #[error("the radio's task failed: {0}")]
    Task(String),
}

/// A semi-transparent radio running in a task of its own (see the [module](self)).
#[derive(Debug)]
pub struct RadioBridge {
    task: JoinHandle<Result<RadioStats, RadioError>>,
    stop: oneshot::Sender<()>,
    local_addrs: [Option<SocketAddr>; 2],
}

impl RadioBridge {
    /// Opens side A (the ground station's) on `a` and side B (the vehicle's) on `b` and
    /// starts forwarding; `notify` hears each [`RadioNotice`].
    ///
    /// # Errors
    ///
    /// [`RadioError::Open`] when a side cannot be opened.
    pub async fn start(
        a: &ConnSpec,
        b: &ConnSpec,
        config: RadioConfig,
        notify: impl FnMut(&RadioNotice) + Send + 'static,
    ) -> Result<Self, RadioError> {
        let side_a = open_side(a, Side::A).await?;
        let side_b = open_side(b, Side::B).await?;
        let local_addrs = [side_a.local_addr(), side_b.local_addr()];
        let (stop, stopped) = oneshot::channel();
        let task = tokio::spawn(run(side_a, side_b, config, notify, stopped));
        Ok(Self {
            task,
            stop,
            local_addrs,
        })
    }

    /// The local addresses of sides A and B (for a bound UDP or TCP server side).
    #[must_use]
    pub fn local_addrs(&self) -> [Option<SocketAddr>; 2] {
        self.local_addrs
    }

    /// Whether the radio has stopped by itself (a side's connection ended).
    #[must_use]
    pub fn is_finished(&self) -> bool {
        self.task.is_finished()
    }

    /// Forwards until `stop` completes or a side's connection ends, then stops as
    /// [`RadioBridge::stop`] does.
    ///
    /// # Errors
    ///
    /// As [`RadioBridge::stop`].
    pub async fn run_until(
        mut self,
        stop: impl Future<Output = ()>,
    ) -> Result<RadioStats, RadioError> {
        let ended = tokio::select! {
            () = stop => None,
            r = &mut self.task => Some(r),
        };
        match ended {
            None => self.stop().await,
            Some(r) => r.map_err(|e| RadioError::Task(e.to_string()))?,
        }
    }

    /// Stops forwarding, closes both sides and returns the radio's counters.
    ///
    /// # Errors
    ///
    /// [`RadioError::Send`] or [`RadioError::Link`] when a side failed; [`RadioError::Task`] when the task panicked.
    pub async fn stop(self) -> Result<RadioStats, RadioError> {
        let _ = self.stop.send(());
        self.task
            .await
            .map_err(|e| RadioError::Task(e.to_string()))?
    }
}

async fn open_side(spec: &ConnSpec, side: Side) -> Result<RadioSide, RadioError> {
    Connection::open(
        spec,
        FrameProtocol::new(mavstack_core::MessageTable::of::<MavMessage>())
            .keep_unknown(true)
            .peer_events(false),
    )
    .await
    .map_err(|source| RadioError::Open { side, source })
}

async fn run(
    side_a: RadioSide,
    side_b: RadioSide,
    config: RadioConfig,
    mut notify: impl FnMut(&RadioNotice) + Send,
    mut stopped: oneshot::Receiver<()>,
) -> Result<RadioStats, RadioError> {
    let interval = config.interval;
    let mut radio = Radio::new(config);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut status_framing = None;
    let mut side_a = side_a;
    let mut side_b = side_b;
    loop {
        let wake = radio
            .poll_timeout()
            .map(|t| t.as_micros().saturating_sub(clock::now().as_micros()))
            .map_or(Duration::from_secs(1), Duration::from_micros);
        let (side, event) = tokio::select! {
            _ = &mut stopped => break,
            () = tokio::time::sleep(wake) => {
                radio.handle_timeout(clock::now());
                (None, None)
            }
            e = side_a.recv() => (Some(Side::A), e),
            e = side_b.recv() => (Some(Side::B), e),
        };
        if let Some(side) = side {
            let Some(event) = event else { break };
            if let FrameEvent::Frame(f) | FrameEvent::Unknown(f) = event {
                let mut rest = f.frame.as_bytes();
                while !rest.is_empty() {
                    let taken = radio.handle_input(clock::now(), side, rest);
                    rest = &rest[taken..];
                    if taken == 0 {
                        break;
                    }
                }
            }
        }
        while let Some(RadioEvent::FirstMavlink2 { from }) = radio.poll_event() {
            notify(&RadioNotice::FirstMavlink2 { from });
        }
        while let Some(t) = radio.poll_transmit(clock::now(), &mut buf) {
            let Ok(frame) = FrameBuf::new(&buf[..t.len]) else {
                continue;
            };
            if t.injected && status_framing != Some(t.version) {
                status_framing = Some(t.version);
                notify(&RadioNotice::StatusFraming {
                    version: t.version,
                    interval,
                });
            }
            let conn = if t.to == Side::A { &side_a } else { &side_b };
            conn.send(FrameCommand::to_all(frame))
                .await
                .map_err(|source| RadioError::Send { side: t.to, source })?;
        }
    }
    let stats = radio.stats();
    side_a.close().await.map_err(|source| RadioError::Link {
        side: Side::A,
        source,
    })?;
    side_b.close().await.map_err(|source| RadioError::Link {
        side: Side::B,
        source,
    })?;
    Ok(stats)
}
