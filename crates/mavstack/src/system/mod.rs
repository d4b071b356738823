//! [`System`]: a remote MAVLink system as a ground station or companion sees it, through a
//! [`Node`](crate::Node) (feature `services`), with one handle per microservice in
//! MAVSDK's plugin shape: [`params`](System::params), [`mission`](System::mission),
//! [`commands`](System::commands), [`modes`](System::modes), [`action`](System::action),
//! [`offboard`](System::offboard), [`manual_control`](System::manual_control),
//! [`telemetry`](System::telemetry), [`ftp`](System::ftp), [`logs`](System::logs),
//! [`signing`](System::signing), [`rtk`](System::rtk), [`shell`](System::shell),
//! [`gimbals`](System::gimbals) and [`cameras`](System::cameras).
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use core::time::Duration;
//! use mavstack::system::{System, Wanted};
//! use mavstack::LinkSpec;
//! let spec = LinkSpec::parse("udpin:0.0.0.0:14550", &|_| None)?;
//! // The link opened, the first autopilot heard (the MAVLink 2 handshake if it speaks 1).
//! let session = System::connect(spec, Wanted::AnyAutopilot, Duration::from_secs(10)).await?;
//! let vehicle = session.system();
//! let table = vehicle.params().get_all().await?;
//! println!("{} parameters from {}", table.len(), vehicle.target());
//! session.close().await?;
//! # Ok(()) }
//! ```
//!
//! A `System` is a cheap handle: clones share one state, kept by a task that reads what the
//! system sends about itself (HEARTBEAT, home, position, capabilities, mode, what it says)
//! for as long as a clone lives. Every operation runs the `mavstack-services` state machine
//! for it (retries, timeouts, IN_PROGRESS) over the node's link to the system and ends when
//! its future resolves; dropping the future abandons it. Operations of different services
//! run side by side; two of one service (two mission uploads) run one after the other.

use core::sync::atomic::{AtomicU8, Ordering};
use core::time::Duration;
use std::sync::{Arc, Mutex, MutexGuard};

use mavstack_channel::HandshakeOutcome;
use mavstack_core::Message as _;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{
    AutopilotVersion, CommandLong, MavAutopilot, MavCmd, MavMessage, MavProtocolCapability, MavType,
};
use mavstack_router::LinkId;
use mavstack_services::Address;
use mavstack_services::param::Encoding;
use tokio::sync::watch;
use tokio::task::AbortHandle;

mod action;
mod camera;
mod commands;
mod connect;
mod discovery;
mod error;
mod ftp;
mod gimbal;
mod logs;
mod manual;
mod mission;
mod modes;
mod offboard;
mod params;
mod rates;
mod rtk;
mod run;
mod said;
mod shell;
mod signing;
mod state;
mod telemetry;

pub use action::{Action, GOTO_RADIUS_M, MAX_HEIGHT_M, TAKEOFF_REACHED, distance_m};
pub use camera::{Camera, Cameras, SettingView};
pub use commands::{
    CommandOutcome, Commands, FORCE_DISARM, SHORTCUTS, command_id, command_name, result_name,
    to_int,
};
pub use connect::{ConnectOptions, Session};
pub use discovery::Discovery;
pub use error::SystemError;
pub use ftp::{Ftp, FtpPathOp};
pub use gimbal::{Gimbal, GimbalControl, Gimbals};
pub use logs::{FTP_LOG_DIRS, Logs, LogsVia, ftp_log_path};
pub use manual::{ManualControl, ManualSession, Sticks};
pub use mission::Mission;
pub use modes::{Mode, Modes};
pub use offboard::{
    MAX_RATE_HZ, MAX_SPEED, MIN_RATE_HZ, Offboard, OffboardSession, Setpoint, quaternion,
};
pub use params::{
    AUTO_FTP_RETRIES, CAPABILITIES_WAIT, Change, LoadReport, Params, ParamsVia, typed_value,
};
pub use rates::{RateMethod, RateRequest};
pub use rtk::{RtcmReader, RtcmSource, RtcmSourceError, Rtk, RtkReport};
pub use shell::{Shell, ShellSession};
pub use signing::{Signing, SigningCheck};
pub use telemetry::{Position, Sample, Telemetry, TelemetryStream};

use crate::modes::Flavour;
use crate::node::{NodeHandle, Subscription};
use state::State;

/// Retries per message of parameter and mission operations by default: with 10, a 500-item
/// upload over a link that drops 20 % each way fails about once in 150 (with the services'
/// default 3, about once in two).
pub const PATIENT_RETRIES: u8 = 10;

/// How long a check that the vehicle is armed waits for a HEARTBEAT that says so.
const ARMED_WAIT: Duration = Duration::from_millis(2500);

/// How often [`System::capabilities`] asks again for AUTOPILOT_VERSION.
const CAPABILITIES_RESEND: Duration = Duration::from_millis(500);

/// Which system [`System::wait`] and [`System::connect`] wait for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Wanted {
    /// The first HEARTBEAT of an autopilot (not a ground station, not MAV_AUTOPILOT_INVALID).
    AnyAutopilot,
    /// This system; any component, or this one.
    System(u8, Option<u8>),
}

/// A remote system reached through a node's link: a cheap, cloneable handle.
#[derive(Clone, Debug)]
pub struct System {
    inner: Arc<Inner>,
}

/// What every handle of one system shares.
#[derive(Debug)]
struct Inner {
    node: NodeHandle,
    own: Address,
    target: Address,
    /// The router link it was found on.
    link: LinkId,
    link_name: String,
    autopilot: MavAutopilot,
    mav_type: MavType,
    found_in: Version,
    handshake: Option<HandshakeOutcome>,
    /// What the system told about itself, kept by the tracker.
    state: watch::Sender<State>,
    /// The tracker and other tasks of this system: stopped when the last handle goes.
    tasks: Mutex<Vec<AbortHandle>>,
    retries: AtomicU8,
    /// Where the next MAVFTP client starts its sequence numbers.
    ftp_seq: Mutex<u16>,
    /// One operation of each service at a time.
    locks: Locks,
    /// Its event metadata, as far as it is known.
    event_texts: tokio::sync::Mutex<said::EventTexts>,
    /// Its logs as last listed.
    logs: Mutex<Option<Vec<mavstack_services::log_transfer::LogInfo>>>,
    /// The telemetry rates asked for, asked for again after a restart.
    rates: Mutex<rates::Kept>,
}

impl Inner {
    /// Where the system is reached now: see [`System::link`].
    fn link(&self) -> LinkId {
        self.state.borrow().link.unwrap_or(self.link)
    }
}

#[derive(Debug, Default)]
struct Locks {
    params: tokio::sync::Mutex<()>,
    mission: tokio::sync::Mutex<()>,
    ftp: tokio::sync::Mutex<()>,
    logs: tokio::sync::Mutex<()>,
    /// One command exchange at a time; the echo windows of the ACKs taken, from one to the
    /// next (PX4 acknowledges DO_SET_MODE twice: see `mavstack_services::command`).
    commands: tokio::sync::Mutex<mavstack_services::command::AckEchoes>,
    /// The system has one shell.
    shell: tokio::sync::Mutex<()>,
    /// GPS_RTCM_DATA's sequence ids, held while a message's fragments go out.
    rtk: tokio::sync::Mutex<mavstack_services::rtcm::RtcmSender>,
}

impl Drop for Inner {
    fn drop(&mut self) {
        for task in lock(&self.tasks).drain(..) {
            task.abort();
        }
    }
}

/// A std mutex's guard; a lock poisoned by a panic is taken as it is (every update of what
/// these guard is a single assignment).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl System {
    /// Its address (system, and the component that answered or was asked for).
    #[must_use]
    pub fn target(&self) -> Address {
        self.inner.target
    }

    /// Our own address on the link.
    #[must_use]
    pub fn own(&self) -> Address {
        self.inner.own
    }

    /// The autopilot its first HEARTBEAT named.
    #[must_use]
    pub fn autopilot(&self) -> MavAutopilot {
        self.inner.autopilot
    }

    /// The vehicle type its first HEARTBEAT named.
    #[must_use]
    pub fn mav_type(&self) -> MavType {
        self.inner.mav_type
    }

    /// Whose mode numbers it uses, from its HEARTBEAT's autopilot and type (`None` when
    /// they are not known here).
    #[must_use]
    pub fn flavour(&self) -> Option<Flavour> {
        Flavour::of(self.inner.autopilot, self.inner.mav_type)
    }

    /// Its parameter encoding (ArduPilot's C cast, everyone else's bytewise).
    #[must_use]
    pub fn encoding(&self) -> Encoding {
        Encoding::for_autopilot(self.inner.autopilot)
    }

    /// The router link it is reached through: the one its latest HEARTBEAT came in on
    /// (a vehicle that restarted behind a `udpin` link is a new peer there), at first the
    /// one it was found on.
    #[must_use]
    pub fn link(&self) -> LinkId {
        self.inner.link()
    }

    /// The name of that link (its key never appears in it).
    #[must_use]
    pub fn link_name(&self) -> &str {
        &self.inner.link_name
    }

    /// The framing of the HEARTBEAT that found it.
    #[must_use]
    pub fn found_in(&self) -> Version {
        self.inner.found_in
    }

    /// The outcome of the handshake [`wait`](Self::wait) ran, if it ran one.
    #[must_use]
    pub fn handshake(&self) -> Option<&HandshakeOutcome> {
        self.inner.handshake.as_ref()
    }

    /// The node it is reached through.
    #[must_use]
    pub fn node(&self) -> &NodeHandle {
        &self.inner.node
    }

    /// Retries per message of later parameter, mission, MAVFTP and log operations (default
    /// [`PATIENT_RETRIES`]).
    pub fn set_retries(&self, retries: u8) {
        self.inner.retries.store(retries, Ordering::Relaxed);
    }

    fn retries(&self) -> u8 {
        self.inner.retries.load(Ordering::Relaxed)
    }

    /// What the link to the system carries now: `"1"`, `"2"`, `"signed"` or `"auto"` (see
    /// [`LinkReport::version`](crate::LinkReport)); `None` once the node has stopped or the
    /// peer went away.
    pub async fn link_version(&self) -> Option<&'static str> {
        let report = self.inner.node.report().await?;
        report
            .links
            .iter()
            .find(|l| l.link_id == Some(self.inner.link()))
            .map(|l| l.version)
    }

    /// Its parameters.
    #[must_use]
    pub fn params(&self) -> Params {
        Params::new(self.clone())
    }

    /// Its mission, geofence and rally plans.
    #[must_use]
    pub fn mission(&self) -> Mission {
        Mission::new(self.clone())
    }

    /// Commands to it (COMMAND_LONG, COMMAND_INT) and their answers.
    #[must_use]
    pub fn commands(&self) -> Commands {
        Commands::new(self.clone())
    }

    /// Its flight modes.
    #[must_use]
    pub fn modes(&self) -> Modes {
        Modes::new(self.clone())
    }

    /// Flying it: takeoff, land, return home, hold, goto.
    #[must_use]
    pub fn action(&self) -> Action {
        Action::new(self.clone())
    }

    /// Offboard control: a setpoint stream (PX4 OFFBOARD, ArduPilot GUIDED).
    #[must_use]
    pub fn offboard(&self) -> Offboard {
        Offboard::new(self.clone())
    }

    /// Manual control: sticks as MANUAL_CONTROL at a rate.
    #[must_use]
    pub fn manual_control(&self) -> ManualControl {
        ManualControl::new(self.clone())
    }

    /// Its telemetry: typed streams, rates, home and position.
    #[must_use]
    pub fn telemetry(&self) -> Telemetry {
        Telemetry::new(self.clone())
    }

    /// Files on its MAVFTP server.
    #[must_use]
    pub fn ftp(&self) -> Ftp {
        Ftp::new(self.clone())
    }

    /// Its logs (LOG_*).
    #[must_use]
    pub fn logs(&self) -> Logs {
        Logs::new(self.clone())
    }

    /// Message signing with it.
    #[must_use]
    pub fn signing(&self) -> Signing {
        Signing::new(self.clone())
    }

    /// RTK corrections to it (GPS_RTCM_DATA).
    #[must_use]
    pub fn rtk(&self) -> Rtk {
        Rtk::new(self.clone())
    }

    /// Its shell over MAVLink (SERIAL_CONTROL, as PX4's nsh).
    #[must_use]
    pub fn shell(&self) -> Shell {
        Shell::new(self.clone())
    }

    /// Its gimbals (the gimbal protocol v2).
    #[must_use]
    pub fn gimbals(&self) -> Gimbals {
        Gimbals::new(self.clone())
    }

    /// Its cameras (the camera protocol v2).
    #[must_use]
    pub fn cameras(&self) -> Cameras {
        Cameras::new(self.clone())
    }

    // ----- shared by the handles ---------------------------------------------------------

    /// A snapshot of what is known of it.
    fn state(&self) -> watch::Ref<'_, State> {
        self.inner.state.borrow()
    }

    /// Waits up to `wait` for `done` to hold of what is known of it; whether it did.
    async fn wait_state(&self, wait: Duration, mut done: impl FnMut(&State) -> bool) -> bool {
        let mut rx = self.inner.state.subscribe();
        let waited = tokio::time::timeout(wait, rx.wait_for(|s| done(s) || s.stopped)).await;
        matches!(waited, Ok(Ok(s)) if done(&s))
    }

    /// A new subscription to the node's frames (before a request goes out).
    async fn frames(&self) -> Subscription {
        self.inner.node.subscribe().await
    }

    /// Sends one REQUEST_MESSAGE for `id` (no retries, no wait for its answer).
    async fn request_once(&self, id: u32) {
        let target = self.inner.target;
        let request = MavMessage::CommandLong(CommandLong {
            target_system: target.system,
            target_component: target.component,
            command: MavCmd::REQUEST_MESSAGE,
            param1: id as f32,
            ..CommandLong::default()
        });
        self.inner.node.send_on(self.inner.link(), &request).await;
    }

    /// Sends `message` on the system's link; [`SystemError::Stopped`] once the node is gone.
    async fn send(&self, message: &MavMessage) -> Result<(), SystemError> {
        if self.inner.node.send_on(self.inner.link(), message).await == 0 {
            return Err(SystemError::Stopped);
        }
        Ok(())
    }

    /// Runs `task` for as long as a handle of this system lives.
    fn spawn(&self, task: impl Future<Output = ()> + Send + 'static) {
        let handle = tokio::spawn(task).abort_handle();
        let mut tasks = lock(&self.inner.tasks);
        tasks.retain(|t| !t.is_finished());
        tasks.push(handle);
    }

    /// Its capabilities: those of its AUTOPILOT_VERSION once one was seen, or else
    /// AUTOPILOT_VERSION asked for with REQUEST_MESSAGE (again every half second: one
    /// request and its answer through a link losing 20 % each way are both there only two
    /// times in three) and awaited for up to `wait`; `None` when it never came.
    pub async fn capabilities(&self, wait: Duration) -> Option<MavProtocolCapability> {
        let end = tokio::time::Instant::now() + wait;
        loop {
            if let Some(c) = self.state().capabilities {
                return Some(c);
            }
            let left = end.saturating_duration_since(tokio::time::Instant::now());
            if left.is_zero() {
                return None;
            }
            self.request_once(AutopilotVersion::ID).await;
            self.wait_state(left.min(CAPABILITIES_RESEND), |s| s.capabilities.is_some())
                .await;
        }
    }

    /// Whether it is armed, waiting up to [`ARMED_WAIT`] for a HEARTBEAT that says so (an
    /// arming just acknowledged shows in the next HEARTBEAT, up to a second later).
    async fn armed_soon(&self) -> bool {
        self.armed()
            || self
                .wait_state(ARMED_WAIT, |s| s.armed() == Some(true))
                .await
    }

    /// Whether its latest HEARTBEAT says it is armed (`false` before one came).
    #[must_use]
    pub fn armed(&self) -> bool {
        self.state().armed().unwrap_or(false)
    }

    /// The lines it said after thing number `after` (see `State::said_count`), as text.
    async fn said_since(&self, after: u64) -> Vec<String> {
        let said = self.state().said_since(after);
        self.said_texts(said).await
    }

    /// How many things it has said so far (STATUSTEXT lines, EVENTs).
    fn said_count(&self) -> u64 {
        self.state().said_count
    }

    /// Whether message `msg_id` from the system arrives within `wait` (from now).
    async fn comes(&self, msg_id: u32, wait: Duration) -> bool {
        let since = tokio::time::Instant::now();
        self.wait_state(wait, |s| {
            s.last_seen.get(&msg_id).is_some_and(|&t| t >= since)
        })
        .await
    }
}
