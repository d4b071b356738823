//! [`Vehicle`]: the services' server roles put together around the craft.

use core::time::Duration;
use std::collections::VecDeque;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    ComponentMetadata, Heartbeat, MavCmd, MavFrame, MavMessage, MavMissionType, MavSeverity,
    MissionItemInt, MissionItemReached, Statustext,
};
use mavstack_services::command::CommandServer;
use mavstack_services::ftp::param_pck::TableFile;
use mavstack_services::ftp::{DirBackend, FtpServer, Overlay, ServerConfig};
use mavstack_services::gimbal::VehicleState;
use mavstack_services::log_transfer::{LogServer, LogServerEvent};
use mavstack_services::mission::{
    MissionConfig, MissionServer, MissionServerEvent, StrayItems, UploadPacing,
};
use mavstack_services::param::{Encoding, Name, ParamServer, ParamServerEvent, Value};
use mavstack_services::rtcm::{self, Reassembler, ReassemblyStats};
use mavstack_services::stream::StreamScheduler;
use mavstack_services::timesync::{Timesync, TimesyncConfig};
use mavstack_services::{Address, Outgoing, Service};

use crate::control::Control;
use crate::craft::{self, Boot, Craft};
use crate::flight::{Flight, FlightEvent, HOME_AMSL, Tuning};
use crate::gimbal::SimGimbal;
use crate::nsh::Nsh;
use crate::{Autopilot, SimConfig, events, logs};

/// Peers that appear later than this after the start get a HEARTBEAT of their own.
const GREETING_AFTER: Duration = Duration::from_millis(100);

/// How often the craft's model advances.
const STEP: Duration = Duration::from_millis(50);

/// ArduPilot asks again for a mission item it has not received 1 s after its last request
/// (`wp_recv_timeout_ms = 1000U + link->get_stream_slowdown_ms()`, the slow-down 0 on a
/// network link: libraries/GCS_MAVLink/MissionItemProtocol.cpp:407-411, ArduPilot master as
/// of October 2025).
const ARDUPILOT_REREQUEST: Duration = Duration::from_secs(1);

/// ArduPilot gives an upload up 8 s after the last item (or count) it received, and sends
/// MISSION_ACK MAV_MISSION_OPERATION_CANCELLED (`upload_timeout_ms = 8000`:
/// libraries/GCS_MAVLink/MissionItemProtocol.h:95, used in MissionItemProtocol.cpp:391-404).
const ARDUPILOT_UPLOAD_TIMEOUT: Duration = Duration::from_secs(8);

/// The mission server as each flavour's autopilot runs it. The ArduPilot flavour's answers to
/// items it did not ask for are ArduPilot's (INVALID_SEQUENCE during an upload,
/// MissionItemProtocol.cpp:272-275; ERROR outside one), and so are its timings: a
/// ground station slower than the measured round trip is not asked twice (MAVProxy answers
/// both requests, and the copy is refused). The PX4 flavour keeps the round-trip pacing (PX4
/// asks again after 250 ms).
fn mission_config(autopilot: Autopilot) -> MissionConfig {
    let (stray_items, pacing) = match autopilot {
        Autopilot::Ardupilot => (
            StrayItems::ArduPilot,
            UploadPacing::Fixed {
                every: ARDUPILOT_REREQUEST,
                give_up_after: ARDUPILOT_UPLOAD_TIMEOUT,
            },
        ),
        Autopilot::Px4 => (StrayItems::Reask, UploadPacing::Adaptive),
    };
    MissionConfig {
        stray_items,
        pacing,
        ..MissionConfig::default()
    }
}

/// A plan's name in the log: "mission", "fence" or "rally".
fn plan_name(mission_type: MavMissionType) -> &'static str {
    match mission_type {
        MavMissionType::FENCE => "fence",
        MavMissionType::RALLY => "rally",
        _ => "mission",
    }
}

/// The vehicle's MAVFTP server: `@PARAM/param.pck` over the served directory, if any.
/// Under it, the PX4 flavour's event metadata ([`events::MetadataFiles`]), and under that
/// the logs of a [`logs::LogDir`].
type Files = FtpServer<
    Overlay<Overlay<Overlay<DirBackend, logs::LogFiles>, events::MetadataFiles>, TableFile>,
>;

/// The simulated vehicle; see the [crate docs](crate).
#[derive(Debug)]
pub struct Vehicle {
    own: Address,
    commands: CommandServer<Craft>,
    params: ParamServer,
    /// MAVFTP (with [`SimConfig::ftp`]).
    files: Option<Files>,
    /// Log download (LOG_*).
    logs: LogServer<logs::SimLogs>,
    missions: MissionServer,
    timesync: Timesync,
    out: VecDeque<Outgoing>,
    log: VecDeque<String>,
    next_step: Instant,
    /// When the vehicle started.
    started: Instant,
    /// The `id` of the last STATUSTEXT sent in chunks.
    text_id: u16,
    /// The shell over SERIAL_CONTROL (the PX4 flavour's).
    nsh: Option<Nsh>,
    /// RTK corrections received in GPS_RTCM_DATA.
    rtcm: Reassembler,
    /// The gimbal (its manager in the autopilot's component).
    gimbal: SimGimbal,
}

impl Vehicle {
    /// A vehicle on the ground at home, disarmed, at time `now`.
    pub fn new(config: SimConfig, now: Instant) -> Self {
        let encoding = match config.autopilot {
            Autopilot::Ardupilot => Encoding::CCast,
            Autopilot::Px4 => Encoding::Bytewise,
        };
        let mut params = ParamServer::new(config.own, encoding);
        for &(name, value) in &config.params {
            // A table from `params::load` has fewer than 65,535 entries.
            let _ = params.insert(name, value);
        }
        let logs = logs::SimLogs::new(config.log_dir);
        let log_files = logs.ftp_view();
        // PX4 serves its component metadata over MAVFTP whether or not a directory is served.
        let px4 = config.autopilot == Autopilot::Px4;
        let files = (config.ftp || px4).then(|| {
            let table: Vec<(Name, Value)> = params.iter().copied().collect();
            let provider = TableFile::new(&table);
            let under = match config.ftp_files {
                Some(dir) => Overlay::new(dir, log_files),
                None => Overlay::alone(log_files),
            };
            let metadata = if px4 {
                events::MetadataFiles::px4()
            } else {
                events::MetadataFiles::none()
            };
            let overlay = Overlay::new(Overlay::new(under, metadata), provider);
            FtpServer::new(config.own, ServerConfig::default(), overlay)
        });
        let mut streams = StreamScheduler::new();
        for (id, interval) in craft::streams(config.autopilot) {
            let unasked = config.streams_on_request && id != Heartbeat::ID;
            streams.support(id, interval.filter(|_| !unasked));
        }
        if config.autopilot == Autopilot::Px4 {
            streams.support(ComponentMetadata::ID, None);
        }
        let craft = Craft {
            autopilot: config.autopilot,
            mavlink2: config.mavlink2,
            ftp: config.ftp,
            flight: Flight::new(config.autopilot, Tuning::default()),
            streams,
            new_current: None,
            ready_at: now + config.estimator_settle,
            data_streams_only: config.data_streams_only,
            events: events::Events::default(),
            boot: Boot(now),
            control: Control::new(config.autopilot),
            replies: VecDeque::new(),
            early: VecDeque::new(),
            said: Vec::new(),
        };
        let mut vehicle = Self {
            own: config.own,
            commands: CommandServer::new(config.own, Default::default(), craft),
            params,
            files,
            logs: LogServer::new(config.own, Default::default(), logs),
            missions: MissionServer::new(config.own, mission_config(config.autopilot)),
            timesync: Timesync::new(TimesyncConfig {
                interval: None,
                clock_offset_ns: Boot(now).timesync_offset_ns(),
                ..TimesyncConfig::default()
            }),
            out: VecDeque::new(),
            log: VecDeque::new(),
            next_step: now,
            started: now,
            text_id: 0,
            nsh: px4.then(Nsh::default),
            rtcm: Reassembler::default(),
            gimbal: SimGimbal::new(now, config.own),
        };
        vehicle.retune();
        vehicle.restore_home_item();
        vehicle
    }

    /// ArduPilot keeps home as mission item 0: a new or cleared mission has that one item,
    /// so a ground station's download always finds at least it (MAVProxy's `wp list` and
    /// `wp save` rely on it).
    fn restore_home_item(&mut self) {
        if self.commands.handler().autopilot != Autopilot::Ardupilot
            || !self.missions.plan(MavMissionType::MISSION).is_empty()
        {
            return;
        }
        let home = self.commands.handler().flight.home();
        let item = MissionItemInt {
            seq: 0,
            command: MavCmd::NAV_WAYPOINT,
            frame: MavFrame::GLOBAL,
            x: (home.lat * 1e7) as i32,
            y: (home.lon * 1e7) as i32,
            z: HOME_AMSL + home.alt,
            autocontinue: 1,
            mission_type: MavMissionType::MISSION,
            ..MissionItemInt::default()
        };
        self.missions.set_plan(MavMissionType::MISSION, vec![item]);
        let plan = self.missions.plan(MavMissionType::MISSION).to_vec();
        self.craft().flight.set_mission(&plan);
    }

    fn craft(&mut self) -> &mut Craft {
        self.commands.handler_mut()
    }

    /// A parameter's value as `f32`, if the table has it.
    fn param(&self, name: &str) -> Option<f32> {
        let name = Name::new(name).ok()?;
        self.params.get(name).map(|v| v.as_f64() as f32)
    }

    /// Takes the craft's speeds, altitudes and battery size from the parameter table.
    fn retune(&mut self) {
        let mut t = Tuning::default();
        let positive = |v: Option<f32>| v.filter(|v| v.is_finite() && *v > 0.0);
        let autopilot = self.commands.handler().autopilot;
        match autopilot {
            Autopilot::Ardupilot => {
                let cm = |v: Option<f32>| positive(v).map(|v| v / 100.0);
                t.cruise = cm(self.param("WPNAV_SPEED")).unwrap_or(t.cruise);
                t.climb = cm(self.param("WPNAV_SPEED_UP")).unwrap_or(t.climb);
                t.descent = cm(self.param("WPNAV_SPEED_DN")).unwrap_or(t.descent);
                t.land = cm(self.param("LAND_SPEED")).unwrap_or(t.land);
                t.rtl_alt = cm(self.param("RTL_ALT")).unwrap_or(t.rtl_alt);
                t.takeoff_alt = cm(self.param("PILOT_TKOFF_ALT")).unwrap_or(t.takeoff_alt);
                t.capacity_mah = positive(self.param("BATT_CAPACITY")).unwrap_or(t.capacity_mah);
            }
            Autopilot::Px4 => {
                t.cruise = positive(self.param("MPC_XY_CRUISE")).unwrap_or(t.cruise);
                t.climb = positive(self.param("MPC_Z_VEL_MAX_UP")).unwrap_or(t.climb);
                t.descent = positive(self.param("MPC_Z_VEL_MAX_DN")).unwrap_or(t.descent);
                t.land = positive(self.param("MPC_LAND_SPEED")).unwrap_or(t.land);
                t.rtl_alt = positive(self.param("RTL_RETURN_ALT")).unwrap_or(t.rtl_alt);
                t.takeoff_alt = positive(self.param("MIS_TAKEOFF_ALT")).unwrap_or(t.takeoff_alt);
                t.capacity_mah = positive(self.param("BAT1_CAPACITY")).unwrap_or(t.capacity_mah);
            }
        }
        self.craft().flight.set_tuning(t);
    }

    /// Feeds one decoded message from `from`.
    pub fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) {
        let own = self.own;
        match message {
            MavMessage::SetMode(m) if m.target_system == own.system => {
                self.craft().set_mode_message(now, m.custom_mode);
            }
            MavMessage::RequestDataStream(r)
                if own.is_reached_by(Address::new(r.target_system, r.target_component)) =>
            {
                self.craft().request_data_stream(now, r);
            }
            _ => {
                let craft = self.commands.handler_mut();
                craft
                    .control
                    .handle_message(now, own, &mut craft.flight, message);
            }
        }
        self.companion(from, message);
        // The gimbal manager's commands are its own: the autopilot does not answer them too.
        let gimbals = self.gimbal.handle_message(now, from, message)
            && matches!(
                message,
                MavMessage::CommandLong(_) | MavMessage::CommandInt(_)
            );
        if !gimbals {
            self.commands.handle_message(now, from, message);
        }
        self.params.handle_message(now, from, message);
        self.missions.handle_message(now, from, message);
        self.timesync.handle_message(now, from, message);
        if self.logs.handle_message(now, from, message) {
            self.note_logs();
        }
        if let Some(files) = &mut self.files {
            files.handle_message(now, from, message);
        }
        self.settle(now);
    }

    /// Advances the model and every timer to `now`.
    pub fn handle_timeout(&mut self, now: Instant) {
        while self.next_step <= now {
            let at = self.next_step;
            let craft = self.commands.handler_mut();
            craft.control.step(at, &mut craft.flight);
            craft.flight.step(STEP.as_secs_f64());
            let (position, home) = (craft.flight.position(), craft.flight.home());
            let vehicle = VehicleState {
                lat: position.lat,
                lon: position.lon,
                alt_amsl: f64::from(HOME_AMSL + position.alt),
                heading_deg: craft.flight.heading().to_degrees(),
            };
            let home_amsl = f64::from(HOME_AMSL + home.alt);
            self.gimbal.step(at, STEP, vehicle, home_amsl);
            self.next_step += STEP;
        }
        self.commands.handle_timeout(now);
        self.params.handle_timeout(now);
        self.missions.handle_timeout(now);
        self.timesync.handle_timeout(now);
        self.logs.handle_timeout(now);
        if let Some(files) = &mut self.files {
            files.handle_timeout(now);
        }
        self.settle(now);
    }

    /// Applies the parameter files uploaded to `@PARAM/param.pck`, as ArduPilot does: each
    /// known name set (converted to its type), unknown ones skipped, nothing broadcast.
    fn apply_uploads(&mut self) {
        let Some(files) = &mut self.files else { return };
        let provider = files.backend_mut().provider_mut();
        let mut changed = false;
        while let Some(upload) = provider.take_upload() {
            let table = match upload {
                Ok(table) => table,
                Err(e) => {
                    self.log.push_back(format!("param.pck upload refused: {e}"));
                    continue;
                }
            };
            let (mut set, mut unknown) = (0usize, 0usize);
            for (name, value) in table {
                match self.params.set_quietly(name, value) {
                    Ok(now) => {
                        provider.set(name, now);
                        set += 1;
                    }
                    Err(_) => unknown += 1,
                }
            }
            self.log.push_back(format!(
                "param.pck upload: {set} parameters set, {unknown} unknown skipped"
            ));
            changed |= set > 0;
        }
        if changed {
            self.retune();
        }
    }

    /// Carries what one part did over to the others, and queues what is due.
    fn settle(&mut self, now: Instant) {
        self.apply_uploads();
        while let Some(line) = self.gimbal.poll_log() {
            self.log.push_back(line);
        }
        while let Some(e) = self.params.poll_event() {
            if let ParamServerEvent::Changed { from, name, value } = e {
                self.log
                    .push_back(format!("param {name} = {} (set by {from})", value.as_f64()));
                // The packed file is made from the table as it is when opened.
                if let (Some(files), Some(now)) = (&mut self.files, self.params.get(name)) {
                    files.backend_mut().provider_mut().set(name, now);
                }
                self.retune();
            }
        }
        while let Some(e) = self.missions.poll_event() {
            match e {
                MissionServerEvent::PlanChanged {
                    mission_type,
                    count,
                } => {
                    self.log.push_back(format!(
                        "{} plan stored: {count} items",
                        plan_name(mission_type)
                    ));
                    if mission_type == MavMissionType::MISSION {
                        let plan = self.missions.plan(MavMissionType::MISSION).to_vec();
                        self.craft().flight.set_mission(&plan);
                        self.restore_home_item();
                    }
                }
                MissionServerEvent::CurrentChanged { seq } => {
                    self.craft().flight.set_current(seq);
                }
                MissionServerEvent::UploadAbandoned { mission_type } => {
                    self.log
                        .push_back(format!("{} upload abandoned", plan_name(mission_type)));
                }
                _ => {}
            }
        }
        if let Some(seq) = self.craft().new_current.take() {
            self.missions.set_current(seq);
        }
        for e in self.craft().events.take() {
            self.broadcast(MavMessage::Event(e));
        }
        let said = core::mem::take(&mut self.craft().said);
        let failsafes = self.craft().control.take_said();
        for (severity, text) in said.into_iter().chain(failsafes) {
            self.say(severity, text);
        }
        while let Some(reply) = self.craft().replies.pop_front() {
            self.out.push_back(reply);
        }
        while let Some(e) = self.craft().flight.poll_event() {
            match e {
                FlightEvent::ItemReached(seq) => {
                    self.broadcast(MavMessage::MissionItemReached(MissionItemReached { seq }))
                }
                FlightEvent::CurrentChanged(seq) => {
                    self.missions.set_current(seq);
                }
                FlightEvent::Text(text) => self.say(MavSeverity::INFO, text),
                FlightEvent::Warning(text) => self.say(MavSeverity::CRITICAL, text),
            }
        }
        loop {
            let craft = self.commands.handler_mut();
            let Some(due) = craft.streams.poll_due(now) else {
                break;
            };
            if let Some(message) = craft.message(now, due.msg_id) {
                self.out.push_back(Outgoing {
                    target: due.target,
                    message,
                });
            }
        }
    }

    /// A line in STATUSTEXT and in the log: a line longer than the field's 50 bytes goes in
    /// chunks of one `id` (the last shorter than 50 bytes, empty if need be), as ArduPilot
    /// and PX4 send theirs.
    fn say(&mut self, severity: MavSeverity, text: String) {
        let bytes = text.as_bytes();
        let id = if bytes.len() > 50 {
            self.text_id = self.text_id.wrapping_add(1).max(1);
            self.text_id
        } else {
            0
        };
        let mut chunks: Vec<&[u8]> = bytes.chunks(50).collect();
        if id != 0 && bytes.len().is_multiple_of(50) {
            chunks.push(&[]);
        }
        for (seq, chunk) in chunks.into_iter().enumerate().take(usize::from(u8::MAX)) {
            let mut field = [0u8; 50];
            field[..chunk.len()].copy_from_slice(chunk);
            self.broadcast(MavMessage::Statustext(Statustext {
                severity,
                text: field,
                id,
                chunk_seq: u8::try_from(seq).unwrap_or(u8::MAX),
            }));
        }
        self.log.push_back(text);
    }

    /// The shell's input (the PX4 flavour's) and RTK corrections, with a log line for each
    /// command line run and each RTCM message put together.
    fn companion(&mut self, from: Address, message: &MavMessage) {
        match message {
            MavMessage::SerialControl(m) => {
                if let Some(nsh) = &mut self.nsh
                    && nsh.handle(from, m)
                {
                    while let Some(line) = nsh.poll_ran() {
                        self.log.push_back(format!("shell ({from}): {line}"));
                    }
                }
            }
            MavMessage::GpsRtcmData(m) => {
                if let Some(message) = self.rtcm.handle(m) {
                    let s = self.rtcm.stats();
                    let number = rtcm::message_number(&message)
                        .map_or_else(|| "data".to_owned(), |n| format!("RTCM {n}"));
                    self.log.push_back(format!(
                        "rtk: {number}, {} bytes; {} messages, {} bytes, {} fragments \
                         discarded",
                        message.len(),
                        s.messages,
                        s.bytes,
                        s.fragments_discarded
                    ));
                }
            }
            _ => {}
        }
    }

    /// What it has received in GPS_RTCM_DATA: messages put together, fragments used and
    /// discarded.
    pub fn rtcm_received(&self) -> ReassemblyStats {
        self.rtcm.stats()
    }

    /// Says what the log server did (a download's first request, not each gap's).
    fn note_logs(&mut self) {
        while let Some(e) = self.logs.poll_event() {
            let line = match e {
                LogServerEvent::Listing { to, entries } => {
                    format!("log list: {entries} entries to {to}")
                }
                LogServerEvent::Sending {
                    to,
                    id,
                    ofs: 0,
                    bytes,
                } => {
                    format!("log {id}: sending {bytes} bytes to {to}")
                }
                LogServerEvent::NoSuchLog { from, id } => {
                    format!("log {id} asked by {from}: there is none")
                }
                LogServerEvent::Erased { by } => format!("logs erased by {by}"),
                _ => continue,
            };
            self.log.push_back(line);
        }
    }

    fn broadcast(&mut self, message: MavMessage) {
        self.out.push_back(Outgoing {
            target: Address::BROADCAST,
            message,
        });
    }

    /// The next message to send.
    pub fn poll_transmit(&mut self) -> Option<Outgoing> {
        if let Some(o) = self.commands.handler_mut().early.pop_front() {
            return Some(o);
        }
        if let Some(o) = self.commands.poll_transmit() {
            return Some(o);
        }
        if let Some(o) = self.commands.handler_mut().streams.poll_transmit() {
            return Some(o);
        }
        self.out
            .pop_front()
            .or_else(|| self.params.poll_transmit())
            .or_else(|| self.missions.poll_transmit())
            .or_else(|| self.timesync.poll_transmit())
            .or_else(|| self.files.as_mut().and_then(Service::poll_transmit))
            .or_else(|| self.logs.poll_transmit())
            .or_else(|| self.nsh.as_mut().and_then(Nsh::poll_transmit))
            .or_else(|| self.gimbal.poll_transmit())
    }

    /// When [`Vehicle::handle_timeout`] is next due.
    pub fn poll_timeout(&self) -> Instant {
        [
            self.commands.handler().streams.poll_timeout(),
            self.commands.poll_timeout(),
            self.params.poll_timeout(),
            self.missions.poll_timeout(),
            self.timesync.poll_timeout(),
            self.files.as_ref().and_then(Service::poll_timeout),
            self.logs.poll_timeout(),
        ]
        .into_iter()
        .flatten()
        .fold(self.next_step, Instant::min)
    }

    /// The next line of what happened (mode changes, parameter sets, plans stored).
    pub fn poll_log(&mut self) -> Option<String> {
        self.log.pop_front()
    }

    /// What to send a peer that just appeared: our HEARTBEAT at once, so that it need not
    /// wait up to a second to find us — except in the first moments, when the stream's own
    /// first HEARTBEAT reaches the peers a link starts with (a `udpout` destination).
    pub fn greeting(&self, now: Instant) -> Option<MavMessage> {
        (now.saturating_duration_since(self.started) >= GREETING_AFTER)
            .then(|| MavMessage::Heartbeat(self.commands.handler().heartbeat()))
    }

    /// Where its gimbal looks: pitch and yaw from the vehicle's nose, degrees.
    pub fn gimbal_angles(&self) -> (f32, f32) {
        self.gimbal.angles()
    }

    /// The parameter table's size.
    pub fn param_count(&self) -> usize {
        self.params.len()
    }

    /// Whether the motors are armed.
    pub fn is_armed(&self) -> bool {
        self.commands.handler().flight.is_armed()
    }

    /// Whether SETUP_SIGNING is to be refused now: the ArduPilot flavour refuses it while
    /// armed, as ArduPilot does (`GCS_MAVLINK::handle_setup_signing`,
    /// libraries/GCS_MAVLink/GCS_Signing.cpp); the PX4 flavour never.
    pub fn refuses_setup_signing(&self) -> bool {
        self.commands.handler().autopilot == Autopilot::Ardupilot && self.is_armed()
    }

    /// Says why a SETUP_SIGNING was refused, as ArduPilot says it: "ERROR: Won't setup
    /// signing when armed" (severity WARNING).
    pub fn setup_signing_refused(&mut self) {
        self.say(
            MavSeverity::WARNING,
            "ERROR: Won't setup signing when armed".to_owned(),
        );
    }
}

/// The vehicle as one [`Service`]: what runs it on a node (`mavstack::serve`) runs it like
/// any other component.
impl Service for Vehicle {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        Self::handle_message(self, now, from, message);
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        Self::handle_timeout(self, now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        Self::poll_transmit(self)
    }

    fn poll_timeout(&self) -> Option<Instant> {
        Some(Self::poll_timeout(self))
    }
}
