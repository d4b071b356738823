//! What a system says about a refused command, as text: its STATUSTEXT lines (ArduPilot's
//! `PreArm: ...`) and its EVENT messages (PX4's "Arming denied: ..."), the latter made into
//! text with the event metadata the system serves — fetched once, when an event first needs
//! it: COMPONENT_METADATA names the general metadata file, that file the events file, both
//! read over MAVFTP and unpacked (xz).

use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_dialects::common::ComponentMetadata;

use super::System;
use super::state::Said;
use crate::events::{self, Catalog};

/// How long fetching the event metadata may take (two small files over MAVFTP).
const FETCH_LIMIT: Duration = Duration::from_secs(15);

/// How long COMPONENT_METADATA may take to come after its request is accepted.
const METADATA_WAIT: Duration = Duration::from_secs(2);

/// The system's event metadata, as far as it is known.
#[derive(Debug, Default)]
pub(super) enum EventTexts {
    /// Not asked for yet.
    #[default]
    NotFetched,
    /// Fetched.
    Fetched(Catalog),
    /// Cannot be had, and why.
    Unavailable(String),
}

impl System {
    /// `said` as lines: STATUSTEXT as it came, events as their text (fetching the metadata
    /// first when needed; summary events left out), or `event 0x…` with why there is no
    /// text; a line said twice (an event and its STATUSTEXT copy) shown once.
    pub(super) async fn said_texts(&self, said: Vec<Said>) -> Vec<String> {
        let mut texts = self.inner.event_texts.lock().await;
        if said.iter().any(|s| matches!(s, Said::Event { .. }))
            && matches!(*texts, EventTexts::NotFetched)
        {
            let fetched = tokio::time::timeout(FETCH_LIMIT, Box::pin(self.fetch_event_catalog()))
                .await
                .unwrap_or_else(|_| Err(format!("not fetched within {} s", FETCH_LIMIT.as_secs())));
            *texts = match fetched {
                Ok(catalog) => EventTexts::Fetched(catalog),
                Err(why) => {
                    tracing::warn!(target: "mavstack::system", "event texts of {}: {why}", self.target());
                    EventTexts::Unavailable(why)
                }
            };
        }
        let mut why_told = false;
        let mut lines: Vec<String> = Vec::with_capacity(said.len());
        for s in said {
            let line = match s {
                Said::Text(text) => text,
                Said::Event { id, arguments } => match &*texts {
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
    async fn fetch_event_catalog(&self) -> Result<Catalog, String> {
        if self.state().metadata_uri.is_none() {
            self.commands()
                .request_message(ComponentMetadata::ID)
                .await
                .map_err(|e| format!("COMPONENT_METADATA: {e}"))?;
            self.wait_state(METADATA_WAIT, |s| s.metadata_uri.is_some())
                .await;
        }
        let general_uri = self
            .state()
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
    async fn metadata_file(&self, uri: &str) -> Result<Vec<u8>, String> {
        let path = events::ftp_path(uri).ok_or_else(|| format!("{uri}: not an mftp:// URI"))?;
        let bytes = self
            .ftp()
            .read(&path, |_, _| {})
            .await
            .map_err(|e| format!("{uri}: {}", crate::error_chain(&e)))?;
        events::unpack(&bytes).map_err(|e| format!("{uri}: {e}"))
    }
}
