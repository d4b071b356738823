//! The systems a router has heard: the latest HEARTBEAT of each (sysid, compid), where it
//! came from and when, for status pages and reports.
//!
//! ```
//! use core::time::Duration;
//! use mavstack_core::time::Instant;
//! use mavstack_router::LinkId;
//! use mavstack_router::systems::Systems;
//! let mut systems = Systems::default();
//! // A quadrotor (type 2), ArduPilot (autopilot 3), armed (base_mode bit 7), custom mode 4.
//! let payload = [4, 0, 0, 0, 2, 3, 0x81, 4, 3];
//! systems.heard(Instant::from_secs(1), (1, 1), LinkId::new(0), &payload);
//! let s = systems.iter().next().unwrap();
//! assert_eq!((s.sysid, s.mav_type, s.autopilot, s.custom_mode), (1, 2, 3, 4));
//! assert!(s.armed());
//! systems.expire(Instant::from_secs(40), Duration::from_secs(30));
//! assert_eq!(systems.iter().count(), 0);
//! ```

use alloc::collections::BTreeMap;
use core::time::Duration;

use mavstack_core::time::Instant;

use crate::router::LinkId;

/// How many components the table keeps: beyond, the one heard longest ago makes room.
pub const CAPACITY: usize = 1024;

/// One component's latest HEARTBEAT.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct SystemInfo {
    /// System id.
    pub sysid: u8,
    /// Component id.
    pub compid: u8,
    /// `MAV_TYPE`.
    pub mav_type: u8,
    /// `MAV_AUTOPILOT`.
    pub autopilot: u8,
    /// `MAV_MODE_FLAG` bits.
    pub base_mode: u8,
    /// The autopilot's own mode number.
    pub custom_mode: u32,
    /// `MAV_STATE`.
    pub system_status: u8,
    /// The link the HEARTBEAT came in on.
    pub link: LinkId,
    /// When.
    pub last_seen: Instant,
}

impl SystemInfo {
    /// Whether `MAV_MODE_FLAG_SAFETY_ARMED` is set.
    #[must_use]
    pub const fn armed(&self) -> bool {
        self.base_mode & 0x80 != 0
    }
}

/// The table of [`SystemInfo`], by (sysid, compid).
#[derive(Clone, Debug, Default)]
pub struct Systems {
    entries: BTreeMap<(u8, u8), SystemInfo>,
}

impl Systems {
    /// Records a HEARTBEAT payload (as received: a truncated one is zero-extended) from
    /// `source` on `link`.
    pub fn heard(&mut self, now: Instant, source: (u8, u8), link: LinkId, payload: &[u8]) {
        let mut p = [0u8; 9];
        let n = payload.len().min(p.len());
        p[..n].copy_from_slice(&payload[..n]);
        if self.entries.len() >= CAPACITY
            && !self.entries.contains_key(&source)
            && let Some(oldest) = self
                .entries
                .values()
                .min_by_key(|s| s.last_seen)
                .map(|s| (s.sysid, s.compid))
        {
            self.entries.remove(&oldest);
        }
        self.entries.insert(
            source,
            SystemInfo {
                sysid: source.0,
                compid: source.1,
                custom_mode: u32::from_le_bytes([p[0], p[1], p[2], p[3]]),
                mav_type: p[4],
                autopilot: p[5],
                base_mode: p[6],
                system_status: p[7],
                link,
                last_seen: now,
            },
        );
    }

    /// Forgets components silent for longer than `ttl`.
    pub fn expire(&mut self, now: Instant, ttl: Duration) {
        self.entries
            .retain(|_, s| now.saturating_duration_since(s.last_seen) <= ttl);
    }

    /// Forgets what came in on `link` (a link that went away).
    pub fn forget_link(&mut self, link: LinkId) {
        self.entries.retain(|_, s| s.link != link);
    }

    /// Every component heard, by (sysid, compid).
    pub fn iter(&self) -> impl Iterator<Item = &SystemInfo> + '_ {
        self.entries.values()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_table_makes_room_by_dropping_the_component_heard_longest_ago() {
        let mut systems = Systems::default();
        let link = LinkId::new(0);
        for i in 0..CAPACITY {
            let at = Instant::from_micros(1_000 + i as u64);
            systems.heard(at, ((i / 256) as u8, i as u8), link, &[]);
        }
        systems.heard(Instant::from_secs(5), (200, 200), link, &[0, 0, 0, 0, 1]);
        assert_eq!(systems.iter().count(), CAPACITY);
        assert!(!systems.iter().any(|s| (s.sysid, s.compid) == (0, 0)));
        assert!(
            systems
                .iter()
                .any(|s| (s.sysid, s.compid, s.mav_type) == (200, 200, 1))
        );
    }
}
