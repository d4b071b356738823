//! What a remote system tells about itself in passing, kept by one task per [`System`]
//! (its tracker) and shared with every handle through a `watch` channel: its latest
//! HEARTBEAT, home, position, capabilities, landed state and current mode, the lines it
//! said (STATUSTEXT and EVENT), and when each message last came.
//!
//! Operations read it (`home`, `position`, `armed`) and wait on it (`takeoff` until the
//! height is reached, a mode until it is current) without a subscription of their own.
//!
//! [`System`]: super::System

use std::collections::{BTreeMap, VecDeque};

use mavstack_core::MessageSet as _;
use mavstack_dialects::common::{
    CommandAck, Event, ExtendedSysState, GlobalPositionInt, Heartbeat, HomePosition,
    LocalPositionNed, MavAutopilot, MavLandedState, MavMessage, MavModeFlag, MavProtocolCapability,
    MavType,
};
use mavstack_services::Address;
use mavstack_services::statustext::Lines;
use tokio::sync::watch;
use tokio::time::Instant;

use crate::node::Subscription;
use crate::router::LinkId;

/// Lines kept of what the system said (STATUSTEXT and EVENT).
const SAID_KEPT: usize = 64;

/// COMMAND_ACKs kept (for answers that come after the first: PX4 acknowledges DO_SET_MODE
/// twice, from its MAVLink receiver and then from its commander).
const ACKS_KEPT: usize = 16;

/// Event sequence numbers remembered, so that an event sent again counts once.
const SEEN_EVENTS: usize = 64;

/// One thing the system said.
#[derive(Clone, Debug)]
pub(crate) enum Said {
    /// A STATUSTEXT line.
    Text(String),
    /// An EVENT: its id and arguments.
    Event { id: u32, arguments: [u8; 40] },
}

/// The standard-modes protocol's view of a mode (AVAILABLE_MODES, CURRENT_MODE).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct ModeSeen {
    /// MAV_STANDARD_MODE, 0 when not standard.
    pub(crate) standard: u8,
    /// The autopilot's own number.
    pub(crate) custom_mode: u32,
    /// MAV_MODE_PROPERTY bits.
    pub(crate) properties: u32,
    /// Its name, as the vehicle gives it (empty in CURRENT_MODE).
    pub(crate) name: String,
}

/// What is known of the system.
#[derive(Debug, Default)]
pub(crate) struct State {
    /// Its latest HEARTBEAT (of the target component) and when it came.
    pub(crate) heartbeat: Option<(Heartbeat, Instant)>,
    /// Its HOME_POSITION.
    pub(crate) home: Option<HomePosition>,
    /// Home's altitude above mean sea level (m), from HOME_POSITION or GLOBAL_POSITION_INT.
    pub(crate) home_amsl: Option<f32>,
    /// Its latest GLOBAL_POSITION_INT.
    pub(crate) position: Option<GlobalPositionInt>,
    /// Its latest LOCAL_POSITION_NED.
    pub(crate) local: Option<LocalPositionNed>,
    /// Its EXTENDED_SYS_STATE's landed state.
    pub(crate) landed: Option<MavLandedState>,
    /// The capabilities of its AUTOPILOT_VERSION.
    pub(crate) capabilities: Option<MavProtocolCapability>,
    /// The URI of its general metadata file (COMPONENT_METADATA).
    pub(crate) metadata_uri: Option<String>,
    /// Its CURRENT_MODE and when it came.
    pub(crate) current_mode: Option<(ModeSeen, Instant)>,
    /// Its AVAILABLE_MODES, by index (1-based), and how many it has.
    pub(crate) available_modes: BTreeMap<u8, ModeSeen>,
    /// AVAILABLE_MODES' `number_modes`, once one came.
    pub(crate) modes_count: Option<u8>,
    /// The request for AVAILABLE_MODES was refused or not answered: not asked again.
    pub(crate) modes_refused: bool,
    /// What it said, numbered from 1 (the number of the last is `said_count`).
    pub(crate) said: VecDeque<(u64, Said)>,
    /// How many things it has said.
    pub(crate) said_count: u64,
    /// When each message id last came from it.
    pub(crate) last_seen: BTreeMap<u32, Instant>,
    /// The system's components heard (HEARTBEAT), with their autopilot and type.
    pub(crate) components: BTreeMap<u8, (MavAutopilot, MavType)>,
    /// COMMAND_ACKs it sent us, numbered from 1 (the last `acks` of them kept).
    pub(crate) acks: VecDeque<(u64, CommandAck)>,
    /// How many COMMAND_ACKs it has sent us.
    pub(crate) ack_count: u64,
    /// The node stopped: nothing more will come.
    pub(crate) stopped: bool,
    /// The router link its latest HEARTBEAT (of the target component) came in on: where
    /// it is reached now. A vehicle that restarts behind a `udpin` link comes back from
    /// another source port, i.e. as another peer link; requests follow it there.
    pub(crate) link: Option<LinkId>,
    lines: Lines,
    events_seen: VecDeque<(u8, u16)>,
}

impl State {
    /// Whether its latest HEARTBEAT says it is armed.
    pub(crate) fn armed(&self) -> Option<bool> {
        self.heartbeat
            .as_ref()
            .map(|(hb, _)| hb.base_mode.contains(MavModeFlag::SAFETY_ARMED))
    }

    /// The `custom_mode` it reported last: the newer of CURRENT_MODE and HEARTBEAT (PX4 sends
    /// CURRENT_MODE on a change but also at a low rate, so either can be the fresher).
    pub(crate) fn custom_mode(&self) -> Option<u32> {
        match (&self.current_mode, &self.heartbeat) {
            (Some((m, at)), Some((hb, hb_at))) => Some(if at >= hb_at {
                m.custom_mode
            } else {
                hb.custom_mode
            }),
            (Some((m, _)), None) => Some(m.custom_mode),
            (None, Some((hb, _))) => Some(hb.custom_mode),
            (None, None) => None,
        }
    }

    /// The first refusal of `command` among the acknowledgements after number `after`.
    pub(crate) fn refusal_after(
        &self,
        command: mavstack_dialects::common::MavCmd,
        after: u64,
    ) -> Option<CommandAck> {
        self.acks
            .iter()
            .filter(|(n, a)| *n > after && a.command == command)
            .map(|(_, a)| *a)
            .find(|a| {
                !matches!(
                    a.result,
                    mavstack_dialects::common::MavResult::ACCEPTED
                        | mavstack_dialects::common::MavResult::IN_PROGRESS
                )
            })
    }

    /// What it said after thing number `after`, oldest first.
    pub(crate) fn said_since(&self, after: u64) -> Vec<Said> {
        self.said
            .iter()
            .filter(|(n, _)| *n > after)
            .map(|(_, s)| s.clone())
            .collect()
    }

    fn say(&mut self, said: Said) {
        if self.said.len() == SAID_KEPT {
            self.said.pop_front();
        }
        self.said_count += 1;
        self.said.push_back((self.said_count, said));
    }

    /// Takes one message from `from` (a component of the target system); `own` is our
    /// address (events for others are not ours to show), `target` the system's.
    pub(crate) fn note(&mut self, from: Address, own: Address, target: Address, msg: &MavMessage) {
        let now = Instant::now();
        let ours = from.component == target.component;
        if let MavMessage::Heartbeat(hb) = msg {
            self.components
                .insert(from.component, (hb.autopilot, hb.r#type));
        }
        match msg {
            MavMessage::Heartbeat(hb) if ours => self.heartbeat = Some((*hb, now)),
            MavMessage::Statustext(text) => {
                if let Some(line) = self.lines.push((from.system, from.component), text) {
                    self.say(Said::Text(line.text));
                }
            }
            MavMessage::Event(e) => self.event(from, own, e),
            MavMessage::CommandAck(ack)
                if ack.target_system == 0 || ack.target_system == own.system =>
            {
                if self.acks.len() == ACKS_KEPT {
                    self.acks.pop_front();
                }
                self.ack_count += 1;
                self.acks.push_back((self.ack_count, *ack));
            }
            MavMessage::ComponentMetadata(m) if ours => {
                let end = m.uri.iter().position(|&b| b == 0).unwrap_or(m.uri.len());
                self.metadata_uri = Some(String::from_utf8_lossy(&m.uri[..end]).into_owned());
            }
            MavMessage::GlobalPositionInt(p) => {
                self.home_amsl = self
                    .home
                    .map(|h| h.altitude as f32 / 1000.0)
                    .or(Some((p.alt - p.relative_alt) as f32 / 1000.0));
                self.position = Some(*p);
            }
            MavMessage::LocalPositionNed(p) => self.local = Some(*p),
            MavMessage::HomePosition(home) => {
                self.home_amsl = Some(home.altitude as f32 / 1000.0);
                self.home = Some(*home);
            }
            MavMessage::ExtendedSysState(ExtendedSysState { landed_state, .. }) => {
                self.landed = Some(*landed_state);
            }
            MavMessage::AutopilotVersion(v) if ours => self.capabilities = Some(v.capabilities),
            MavMessage::AvailableModes(m) if ours => {
                self.modes_count = Some(m.number_modes);
                // A vehicle's list changes only with a restart; one that shrinks is a new list.
                self.available_modes.retain(|&i, _| i <= m.number_modes);
                self.available_modes.insert(
                    m.mode_index,
                    ModeSeen {
                        standard: m.standard_mode.0,
                        custom_mode: m.custom_mode,
                        properties: m.properties.0,
                        name: text_of(&m.mode_name),
                    },
                );
            }
            MavMessage::CurrentMode(m) if ours => {
                let seen = ModeSeen {
                    standard: m.standard_mode.0,
                    custom_mode: m.custom_mode,
                    properties: 0,
                    name: String::new(),
                };
                self.current_mode = Some((seen, now));
            }
            _ => {}
        }
    }

    fn event(&mut self, from: Address, own: Address, e: &Event) {
        let for_us = (e.destination_system == 0 || e.destination_system == own.system)
            && (e.destination_component == 0 || e.destination_component == own.component);
        if !for_us || self.events_seen.contains(&(from.component, e.sequence)) {
            return;
        }
        if self.events_seen.len() == SEEN_EVENTS {
            self.events_seen.pop_front();
        }
        self.events_seen.push_back((from.component, e.sequence));
        self.say(Said::Event {
            id: e.id,
            arguments: e.arguments,
        });
    }
}

/// A NUL-terminated text field as a string.
fn text_of(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// The tracker: takes every frame of the target system from `frames` into `state` until the
/// node stops (or every [`System`](super::System) handle is gone, which aborts it).
pub(crate) async fn track(
    mut frames: Subscription,
    state: watch::Sender<State>,
    own: Address,
    target: Address,
) {
    while let Some(incoming) = frames.recv().await {
        let f = incoming.frame.frame.view();
        if f.sysid() != target.system {
            continue;
        }
        let id = f.msg_id();
        let Ok(msg) = MavMessage::decode(id, f.payload()) else {
            continue;
        };
        let from = Address::new(f.sysid(), f.compid());
        let link = incoming.link_id;
        state.send_modify(|s| {
            s.last_seen.insert(id, Instant::now());
            if matches!(msg, MavMessage::Heartbeat(_)) && from == target {
                s.link = Some(link);
            }
            s.note(from, own, target, &msg);
        });
    }
    state.send_modify(|s| s.stopped = true);
}
