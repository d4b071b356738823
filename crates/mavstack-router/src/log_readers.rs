//! Where a vehicle's LOG_DATA goes: to the link that asked for the log.
//!
//! LOG_DATA (120) has no target fields, so by the routing rules it is a broadcast: a log a
//! ground station downloads through a router would be copied to every other link (a
//! telemetry radio among them) at the full rate the vehicle streams it. The request that
//! starts a download, LOG_REQUEST_DATA (119), is targeted, so the router learns from it
//! which link is reading which system's log and sends that system's LOG_DATA there only.
//!
//! An entry lives while the transfer does: each request and each LOG_DATA routed by it
//! renews it, LOG_REQUEST_END (122) from the reading link ends it, and it is forgotten after
//! [`IDLE`] without either or when its link goes. At most one entry per system id (a vehicle
//! serves one log transfer at a time; the newest request wins), so a stranger cannot grow
//! the table beyond 255 entries.

use core::time::Duration;

use mavstack_core::time::Instant;

use crate::router::LinkId;

/// LOG_REQUEST_DATA's message id.
pub const LOG_REQUEST_DATA: u32 = 119;
/// LOG_DATA's message id.
pub const LOG_DATA: u32 = 120;
/// LOG_REQUEST_END's message id.
pub const LOG_REQUEST_END: u32 = 122;

/// How long a transfer may go quiet (no request, no data) before its LOG_DATA is broadcast
/// again.
pub const IDLE: Duration = Duration::from_secs(5);

#[derive(Clone, Copy, Debug)]
struct Reader {
    link: LinkId,
    last: Instant,
}

/// The link reading each system's log, by system id.
#[derive(Clone, Debug)]
pub struct LogReaders {
    by_system: [Option<Reader>; 256],
}

impl Default for LogReaders {
    fn default() -> Self {
        Self {
            by_system: [None; 256],
        }
    }
}

impl LogReaders {
    /// `link` asked system `sysid` for log data at `now`.
    pub fn asked(&mut self, now: Instant, sysid: u8, link: LinkId) {
        self.by_system[usize::from(sysid)] = Some(Reader { link, last: now });
    }

    /// `link` ended its transfer from system `sysid` (a request from another link ends
    /// nothing).
    pub fn ended(&mut self, sysid: u8, link: LinkId) {
        let slot = &mut self.by_system[usize::from(sysid)];
        if slot.is_some_and(|r| r.link == link) {
            *slot = None;
        }
    }

    /// The link to send LOG_DATA from system `sysid` to, renewing its entry; `None` when no
    /// fresh transfer is known (the frame is then a broadcast).
    pub fn reader(&mut self, now: Instant, sysid: u8) -> Option<LinkId> {
        let slot = &mut self.by_system[usize::from(sysid)];
        match slot {
            Some(r) if now.saturating_duration_since(r.last) < IDLE => {
                r.last = now;
                Some(r.link)
            }
            Some(_) => {
                *slot = None;
                None
            }
            None => None,
        }
    }

    /// Forgets the transfers read through `link` (it was removed).
    pub fn forget_link(&mut self, link: LinkId) {
        for slot in &mut self.by_system {
            if slot.is_some_and(|r| r.link == link) {
                *slot = None;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: LinkId = LinkId::new(0);
    const B: LinkId = LinkId::new(1);

    fn at(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }

    #[test]
    fn a_transfer_lives_while_data_flows_and_ends_on_request_end() {
        let mut r = LogReaders::default();
        assert_eq!(r.reader(at(0), 1), None);
        r.asked(at(0), 1, A);
        // Data keeps it alive well past IDLE after the one request.
        for s in 1..20 {
            assert_eq!(r.reader(at(s * 1000), 1), Some(A));
        }
        assert_eq!(
            r.reader(at(19_500), 2),
            None,
            "another system's data is not A's"
        );
        r.ended(1, B);
        assert_eq!(
            r.reader(at(20_000), 1),
            Some(A),
            "B cannot end A's transfer"
        );
        r.ended(1, A);
        assert_eq!(r.reader(at(20_001), 1), None);
    }

    #[test]
    fn a_quiet_transfer_expires_and_the_newest_request_wins() {
        let mut r = LogReaders::default();
        r.asked(at(0), 7, A);
        assert_eq!(r.reader(at(5_000), 7), None);
        r.asked(at(6_000), 7, A);
        r.asked(at(6_001), 7, B);
        assert_eq!(r.reader(at(6_002), 7), Some(B));
        r.forget_link(B);
        assert_eq!(r.reader(at(6_003), 7), None);
    }
}
