//! System id remapping on the ground side, for fleets whose vehicles share a sysid.
//!
//! A fleet reuses sysids (every vehicle out of the box is system 1), but the ground
//! stations on one ground router must see distinct systems. Each (vehicle, sysid) pair gets
//! a local sysid: its own while no other vehicle holds it, else the lowest free one from 1 up
//! (never 0, and never 255 nor 254 — ground stations' ids). The mapping is kept for as long as
//! the router runs, so it is stable, and reversible:
//!
//! - every frame of a message the dialect knows has its checksum checked first: a corrupt
//!   one is dropped ([`Remapped::Corrupt`]), whether or not it would have been rewritten, so
//!   that no rewrite ever gives a corrupt frame a valid checksum;
//! - frames from a vehicle: the header's sysid becomes the local one and the checksum is
//!   written again (the dialect's CRC_EXTRA; an id it does not know cannot be checked, so
//!   cannot be remapped, and is dropped, as is a signed frame, whose signature covers the
//!   header);
//! - frames to a vehicle: a `target_system` that is a local id of that vehicle becomes the
//!   vehicle's own again (the dialect's target offset), checksum rewritten; a signed frame
//!   goes as it is.
//!
//! Frames of a vehicle whose sysid is not remapped pass untouched, signatures included.
//!
//! ```
//! use mavstack_bridge::remap::SysidMap;
//! let mut map = SysidMap::default();
//! assert_eq!(map.local("truck-1", 1), Some(1));
//! assert_eq!(map.local("truck-2", 1), Some(2));   // 1 is taken
//! assert_eq!(map.local("truck-2", 1), Some(2));   // stable
//! assert_eq!(map.vehicle(2), Some(("truck-2", 1))); // reversible
//! ```

use std::collections::HashMap;

use mavstack_core::MessageInfo;
use mavstack_core::wire::Frame;

/// Local ids that are never handed out: broadcast, and the usual ground station ids.
const RESERVED: [u8; 3] = [0, 254, 255];

/// The mapping (see the module's documentation).
#[derive(Debug, Default)]
pub struct SysidMap {
    by_vehicle: HashMap<(String, u8), u8>,
    /// Local sysid → (vehicle, its sysid).
    by_local: HashMap<u8, (String, u8)>,
    remapped: u64,
    dropped: u64,
    corrupt: u64,
}

/// What became of a frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Remapped {
    /// It goes as it was.
    Same,
    /// It goes rewritten (these bytes).
    Rewritten(Vec<u8>),
    /// It cannot go (signed or of an unknown id, from a remapped vehicle; no free id).
    Dropped,
    /// Its checksum is wrong: it is dropped, never rewritten.
    Corrupt,
}

impl SysidMap {
    /// The local sysid of `sysid` of vehicle `vid` (given now if new); `None` when every id
    /// is taken.
    pub fn local(&mut self, vid: &str, sysid: u8) -> Option<u8> {
        if let Some(&l) = self.by_vehicle.get(&(vid.to_owned(), sysid)) {
            return Some(l);
        }
        let free = |l: &u8| !self.by_local.contains_key(l) && !RESERVED.contains(l);
        let local = if free(&sysid) {
            sysid
        } else {
            (1..=253u8).find(free)?
        };
        if local != sysid {
            tracing::info!("fleet: vehicle {vid}'s system {sysid} is system {local} here");
        }
        self.by_vehicle.insert((vid.to_owned(), sysid), local);
        self.by_local.insert(local, (vid.to_owned(), sysid));
        Some(local)
    }

    /// The vehicle and its own sysid behind local sysid `local`.
    #[must_use]
    pub fn vehicle(&self, local: u8) -> Option<(&str, u8)> {
        self.by_local.get(&local).map(|(v, s)| (v.as_str(), *s))
    }

    /// A frame from vehicle `vid`, for the local side.
    pub fn from_vehicle(
        &mut self,
        vid: &str,
        frame: &[u8],
        info: impl Fn(u32) -> Option<MessageInfo>,
    ) -> Remapped {
        let Ok(view) = Frame::new_checked(frame) else {
            return Remapped::Same;
        };
        // Before anything else: a corrupt sysid must not take a local id either.
        let info = info(view.msg_id());
        if info.is_some_and(|i| !view.check_crc(i.crc_extra)) {
            self.corrupt += 1;
            return Remapped::Corrupt;
        }
        let Some(local) = self.local(vid, view.sysid()) else {
            self.dropped += 1;
            return Remapped::Dropped;
        };
        if local == view.sysid() {
            return Remapped::Same;
        }
        let Some(info) = info.filter(|_| !view.is_signed()) else {
            self.dropped += 1;
            return Remapped::Dropped;
        };
        self.rewrite(&frame[..view.frame_len()], info.crc_extra, |f| {
            f.set_sysid(local)
        })
    }

    /// A frame for vehicle `vid`: its target system back to the vehicle's own id.
    pub fn to_vehicle(
        &mut self,
        vid: &str,
        frame: &[u8],
        info: impl Fn(u32) -> Option<MessageInfo>,
    ) -> Remapped {
        let Ok(view) = Frame::new_checked(frame) else {
            return Remapped::Same;
        };
        let Some(info) = info(view.msg_id()) else {
            return Remapped::Same;
        };
        if !view.check_crc(info.crc_extra) {
            self.corrupt += 1;
            return Remapped::Corrupt;
        }
        let Some(at) = info.target_system_offset.map(usize::from) else {
            return Remapped::Same;
        };
        let Some(&target) = view.payload().get(at) else {
            return Remapped::Same;
        };
        let own = match self.by_local.get(&target) {
            Some((v, own)) if v == vid && *own != target => *own,
            _ => return Remapped::Same,
        };
        if view.is_signed() {
            return Remapped::Same;
        }
        self.rewrite(&frame[..view.frame_len()], info.crc_extra, |f| {
            f.payload_mut()[at] = own;
        })
    }

    /// A copy of `frame` changed by `change`, its checksum written again.
    fn rewrite(
        &mut self,
        frame: &[u8],
        crc_extra: u8,
        change: impl FnOnce(&mut Frame<&mut [u8]>),
    ) -> Remapped {
        let mut out = frame.to_vec();
        let mut f = Frame::new_unchecked(&mut out[..]);
        change(&mut f);
        f.fill_checksum(crc_extra);
        self.remapped += 1;
        Remapped::Rewritten(out)
    }

    /// Frames rewritten, and frames dropped because they could not be.
    #[must_use]
    pub const fn counts(&self) -> (u64, u64) {
        (self.remapped, self.dropped)
    }

    /// Frames dropped because their checksum was wrong.
    #[must_use]
    pub const fn corrupt(&self) -> u64 {
        self.corrupt
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_core::MessageSet as _;
    use mavstack_core::wire::{FrameHeader, Version, emit_message};
    use mavstack_dialects::common::{Attitude, CommandLong, MavCmd, MavMessage};

    fn info(id: u32) -> Option<MessageInfo> {
        MavMessage::info(id).copied()
    }

    fn frame<M: mavstack_core::Message>(sysid: u8, m: &M) -> Vec<u8> {
        let header = FrameHeader {
            version: Version::V2,
            seq: 3,
            sysid,
            compid: 1,
            signed: false,
        };
        let mut out = [0u8; 280];
        let n = emit_message(&header, m, &mut out).unwrap();
        out[..n].to_vec()
    }

    #[test]
    fn a_second_vehicle_with_the_same_sysid_is_rewritten_both_ways() {
        let mut map = SysidMap::default();
        let att = Attitude {
            roll: 0.5,
            ..Default::default()
        };
        assert_eq!(map.from_vehicle("a", &frame(1, &att), info), Remapped::Same);
        let Remapped::Rewritten(b) = map.from_vehicle("b", &frame(1, &att), info) else {
            panic!("not rewritten")
        };
        // Exactly what the vehicle would have sent as system 2.
        assert_eq!(b, frame(2, &att));
        let cmd = |target| CommandLong {
            target_system: target,
            target_component: 1,
            command: MavCmd::COMPONENT_ARM_DISARM,
            ..Default::default()
        };
        let from_gcs = frame(255, &cmd(2));
        assert_eq!(
            map.to_vehicle("b", &from_gcs, info),
            Remapped::Rewritten(frame(255, &cmd(1)))
        );
        // Vehicle a's own id, and broadcasts, are left alone.
        assert_eq!(
            map.to_vehicle("a", &frame(255, &cmd(1)), info),
            Remapped::Same
        );
        assert_eq!(
            map.to_vehicle("b", &frame(255, &cmd(0)), info),
            Remapped::Same
        );
        assert_eq!(map.counts(), (2, 0));
    }

    #[test]
    fn frames_that_cannot_be_rewritten_are_dropped_and_reserved_ids_never_given() {
        let mut map = SysidMap::default();
        map.local("a", 7);
        let mut unknown = frame(7, &Attitude::default());
        unknown[7] = 0xEE; // an id no dialect has (the CRC no longer matters)
        assert_eq!(map.from_vehicle("b", &unknown, info), Remapped::Dropped);
        for v in 0..260 {
            if let Some(l) = map.local(&format!("v{v}"), 255) {
                assert!(!RESERVED.contains(&l));
            }
        }
        assert_eq!(map.local("late", 9), None, "every id taken");
    }

    #[test]
    fn corrupt_frames_are_dropped_never_given_a_fresh_checksum() {
        let mut map = SysidMap::default();
        let att = Attitude {
            roll: 0.5,
            ..Default::default()
        };
        map.local("a", 1);
        let mut corrupt = frame(1, &att);
        corrupt[14] ^= 0x01; // a payload byte: the checksum no longer matches
        // Vehicle b's system 1 would be rewritten as 2; corrupt, it is dropped.
        assert_eq!(map.from_vehicle("b", &corrupt, info), Remapped::Corrupt);
        // Vehicle a's would go as it is; corrupt, it is dropped all the same.
        assert_eq!(map.from_vehicle("a", &corrupt, info), Remapped::Corrupt);
        // A corrupt sysid never takes a local id.
        let mut bad_sysid = frame(9, &att);
        bad_sysid[5] = 77;
        assert_eq!(map.from_vehicle("b", &bad_sysid, info), Remapped::Corrupt);
        assert_eq!(map.vehicle(77), None);
        // Towards a remapped vehicle: the target would be rewritten; corrupt, dropped.
        assert_eq!(map.local("b", 1), Some(2));
        let cmd = CommandLong {
            target_system: 2,
            target_component: 1,
            command: MavCmd::COMPONENT_ARM_DISARM,
            ..Default::default()
        };
        let mut to_b = frame(255, &cmd);
        to_b[12] ^= 0x40;
        assert_eq!(map.to_vehicle("b", &to_b, info), Remapped::Corrupt);
        assert_eq!(map.corrupt(), 4);
        assert_eq!(map.counts(), (0, 0));
    }
}
