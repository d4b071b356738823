//! What a system says about a refused command: its STATUSTEXT lines (ArduPilot's
//! `PreArm: ...`) and its EVENT messages (PX4's "Arming denied: ..."), the latter made into
//! text with the event metadata the system serves — fetched once, when an event first needs
//! it: COMPONENT_METADATA names the general metadata file, that file the events file, both
//! read over MAVFTP and unpacked (xz).

use core::time::Duration;
use std::collections::VecDeque;

use mavstack_core::Message as _;
use mavstack_dialects::common::{ComponentMetadata, Event};
use mavstack_services::Address;

use super::{MAX_SAID, System};
use crate::events::{self, Catalog};

/// How long fetching the event metadata may take (two small files over MAVFTP).
const FETCH_LIMIT: Duration = Duration::from_secs(15);

/// How long COMPONENT_METADATA may take to come after its request is accepted.
const METADATA_WAIT: Duration = Duration::from_secs(2);

/// Event sequence numbers remembered, so that an event sent again counts once.
const SEEN_EVENTS: usize = 64;

/// One thing the system said while a command ran.
#[derive(Clone, Debug)]
pub(super) enum Said {
    /// A STATUSTEXT line.
    Text(String),
    /// An EVENT: its id and arguments.
    Event { id: u32, arguments: [u8; 40] },
}

/// The system's event metadata, as far as it is known.
#[derive(Debug, Default)]
pub(super) enum EventTexts {
    /// Not asked for yet.
    #[default]
    NotFetched,
    /// Being fetched (a command the fetch sends must not fetch again).
    Fetching,
    /// Fetched.
    Fetched(Catalog),
    /// Cannot be had, and why.
    Unavailable(String),
}

/// What [`Said`] needs kept on the [`System`].
#[derive(Debug, Default)]
pub(super) struct Listening {
    /// What the target said since the current command started, oldest first.
    pub(super) said: Vec<Said>,
    /// Its event metadata.
    pub(super) texts: EventTexts,
    /// The URI of its general metadata file, once COMPONENT_METADATA came.
    pub(super) metadata_uri: Option<String>,
    /// (component, sequence) of the events seen last.
    seen: VecDeque<(u8, u16)>,
}

impl Listening {
    pub(super) fn push(&mut self, said: Said) {
        if self.said.len() == MAX_SAID {
            self.said.remove(0);
        }
        self.said.push(said);
    }

    /// An EVENT from the target for us (or for everyone).
    pub(super) fn event(&mut self, from: Address, own: Address, e: &Event) {
        let for_us = (e.destination_system == 0 || e.destination_system == own.system)
            && (e.destination_component == 0 || e.destination_component == own.component);
        if !for_us || self.seen.contains(&(from.component, e.sequence)) {
            return;
        }
        if self.seen.len() == SEEN_EVENTS {
            self.seen.pop_front();
        }
        self.seen.push_back((from.component, e.sequence));
        self.push(Said::Event {
            id: e.id,
            arguments: e.arguments,
        });
    }

    pub(super) fn component_metadata(&mut self, m: &ComponentMetadata) {
        let end = m.uri.iter().position(|&b| b == 0).unwrap_or(m.uri.len());
        self.metadata_uri = Some(String::from_utf8_lossy(&m.uri[..end]).into_owned());
    }
}

impl System {
    /// `said` as lines: STATUSTEXT as it came, events as their text (fetching the metadata
    /// first when needed; summary events left out), or `event 0x…` with why there is no
    /// text; a line said twice (an event and its STATUSTEXT copy) shown once.
    pub(super) async fn said_texts(&mut self, said: Vec<Said>) -> Vec<String> {
        if said.iter().any(|s| matches!(s, Said::Event { .. }))
            && matches!(self.listening.texts, EventTexts::NotFetched)
        {
            self.listening.texts = EventTexts::Fetching;
            let fetched = tokio::time::timeout(FETCH_LIMIT, Box::pin(self.fetch_event_catalog()))
                .await
                .unwrap_or_else(|_| Err(format!("not fetched within {} s", FETCH_LIMIT.as_secs())));
            self.listening.texts = match fetched {
                Ok(catalog) => EventTexts::Fetched(catalog),
                Err(why) => {
                    tracing::warn!(target: "mavstack::system", "event texts of {}: {why}", self.target);
                    EventTexts::Unavailable(why)
                }
            };
        }
        let mut why_told = false;
        let mut lines: Vec<String> = Vec::with_capacity(said.len());
        for s in said {
            let line = match s {
                Said::Text(text) => text,
                Said::Event { id, arguments } => match &self.listening.texts {
                    EventTexts::Fetched(c) => match c.decode(id, &arguments) {
                        // Bits for a health display, told again as events of their own.
                        Some(d) if d.summary => continue,
                        Some(d) => d.text,
                        None => format!("event {id:#010x} (not in the vehicle's event metadata)"),
                    },
                    EventTexts::Unavailable(why) if !why_told => {
                        why_told = true;
                        format!("event {id:#010x} (no event texts: {why})")
                    }
                    _ => format!("event {id:#010x}"),
                },
            };
            // PX4 says an event's text again in STATUSTEXT: once is enough.
            if !lines.contains(&line) {
                lines.push(line);
            }
        }
        lines
    }

    /// COMPONENT_METADATA, then the general metadata file and the events file it names.
    async fn fetch_event_catalog(&mut self) -> Result<Catalog, String> {
        let kept = core::mem::take(&mut self.listening.said);
        let result = self.fetch_event_catalog_keeping_said().await;
        self.listening.said = kept;
        result
    }

    async fn fetch_event_catalog_keeping_said(&mut self) -> Result<Catalog, String> {
        if self.listening.metadata_uri.is_none() {
            self.request_message(ComponentMetadata::ID)
                .await
                .map_err(|e| format!("COMPONENT_METADATA: {e}"))?;
            self.take_until(METADATA_WAIT, |s, _| s.listening.metadata_uri.is_some())
                .await;
        }
        let general_uri = self
            .listening
            .metadata_uri
            .clone()
            .ok_or("COMPONENT_METADATA did not come")?;
        let general = self.metadata_file(&general_uri).await?;
        let events_uri = events::events_uri(&general)
            .map_err(|e| format!("{general_uri}: {e}"))?
            .ok_or_else(|| format!("{general_uri} names no event metadata"))?;
        let json = self.metadata_file(&events_uri).await?;
        Catalog::from_json(&json).map_err(|e| format!("{events_uri}: {e}"))
    }

    /// A metadata file by its `mftp://` URI, unpacked.
    async fn metadata_file(&mut self, uri: &str) -> Result<Vec<u8>, String> {
        let path = events::ftp_path(uri).ok_or_else(|| format!("{uri}: not an mftp:// URI"))?;
        let bytes = self
            .ftp_read(&path, |_, _| {})
            .await
            .map_err(|e| format!("{uri}: {e}"))?;
        events::unpack(&bytes).map_err(|e| format!("{uri}: {e}"))
    }
}
