//! Reading a file: bursts for what lies ahead, a window of ReadFile requests for the gaps
//! loss leaves behind them.
//!
//! While a burst streams the file onward, the holes it leaves (packets lost on the way) are
//! asked for with ReadFile, up to [`READ_WINDOW`] at once, each resent on its own timeout.
//! Filling holes one round trip at a time made a lossy, slow link cost a round trip per
//! lost packet; pymavlink's `mavftp` keeps five gap reads in flight too (`max_backlog`).

use alloc::vec;
use alloc::vec::Vec;

use mavstack_core::time::Instant;

use super::{FtpClient, FtpError, FtpEvent, FtpOutput, Op, Pending, Phase};
use crate::ftp::payload::{MAX_DATA, NakCode, Opcode, Payload};
use crate::ranges::{subtract, total};

/// ReadFile requests in flight at once.
pub(super) const READ_WINDOW: usize = 5;

#[derive(Debug)]
pub(super) struct Read {
    pub(super) phase: Phase,
    pub(super) session: u8,
    pub(super) data: Vec<u8>,
    /// Ranges still wanted, `[start, end)`, sorted and disjoint.
    missing: Vec<(u32, u32)>,
    /// The end of the furthest data received.
    high: u32,
    /// A burst ended with no data: use ReadFile from now on.
    no_burst: bool,
    /// Bytes still missing after the last reply, and replies since that brought none.
    left: u64,
    stalls: u16,
    /// ReadFile requests in flight, at most [`READ_WINDOW`].
    gaps: Vec<Pending>,
}

impl Read {
    /// A read about to open its file.
    pub(super) const fn new(burst: bool) -> Self {
        Self {
            phase: Phase::Open,
            session: 0,
            data: Vec::new(),
            missing: Vec::new(),
            high: 0,
            no_burst: !burst,
            left: u64::MAX,
            stalls: 0,
            gaps: Vec::new(),
        }
    }

    /// The file is `size` bytes long, all of them still wanted.
    pub(super) fn opened(&mut self, session: u8, size: u32) {
        self.session = session;
        self.phase = Phase::Transfer;
        self.data = vec![0; size as usize];
        if size > 0 {
            self.missing.push((0, size));
        }
    }

    /// The file ends at `end` (NAK EndOfFile), never before data already received.
    fn ends_at(&mut self, end: u32) {
        let end = end.max(self.high);
        let size = u32::try_from(self.data.len()).unwrap_or(u32::MAX);
        if end < size {
            self.data.truncate(end as usize);
            subtract(&mut self.missing, end, size);
        }
    }

    /// The next gap chunks to ask for with ReadFile: missing bytes below `limit` that no
    /// request in flight asks for, as many as the window has room for.
    fn gap_chunks(&self, limit: u32) -> Vec<(u32, u32)> {
        let room = READ_WINDOW.saturating_sub(self.gaps.len());
        let asked = |a: u32| {
            self.gaps.iter().find_map(|g| {
                let end = g.req.offset.saturating_add(g.req.data.len() as u32);
                (g.req.offset <= a && a < end).then_some(end)
            })
        };
        let mut out = Vec::new();
        for &(start, end) in &self.missing {
            let end = end.min(limit);
            let mut a = start;
            while a < end && out.len() < room {
                if let Some(next) = asked(a) {
                    a = next;
                    continue;
                }
                let next_asked = self
                    .gaps
                    .iter()
                    .map(|g| g.req.offset)
                    .filter(|&o| o > a)
                    .min()
                    .unwrap_or(u32::MAX);
                let b = end.min(a.saturating_add(MAX_DATA as u32)).min(next_asked);
                out.push((a, b));
                a = b;
            }
            if out.len() >= room || start >= limit {
                break;
            }
        }
        out
    }

    /// Where the next burst starts: the first missing byte at or past the furthest data.
    fn burst_start(&self) -> Option<u32> {
        self.missing
            .iter()
            .find(|&&(_, b)| b > self.high)
            .map(|&(a, _)| a.max(self.high))
    }
}

impl FtpClient {
    /// Keeps `bytes` at `offset` of the file being read, inside the announced size only.
    fn store(&mut self, offset: u32, bytes: &[u8]) {
        let Some(Op::Read(r)) = self.op.as_mut() else {
            return;
        };
        let size = u32::try_from(r.data.len()).unwrap_or(u32::MAX);
        let len = u32::try_from(bytes.len()).unwrap_or(u32::MAX);
        let start = offset.min(size);
        let end = offset.saturating_add(len).min(size);
        if start >= end {
            return;
        }
        let (s, e) = (start as usize, end as usize);
        let Some(src) = bytes.get(..e - s) else {
            return;
        };
        let Some(dst) = r.data.get_mut(s..e) else {
            return;
        };
        dst.copy_from_slice(src);
        subtract(&mut r.missing, start, end);
        r.high = r.high.max(end);
        let left: u64 = total(&r.missing);
        let total = u64::from(size);
        self.events.push_back(FtpEvent::Progress {
            done: total - left,
            total,
        });
    }

    /// Handles a reply to the burst in flight (`self.pending`).
    pub(super) fn on_burst_reply(&mut self, now: Instant, reply: &Payload) {
        let Some(Op::Read(r)) = self.op.as_mut() else {
            return;
        };
        if reply.opcode == Opcode::Nak {
            match reply.nak() {
                // The file ends before the size announced at open (ArduPilot announces
                // an estimate for `@PARAM/param.pck`): it ends there.
                Some((NakCode::Eof, _)) => r.ends_at(reply.offset),
                // A burst that fails before bringing anything: ReadFile from now on.
                _ => {
                    if self.pending.as_ref().is_some_and(|p| p.burst_packets == 0) {
                        r.no_burst = true;
                    }
                }
            }
            self.pending = None;
            self.next_read(now);
            return;
        }
        self.store(reply.offset, &reply.data);
        if reply.burst_complete {
            self.pending = None;
            self.next_read(now);
        } else if let Some(p) = self.pending.as_mut() {
            p.burst_packets += 1;
            p.deadline = now + self.rtt.backoff(self.config.timeout, 1);
        }
    }

    /// Takes a ReadFile reply if it answers a gap read in flight.
    pub(super) fn take_gap_reply(&mut self, now: Instant, reply: &Payload) -> bool {
        let Some(Op::Read(r)) = self.op.as_mut() else {
            return false;
        };
        let Some(i) = r
            .gaps
            .iter()
            .position(|g| reply.seq == g.req.seq.wrapping_add(1) && reply.session == g.req.session)
        else {
            return false;
        };
        let gap = r.gaps.swap_remove(i);
        if gap.attempt == 1 {
            self.rtt.sample(gap.sent, now);
        }
        if reply.opcode == Opcode::Nak {
            match reply.nak() {
                Some((NakCode::Eof, _)) => r.ends_at(gap.req.offset),
                n => {
                    let (code, errno) = n.unwrap_or((NakCode::None, None));
                    self.fail_read(FtpError::Nak { code, errno });
                    return true;
                }
            }
        } else if reply.offset <= gap.req.offset {
            // Keep only the range asked for, wherever the reply says it is.
            let skip = (gap.req.offset - reply.offset) as usize;
            let bytes = reply.data.get(skip..).unwrap_or(&[]);
            let bytes = &bytes[..bytes.len().min(gap.req.data.len())];
            self.store(gap.req.offset, bytes);
        }
        self.next_read(now);
        true
    }

    /// Resends the gap reads whose time is up; fails the read when one has had every
    /// attempt.
    pub(super) fn gap_timeouts(&mut self, now: Instant) {
        let attempts = self.config.attempts;
        let Some(Op::Read(r)) = self.op.as_mut() else {
            return;
        };
        let due = |g: &&Pending| now >= g.deadline;
        if let Some(attempts) = r
            .gaps
            .iter()
            .filter(due)
            .find(|g| g.attempt >= attempts)
            .map(|g| g.attempt)
        {
            self.fail_read(FtpError::TimedOut { attempts });
            return;
        }
        let mut resend = Vec::new();
        for g in r.gaps.iter_mut().filter(|g| now >= g.deadline) {
            g.attempt += 1;
            g.sent = now;
            g.deadline = now + self.rtt.backoff(self.config.timeout, g.attempt);
            resend.push(g.req.clone());
        }
        for req in &resend {
            self.transmit(req);
        }
    }

    /// The earliest deadline of the gap reads in flight.
    pub(super) fn gap_deadline(&self) -> Option<Instant> {
        match &self.op {
            Some(Op::Read(r)) => r.gaps.iter().map(|g| g.deadline).min(),
            _ => None,
        }
    }

    /// Ends the read with `error`, closing its session with one TerminateSession.
    fn fail_read(&mut self, error: FtpError) {
        if let Some(Op::Read(r)) = &self.op {
            let req = Self::request(Opcode::TerminateSession, r.session, 0, &[]);
            self.transmit(&req);
        }
        self.finish(Err(error));
    }

    /// Asks for what is still missing: gap reads up to the window, a burst for what lies
    /// past the furthest data when none is streaming, TerminateSession when all is here.
    pub(super) fn next_read(&mut self, now: Instant) {
        let window = usize::from(self.config.attempts) * (READ_WINDOW + 1);
        // The request answered last (an open, a burst that ended) waits no more; only a
        // burst still streaming does.
        if !self.bursting() {
            self.pending = None;
        }
        let Some(Op::Read(r)) = self.op.as_mut() else {
            return;
        };
        let left: u64 = total(&r.missing);
        if left < r.left {
            r.left = left;
            r.stalls = 0;
        } else {
            r.stalls = r.stalls.saturating_add(1);
            if usize::from(r.stalls) > window {
                // Replies keep coming and bring nothing asked for.
                self.fail_read(FtpError::Protocol);
                return;
            }
        }
        if r.missing.is_empty() {
            r.gaps.clear();
            r.phase = Phase::Terminate;
            let req = Self::request(Opcode::TerminateSession, r.session, 0, &[]);
            self.send(now, req);
            return;
        }
        let limit = if r.no_burst { u32::MAX } else { r.high };
        let session = r.session;
        for (a, b) in r.gap_chunks(limit) {
            let req = Self::request(Opcode::ReadFile, session, a, &vec![0; (b - a) as usize]);
            let gap = self.pending_for(now, req);
            if let Some(Op::Read(r)) = self.op.as_mut() {
                r.gaps.push(gap);
            }
        }
        let burst_at = match &self.op {
            Some(Op::Read(r)) if !r.no_burst => r.burst_start(),
            _ => None,
        };
        if let Some(at) = burst_at.filter(|_| !self.bursting()) {
            let req = Self::request(Opcode::BurstReadFile, session, at, &[0; MAX_DATA]);
            self.send(now, req);
        }
        if self.pending.is_none() && matches!(&self.op, Some(Op::Read(r)) if r.gaps.is_empty()) {
            // Bytes are missing and nothing could ask for them.
            self.fail_read(FtpError::Protocol);
        }
    }

    /// Whether a burst is streaming.
    fn bursting(&self) -> bool {
        self.pending
            .as_ref()
            .is_some_and(|p| p.req.opcode == Opcode::BurstReadFile)
    }

    /// The data of a finished read.
    pub(super) fn read_done(&mut self) {
        if let Some(Op::Read(r)) = self.op.as_mut() {
            let data = core::mem::take(&mut r.data);
            self.finish(Ok(FtpOutput::Data(data)));
        }
    }
}
