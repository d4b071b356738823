//! Message rates and one-shot requests (the topic side of MAVLink).
//!
//! **Server** ([`StreamScheduler`]): the vehicle's table of which messages it streams at
//! which interval. It answers MAV_CMD_SET_MESSAGE_INTERVAL (511) and
//! MAV_CMD_REQUEST_MESSAGE (512) when its [`StreamScheduler::handle_command`] is called from
//! the vehicle's [`CommandHandler`], and says when each
//! message is due ([`StreamScheduler::poll_due`]); the vehicle builds the message itself,
//! since only it knows the values. REQUEST_MESSAGE(MESSAGE_INTERVAL 244, id) and
//! MAV_CMD_GET_MESSAGE_INTERVAL (510) are answered by the scheduler directly
//! ([`StreamScheduler::poll_transmit`]).
//!
//! [`StreamServer`] puts a scheduler, its commands and a [`MessageSource`] together into one
//! [`Service`], ready to run on a node.
//!
//! **Client**: [`set_message_interval`] and [`request_message`] build the commands to send
//! with a [`CommandClient`](crate::command::CommandClient), and [`Subscriptions`] hands out
//! the messages of the types subscribed to, with a measured rate per source.
//!
//! ```
//! use core::time::Duration;
//! use mavstack_core::time::Instant;
//! use mavstack_services::stream::{Interval, StreamScheduler};
//!
//! let mut s = StreamScheduler::new();
//! s.support(0, Some(Duration::from_secs(1))); // HEARTBEAT at 1 Hz by default
//! s.support(30, None); // ATTITUDE, off until asked for
//! s.set_interval(Instant::ZERO, 30, Interval::Every(Duration::from_millis(100))).unwrap();
//! let due: Vec<u32> = core::iter::from_fn(|| s.poll_due(Instant::ZERO)).map(|d| d.msg_id).collect();
//! assert_eq!(due, [0, 30]);
//! assert_eq!(s.poll_timeout(), Some(Instant::from_millis(100)));
//! ```

use alloc::collections::{BTreeMap, VecDeque};
use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    Attitude, BatteryStatus, CommandLong, DistanceSensor, ExtendedSysState, GlobalPositionInt,
    GpsRawInt, LocalPositionNed, MavCmd, MavDataStream, MavMessage, MavResult, MessageInterval,
    MissionCurrent, NavControllerOutput, PowerStatus, RawImu, RcChannels, RcChannelsRaw,
    RequestDataStream, ScaledImu2, ScaledPressure, ServoOutputRaw, SysStatus, SystemTime, VfrHud,
    Vibration,
};

use crate::command::{
    Command, CommandHandler, CommandServer, CommandServerConfig, CommandServerEvent, Request,
    Response,
};
use crate::{Address, Outgoing, Service};

/// The id of MESSAGE_INTERVAL, which REQUEST_MESSAGE uses to query a rate.
const MESSAGE_INTERVAL_ID: u32 = 244;

/// A stream's rate as SET_MESSAGE_INTERVAL's param2 encodes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interval {
    /// Off (−1).
    Disabled,
    /// The vehicle's default rate (0), which may be off.
    Default,
    /// Every this long (> 0 µs).
    Every(Duration),
}

impl Interval {
    /// From param2 (µs; −1 off, 0 default; other negatives are off).
    #[must_use]
    pub fn from_param(us: f32) -> Self {
        if us == 0.0 {
            Self::Default
        } else if us.is_nan() || us < 0.0 {
            Self::Disabled
        } else {
            Self::Every(Duration::from_micros(us as u64))
        }
    }

    /// As param2.
    #[must_use]
    pub fn to_param(self) -> f32 {
        match self {
            Self::Disabled => -1.0,
            Self::Default => 0.0,
            Self::Every(d) => d.as_micros() as f32,
        }
    }
}

/// Why [`StreamScheduler::set_interval`] refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum StreamError {
    /// The vehicle does not produce this message.
    #[error("message id {msg_id} is not supported")]
    Unsupported {
        /// The message id.
        msg_id: u32,
    },
}

/// A message the vehicle should send now.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Due {
    /// Its id.
    pub msg_id: u32,
    /// Whom to send it to: broadcast for streams, the requester for a one-shot request
    /// that asked for it (param7 = 1).
    pub target: Address,
    /// Params 2–6 of a one-shot REQUEST_MESSAGE (message-specific, e.g. an index); zero for
    /// streams.
    pub params: [f32; 5],
}

#[derive(Debug)]
struct Stream {
    default: Option<Duration>,
    interval: Option<Duration>,
    next: Instant,
}

/// The server side: which messages stream at which interval, and one-shot requests.
#[derive(Debug, Default)]
pub struct StreamScheduler {
    streams: BTreeMap<u32, Stream>,
    one_shots: VecDeque<Due>,
    out: VecDeque<Outgoing>,
}

impl StreamScheduler {
    /// An empty scheduler (no message supported).
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Declares that the vehicle can produce `msg_id`, streamed at `default` (`None`: off
    /// until asked for).
    pub fn support(&mut self, msg_id: u32, default: Option<Duration>) {
        self.streams.insert(
            msg_id,
            Stream {
                default,
                interval: default,
                next: Instant::ZERO,
            },
        );
    }

    /// The interval `msg_id` streams at now (`None`: off or unsupported).
    #[must_use]
    pub fn interval(&self, msg_id: u32) -> Option<Duration> {
        self.streams.get(&msg_id).and_then(|s| s.interval)
    }

    /// Changes the interval of `msg_id`; the first message goes out at once.
    ///
    /// # Errors
    ///
    /// [`StreamError::Unsupported`] for a message not declared with
    /// [`StreamScheduler::support`].
    pub fn set_interval(
        &mut self,
        now: Instant,
        msg_id: u32,
        interval: Interval,
    ) -> Result<(), StreamError> {
        let s = self
            .streams
            .get_mut(&msg_id)
            .ok_or(StreamError::Unsupported { msg_id })?;
        s.interval = match interval {
            Interval::Disabled => None,
            Interval::Default => s.default,
            Interval::Every(d) => Some(d.max(Duration::from_micros(1))),
        };
        s.next = now;
        Ok(())
    }

    /// Answers SET_MESSAGE_INTERVAL, REQUEST_MESSAGE and GET_MESSAGE_INTERVAL; `None` for any
    /// other command (so a vehicle's handler can try it first and fall through).
    pub fn handle_command(&mut self, now: Instant, request: &Request) -> Option<Response> {
        let (p1, p2, p3, p4, p5, p6, p7) = match &request.command {
            Command::Long(c) => (
                c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7,
            ),
            Command::Int(c) => (
                c.param1, c.param2, c.param3, c.param4, c.x as f32, c.y as f32, c.z,
            ),
        };
        let msg_id = if p1.is_finite() && p1 >= 0.0 {
            p1 as u32
        } else {
            u32::MAX
        };
        let target = if p7 == 1.0 {
            request.from
        } else {
            Address::BROADCAST
        };
        Some(match request.command.id() {
            MavCmd::SET_MESSAGE_INTERVAL => {
                match self.set_interval(now, msg_id, Interval::from_param(p2)) {
                    Ok(()) => Response::done(MavResult::ACCEPTED),
                    Err(_) => Response::done(MavResult::DENIED),
                }
            }
            MavCmd::REQUEST_MESSAGE if msg_id == MESSAGE_INTERVAL_ID => {
                let of = if p2.is_finite() && p2 >= 0.0 {
                    p2 as u32
                } else {
                    u32::MAX
                };
                self.tell_interval(of, target);
                Response::done(MavResult::ACCEPTED)
            }
            // The older query (deprecated for REQUEST_MESSAGE, still what PX4 answers): the
            // id in param1, MESSAGE_INTERVAL to the one who asked.
            MavCmd::GET_MESSAGE_INTERVAL => {
                self.tell_interval(msg_id, request.from);
                Response::done(MavResult::ACCEPTED)
            }
            MavCmd::REQUEST_MESSAGE => {
                if self.streams.contains_key(&msg_id) {
                    self.one_shots.push_back(Due {
                        msg_id,
                        target,
                        params: [p2, p3, p4, p5, p6],
                    });
                    Response::done(MavResult::ACCEPTED)
                } else {
                    Response::done(MavResult::DENIED)
                }
            }
            _ => return None,
        })
    }

    /// The next message due at `now`: one-shot requests first, then streams in id order
    /// (each stream's next time advances by its interval). Call until `None` whenever
    /// [`StreamScheduler::poll_timeout`] has passed and after every command.
    #[must_use]
    pub fn poll_due(&mut self, now: Instant) -> Option<Due> {
        if let Some(d) = self.one_shots.pop_front() {
            return Some(d);
        }
        let (&msg_id, s) = self
            .streams
            .iter_mut()
            .find(|(_, s)| s.interval.is_some() && s.next <= now)?;
        let every = s.interval?;
        let next = s.next + every;
        // Keep the cadence; after a stall, restart it from now rather than bursting.
        s.next = if next > now { next } else { now + every };
        Some(Due {
            msg_id,
            target: Address::BROADCAST,
            params: [0.0; 5],
        })
    }

    /// When the next stream message is due (`now` or earlier if one-shots wait).
    #[must_use]
    pub fn poll_timeout(&self) -> Option<Instant> {
        if !self.one_shots.is_empty() {
            return Some(Instant::ZERO);
        }
        self.streams
            .values()
            .filter(|s| s.interval.is_some())
            .map(|s| s.next)
            .min()
    }

    /// Queues MESSAGE_INTERVAL for message `of` (0 µs: not sent by this scheduler; -1: off).
    fn tell_interval(&mut self, of: u32, target: Address) {
        let interval_us = match self.streams.get(&of) {
            None => 0,
            Some(s) => s
                .interval
                .map_or(-1, |d| i32::try_from(d.as_micros()).unwrap_or(i32::MAX)),
        };
        self.out.push_back(Outgoing {
            target,
            message: MavMessage::MessageInterval(MessageInterval {
                message_id: u16::try_from(of).unwrap_or(u16::MAX),
                interval_us,
            }),
        });
    }

    /// Replies the scheduler builds itself (MESSAGE_INTERVAL). Call until `None` after
    /// every command.
    #[must_use]
    pub fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }
}

/// Builds the messages a [`StreamServer`] sends: the one `due` asks for, from the
/// component's current state, or `None` when there is nothing to say yet (no fix, say).
///
/// Closures `FnMut(Instant, &Due) -> Option<MavMessage>` are sources.
pub trait MessageSource {
    /// The message for `due` at `now`.
    fn message(&mut self, now: Instant, due: &Due) -> Option<MavMessage>;
}

impl<F: FnMut(Instant, &Due) -> Option<MavMessage>> MessageSource for F {
    fn message(&mut self, now: Instant, due: &Due) -> Option<MavMessage> {
        self(now, due)
    }
}

/// A [`CommandHandler`] that supports nothing (every command is answered UNSUPPORTED): the
/// default for the other commands of a [`StreamServer`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoCommands;

impl CommandHandler for NoCommands {
    fn handle_command(&mut self, _now: Instant, _request: &Request) -> Response {
        Response::done(MavResult::UNSUPPORTED)
    }
}

/// The scheduler answering its two commands first, every other one handed to `H`.
#[derive(Debug)]
struct StreamCommands<H> {
    scheduler: StreamScheduler,
    others: H,
}

impl<H: CommandHandler> CommandHandler for StreamCommands<H> {
    fn handle_command(&mut self, now: Instant, request: &Request) -> Response {
        self.scheduler
            .handle_command(now, request)
            .unwrap_or_else(|| self.others.handle_command(now, request))
    }
}

/// Message-interval streams as a whole [`Service`], for a component that publishes
/// telemetry (a companion computer, a peripheral, a vehicle): a [`StreamScheduler`] behind a
/// [`CommandServer`] (SET_MESSAGE_INTERVAL and REQUEST_MESSAGE answered, every other
/// command handed to `H`, [`NoCommands`] by default, so one component has one command
/// server), and a [`MessageSource`] that builds each message when it is due.
///
/// ```
/// use mavstack_core::Message as _;
/// use mavstack_core::time::Instant;
/// use mavstack_dialects::common::{CommandLong, DistanceSensor, MavCmd, MavMessage};
/// use mavstack_services::stream::{Due, StreamServer};
/// use mavstack_services::{Address, Service};
///
/// let own = Address::new(1, 158);
/// let mut range = StreamServer::new(own, |_now: Instant, _due: &Due| {
///     Some(MavMessage::DistanceSensor(DistanceSensor { current_distance: 412, ..Default::default() }))
/// });
/// range.support(DistanceSensor::ID, None); // off until a ground station asks
/// let ask = MavMessage::CommandLong(CommandLong {
///     target_system: 1,
///     target_component: 158,
///     command: MavCmd::SET_MESSAGE_INTERVAL,
///     param1: DistanceSensor::ID as f32,
///     param2: 200_000.0, // every 200 ms
///     ..Default::default()
/// });
/// range.handle_message(Instant::ZERO, Address::new(255, 190), &ask);
/// let sent: Vec<_> = core::iter::from_fn(|| range.poll_transmit()).map(|o| o.message).collect();
/// assert!(matches!(&sent[..], [MavMessage::CommandAck(_), MavMessage::DistanceSensor(_)]));
/// assert_eq!(range.poll_timeout(), Some(Instant::from_millis(200)));
/// ```
#[derive(Debug)]
pub struct StreamServer<S, H = NoCommands> {
    commands: CommandServer<StreamCommands<H>>,
    source: S,
    out: VecDeque<Outgoing>,
}

impl<S: MessageSource> StreamServer<S> {
    /// A server for component `own` whose messages `source` builds; no stream supported
    /// yet ([`StreamServer::support`]), no other command.
    #[must_use]
    pub fn new(own: Address, source: S) -> Self {
        Self::with_commands(own, source, NoCommands)
    }
}

impl<S: MessageSource, H: CommandHandler> StreamServer<S, H> {
    /// A server whose commands other than SET_MESSAGE_INTERVAL and REQUEST_MESSAGE go to
    /// `others`.
    #[must_use]
    pub fn with_commands(own: Address, source: S, others: H) -> Self {
        let handler = StreamCommands {
            scheduler: StreamScheduler::new(),
            others,
        };
        Self {
            commands: CommandServer::new(own, CommandServerConfig::default(), handler),
            source,
            out: VecDeque::new(),
        }
    }

    /// Declares that the component produces `msg_id`, streamed at `default` (`None`: off
    /// until asked for).
    pub fn support(&mut self, msg_id: u32, default: Option<Duration>) {
        self.commands
            .handler_mut()
            .scheduler
            .support(msg_id, default);
    }

    /// The scheduler (intervals in force).
    pub fn scheduler(&self) -> &StreamScheduler {
        &self.commands.handler().scheduler
    }

    /// The scheduler, mutably (to set intervals locally).
    pub fn scheduler_mut(&mut self) -> &mut StreamScheduler {
        &mut self.commands.handler_mut().scheduler
    }

    /// The source.
    pub fn source(&self) -> &S {
        &self.source
    }

    /// The source, to update the state it builds messages from.
    pub fn source_mut(&mut self) -> &mut S {
        &mut self.source
    }

    /// The handler of the other commands.
    pub fn commands_mut(&mut self) -> &mut H {
        &mut self.commands.handler_mut().others
    }

    /// The command server's next event (commands run, duplicates answered).
    #[must_use]
    pub fn poll_event(&mut self) -> Option<CommandServerEvent> {
        self.commands.poll_event()
    }

    /// Builds every message due at `now` and queues the scheduler's own replies.
    fn produce(&mut self, now: Instant) {
        let handler = self.commands.handler_mut();
        while let Some(o) = handler.scheduler.poll_transmit() {
            self.out.push_back(o);
        }
        while let Some(due) = handler.scheduler.poll_due(now) {
            if let Some(message) = self.source.message(now, &due) {
                self.out.push_back(Outgoing {
                    target: due.target,
                    message,
                });
            }
        }
    }
}

impl<S: MessageSource, H: CommandHandler> Service for StreamServer<S, H> {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let used = self.commands.handle_message(now, from, message);
        if used {
            self.produce(now);
        }
        used
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.commands.handle_timeout(now);
        self.produce(now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        // The ACK goes before what it started.
        self.commands
            .poll_transmit()
            .or_else(|| self.out.pop_front())
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.commands.handler().scheduler.poll_timeout()
    }
}

/// MAV_CMD_SET_MESSAGE_INTERVAL for `msg_id` (response target: the stack's default).
#[must_use]
pub fn set_message_interval(msg_id: u32, interval: Interval) -> Command {
    Command::Long(CommandLong {
        command: MavCmd::SET_MESSAGE_INTERVAL,
        param1: msg_id as f32,
        param2: interval.to_param(),
        ..CommandLong::default()
    })
}

/// MAV_CMD_REQUEST_MESSAGE for `msg_id` with message-specific params 2–6, answered to the
/// requester (param7 = 1).
#[must_use]
pub fn request_message(msg_id: u32, params: [f32; 5]) -> Command {
    Command::Long(CommandLong {
        command: MavCmd::REQUEST_MESSAGE,
        param1: msg_id as f32,
        param2: params[0],
        param3: params[1],
        param4: params[2],
        param5: params[3],
        param6: params[4],
        param7: 1.0,
        ..CommandLong::default()
    })
}

/// REQUEST_DATA_STREAM's groups as ArduPilot fills them (the messages of the `common`
/// dialect among them): the older way to ask for telemetry, which ArduPilot before 4.0 and
/// some links need where SET_MESSAGE_INTERVAL is refused or ignored. A group's rate applies to
/// all its messages.
#[must_use]
pub fn data_stream_members(group: MavDataStream) -> &'static [u32] {
    match group {
        MavDataStream::RAW_SENSORS => &[RawImu::ID, ScaledImu2::ID, ScaledPressure::ID],
        MavDataStream::EXTENDED_STATUS => &[
            SysStatus::ID,
            PowerStatus::ID,
            MissionCurrent::ID,
            GpsRawInt::ID,
            NavControllerOutput::ID,
        ],
        MavDataStream::RC_CHANNELS => &[ServoOutputRaw::ID, RcChannels::ID, RcChannelsRaw::ID],
        MavDataStream::POSITION => &[GlobalPositionInt::ID, LocalPositionNed::ID],
        MavDataStream::EXTRA1 => &[Attitude::ID],
        MavDataStream::EXTRA2 => &[VfrHud::ID],
        MavDataStream::EXTRA3 => &[
            SystemTime::ID,
            BatteryStatus::ID,
            DistanceSensor::ID,
            Vibration::ID,
            ExtendedSysState::ID,
        ],
        _ => &[],
    }
}

/// The REQUEST_DATA_STREAM group that carries `msg_id` ([`data_stream_members`]).
#[must_use]
pub fn data_stream_of(msg_id: u32) -> Option<MavDataStream> {
    [
        MavDataStream::RAW_SENSORS,
        MavDataStream::EXTENDED_STATUS,
        MavDataStream::RC_CHANNELS,
        MavDataStream::POSITION,
        MavDataStream::EXTRA1,
        MavDataStream::EXTRA2,
        MavDataStream::EXTRA3,
    ]
    .into_iter()
    .find(|g| data_stream_members(*g).contains(&msg_id))
}

/// REQUEST_DATA_STREAM starting `group` at `hz` (at least 1) for `target`.
#[must_use]
pub fn request_data_stream(target: Address, group: MavDataStream, hz: f32) -> RequestDataStream {
    RequestDataStream {
        target_system: target.system,
        target_component: target.component,
        req_stream_id: group,
        req_message_rate: if hz.is_finite() {
            hz.round().clamp(1.0, 1000.0) as u16
        } else {
            1
        },
        start_stop: 1,
    }
}

/// Names one subscription.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SubscriptionId(u32);

/// A message of a subscribed type.
#[derive(Clone, Debug, PartialEq)]
pub struct Delivery {
    /// The subscription it matched.
    pub subscription: SubscriptionId,
    /// Who sent it.
    pub from: Address,
    /// The message.
    pub message: MavMessage,
}

#[derive(Debug)]
struct Rate {
    last: Instant,
    /// Smoothed interval between arrivals, in µs.
    mean_us: Option<f64>,
}

/// The client side of the topic model: subscriptions to message types, with a measured
/// rate per (source, type).
#[derive(Debug, Default)]
pub struct Subscriptions {
    next: u32,
    subs: BTreeMap<SubscriptionId, (Option<Address>, u32)>,
    rates: BTreeMap<(Address, u32), Rate>,
    deliveries: VecDeque<Delivery>,
}

impl Subscriptions {
    /// No subscriptions.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Subscribes to messages with id `msg_id`, from `from` only or from anyone.
    pub fn subscribe(&mut self, msg_id: u32, from: Option<Address>) -> SubscriptionId {
        let id = SubscriptionId(self.next);
        self.next = self.next.wrapping_add(1);
        self.subs.insert(id, (from, msg_id));
        id
    }

    /// Ends a subscription. Returns whether it existed.
    pub fn unsubscribe(&mut self, id: SubscriptionId) -> bool {
        self.subs.remove(&id).is_some()
    }

    /// Feeds one received message; queues a [`Delivery`] per matching subscription and
    /// updates the measured rate. Returns whether any subscription matched.
    pub fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        use mavstack_core::MessageSet;
        let msg_id = message.id();
        let mut matched = false;
        for (&subscription, &(who, id)) in &self.subs {
            if id == msg_id && who.is_none_or(|w| from.is_reached_by(w)) {
                matched = true;
                self.deliveries.push_back(Delivery {
                    subscription,
                    from,
                    message: message.clone(),
                });
            }
        }
        if matched {
            let rate = self.rates.entry((from, msg_id)).or_insert(Rate {
                last: now,
                mean_us: None,
            });
            if now > rate.last {
                let gap = (now - rate.last).as_micros() as f64;
                rate.mean_us = Some(rate.mean_us.map_or(gap, |m| m + (gap - m) / 8.0));
                rate.last = now;
            }
        }
        matched
    }

    /// The measured rate of `msg_id` from `from` in Hz (smoothed over the last few
    /// arrivals), once two have arrived.
    #[must_use]
    pub fn rate_hz(&self, from: Address, msg_id: u32) -> Option<f64> {
        self.rates
            .get(&(from, msg_id))?
            .mean_us
            .filter(|&m| m > 0.0)
            .map(|m| 1e6 / m)
    }

    /// The next delivery, if any. Call until `None` after every message.
    #[must_use]
    pub fn poll_delivery(&mut self) -> Option<Delivery> {
        self.deliveries.pop_front()
    }
}
