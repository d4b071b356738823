//! [`Signing`]: message signing with a system — SETUP_SIGNING sent, the link signed, and the
//! change proven by an answer (the system confirms nothing itself); when it is not proven,
//! what the system said meanwhile (ArduPilot: "ERROR: Won't setup signing when armed").
//!
//! A system that refuses SETUP_SIGNING says so unsigned, and the link, signed by then, turns
//! unsigned frames away: the lines are read from the link's raw input (a tap) instead —
//! STATUSTEXT frames of the target with a good checksum, shown for what they say, never
//! taken as messages.

use core::time::Duration;

use mavstack_core::parse::{Item, SliceParser};
use mavstack_core::signing::SecretKey;
use mavstack_core::{Message as _, MessageSet as _};
use mavstack_dialects::common::{MavMessage, SetupSigning, Statustext};
use mavstack_services::statustext::Lines;
use mavstack_transport::clock;

use super::{System, SystemError};
use crate::node::TapSubscription;

/// How long what a system says after a signing change is still collected.
const SAID_AFTER: Duration = Duration::from_millis(500);

/// What a signing change proved: requests sent in the link's new signing after it, and
/// the answers that came back (on a signed link only frames that verify with the key are
/// accepted, so an answer there is a signed one); and what the system said meanwhile.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct SigningCheck {
    /// Requests sent.
    pub asked: u8,
    /// Requests answered.
    pub answered: u8,
    /// What the system said (STATUSTEXT, EVENT texts) from SETUP_SIGNING until the proof
    /// ended, when it was not proven: the reason a flight stack gives for ignoring it.
    pub statustext: Vec<String>,
}

impl SigningCheck {
    /// Every request was answered.
    #[must_use]
    pub const fn proven(&self) -> bool {
        self.asked > 0 && self.answered == self.asked
    }
}

/// Signing with a system (from [`System::signing`]).
#[derive(Clone, Debug)]
pub struct Signing {
    system: System,
}

impl Signing {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// Sets up signing with the system: sends SETUP_SIGNING with `key` and a timestamp of
    /// now over the link (which should be a secure one: a wire, or a link already signed),
    /// signs the link with `key` and link id `link_id`, then proves it: one request
    /// (REQUEST_MESSAGE for AUTOPILOT_VERSION, with the command protocol's retries) goes out
    /// signed, and only a signed answer that verifies with `key` can reach us on the signed
    /// link ([`SigningCheck::answered`]).
    ///
    /// # Errors
    /// [`SystemError::Busy`] on a link that cannot sign (`version=1`),
    /// [`SystemError::Stopped`].
    pub async fn setup(&self, key: SecretKey, link_id: u8) -> Result<SigningCheck, SystemError> {
        let said_before = self.system.said_count();
        let tap = self.system.node().tap().await;
        let timestamp =
            mavstack_core::signing::timestamp_from_unix_micros(clock::now().as_micros());
        self.send_setup(*key.as_bytes(), timestamp).await?;
        let mut signing = mavstack_channel::SigningConfig::new(key, link_id);
        signing.initial_timestamp = timestamp;
        self.sign_link(Some(signing)).await?;
        Ok(self.check(said_before, tap).await)
    }

    /// Turns signing off with the system: sends SETUP_SIGNING with the all-zero key and
    /// timestamp (signed with the link's current key, as the system requires), stops signing
    /// the link, then proves it with one unsigned request ([`SigningCheck::answered`]: the
    /// system answered it, so it accepts unsigned frames again).
    ///
    /// # Errors
    /// As [`setup`](Self::setup).
    pub async fn remove(&self) -> Result<SigningCheck, SystemError> {
        let said_before = self.system.said_count();
        let tap = self.system.node().tap().await;
        self.send_setup([0; 32], 0).await?;
        self.sign_link(None).await?;
        Ok(self.check(said_before, tap).await)
    }

    async fn send_setup(&self, secret_key: [u8; 32], timestamp: u64) -> Result<(), SystemError> {
        let target = self.system.target();
        let setup = MavMessage::SetupSigning(SetupSigning {
            target_system: target.system,
            target_component: target.component,
            secret_key,
            initial_timestamp: timestamp,
        });
        self.system.send(&setup).await
    }

    async fn sign_link(
        &self,
        signing: Option<mavstack_channel::SigningConfig>,
    ) -> Result<(), SystemError> {
        self.system
            .node()
            .set_signing(self.system.link(), signing)
            .await
            .map_err(|e| match e {
                crate::node::RequestError::Stopped => SystemError::Stopped,
                e => SystemError::Busy(e.to_string()),
            })
    }

    /// One request in the link's current signing; whether it was answered, and what the
    /// system said since thing number `said_before` (or in what `tap` saw, where the link
    /// refused it) when it was not.
    async fn check(&self, said_before: u64, mut tap: TapSubscription) -> SigningCheck {
        let answered = self.system.commands().answered().await;
        let statustext = if answered {
            Vec::new()
        } else {
            tokio::time::sleep(SAID_AFTER).await;
            let mut said = self.system.said_since(said_before).await;
            for line in self.refused_lines(&mut tap) {
                if !said.contains(&line) {
                    said.push(line);
                }
            }
            said
        };
        SigningCheck {
            asked: 1,
            answered: u8::from(answered),
            statustext,
        }
    }
}

impl Signing {
    /// The STATUSTEXT lines of the target in the raw input `tap` saw on its link.
    fn refused_lines(&self, tap: &mut TapSubscription) -> Vec<String> {
        let (link, target) = (self.system.link(), self.system.target());
        let lookup = |id: u32| MavMessage::info(id).map(|m| m.crc_extra);
        let mut lines = Lines::default();
        let mut said = Vec::new();
        while let Ok(input) = tap.try_recv() {
            if input.link_id != link {
                continue;
            }
            for item in SliceParser::new(&input.bytes, lookup) {
                let Item::Frame(f) = item else { continue };
                if f.sysid() != target.system || f.msg_id() != Statustext::ID {
                    continue;
                }
                if let Ok(MavMessage::Statustext(text)) =
                    MavMessage::decode(f.msg_id(), f.payload())
                    && let Some(line) = lines.push((f.sysid(), f.compid()), &text)
                {
                    said.push(line.text);
                }
            }
        }
        said
    }
}
