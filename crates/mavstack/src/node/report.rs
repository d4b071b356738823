//! What a node reports: every link's counters, routes and systems.

use std::collections::HashMap;

use mavstack_core::time::Instant;
use mavstack_router::{LinkConfig, LinkId, LinkMode};

use super::driver::Driver;
use super::{LinkReport, NodeReport, SystemReport};

impl Driver {
    pub(super) fn report(&self, now: Instant) -> NodeReport {
        let mut links = Vec::new();
        let mut names: HashMap<LinkId, (String, Option<String>)> = HashMap::new();
        for (i, slot) in self.slots.iter().enumerate() {
            if slot.peers.is_empty() {
                links.push(LinkReport {
                    name: slot.template.name.clone(),
                    link_id: None,
                    peer: None,
                    version: mode_of(&slot.template).as_str(),
                    rx_frames: 0,
                    rx_bytes: 0,
                    tx_frames: 0,
                    tx_bytes: 0,
                    converted: 0,
                    conversions: conversions(&mavstack_router::Conversions::default()),
                    dropped: Vec::new(),
                    seq_lost: 0,
                    sources: Vec::new(),
                });
            }
            let first = links.len();
            let mut peers: Vec<_> = slot.peers.values().collect();
            peers.sort_by_key(|(id, _, _)| *id);
            for (id, _, addr) in peers {
                let Some(status) = self.router.link_status(*id) else {
                    continue;
                };
                let peer = Some(addr.clone());
                names.insert(*id, (slot.template.name.clone(), peer.clone()));
                let c = &status.counters;
                links.push(LinkReport {
                    name: slot.template.name.clone(),
                    link_id: Some(*id),
                    peer,
                    version: status.mode.as_str(),
                    rx_frames: c.rx_frames,
                    rx_bytes: c.rx_bytes,
                    tx_frames: c.tx_frames,
                    tx_bytes: c.tx_bytes,
                    converted: c.converted,
                    conversions: conversions(&c.conversions),
                    dropped: status.drops().into_iter().filter(|(_, n)| *n > 0).collect(),
                    seq_lost: status.channel.lost,
                    sources: self.router.channel(*id).map_or_else(Vec::new, |ch| {
                        ch.sources()
                            .iter()
                            .map(|s| (s.sysid, s.compid, s.received, s.lost))
                            .collect()
                    }),
                });
            }
            // What the link refused before any router link saw it goes on its first entry.
            if let Some(entry) = links.get_mut(first) {
                let io = slot.io.stats();
                let log_full = self.log.as_ref().map_or(0, |l| l.dropped(i));
                for (reason, n) in [
                    ("not_mavlink", io.rx_unadmitted),
                    ("peer_refused", io.peers_refused),
                    ("log_full", log_full),
                ] {
                    if n > 0 {
                        entry.dropped.push((reason, n));
                    }
                }
            }
        }
        let routes = self
            .router
            .routes()
            .map(|r| {
                let (name, peer) = names.get(&r.link).cloned().unwrap_or_default();
                let age = now.saturating_duration_since(r.last_seen).as_secs_f64();
                (r.sysid, r.compid, name, peer, age)
            })
            .collect();
        let systems = self
            .router
            .systems()
            .map(|s| {
                let (link, peer) = names.get(&s.link).cloned().unwrap_or_default();
                let age = now.saturating_duration_since(s.last_seen);
                SystemReport {
                    heartbeat: *s,
                    link,
                    peer,
                    age_ms: u64::try_from(age.as_millis()).unwrap_or(u64::MAX),
                }
            })
            .collect();
        NodeReport {
            t_s: now.saturating_duration_since(self.started).as_secs_f64(),
            links,
            routes,
            systems,
            transport: self
                .slots
                .iter()
                .map(|s| (s.template.name.clone(), s.io.stats()))
                .collect(),
            subscriber_drops: self.subscriber_drops,
        }
    }
}

/// What a link with no peer yet will carry.
pub(super) const fn mode_of(config: &LinkConfig) -> LinkMode {
    if config.signing.is_some() {
        return LinkMode::Signed;
    }
    match config.version {
        mavstack_router::VersionMode::Mavlink1 => LinkMode::Mavlink1,
        mavstack_router::VersionMode::Mavlink2 => LinkMode::Mavlink2,
        mavstack_router::VersionMode::Auto => LinkMode::Auto,
        mavstack_router::VersionMode::Transparent => LinkMode::Transparent,
    }
}

pub(super) const fn conversions(c: &mavstack_router::Conversions) -> [(&'static str, u64); 4] {
    [
        ("to_mavlink1", c.to_mavlink1),
        ("to_mavlink2", c.to_mavlink2),
        ("signature_removed", c.signature_removed),
        ("signed", c.signed),
    ]
}
