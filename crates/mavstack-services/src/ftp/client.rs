//! The FTP client role: [`FtpClient`], one operation at a time against one server.

use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{FileTransferProtocol, MavMessage};

use super::payload::{DirEntry, MAX_DATA, NakCode, Opcode, Payload, parse_entries};
use crate::rtt::Rtt;
use crate::{Address, Outgoing, Service};
use read::Read;

mod read;

/// [`FtpClient`] settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClientConfig {
    /// The longest wait for a reply (the adaptive timeout's ceiling and its value until a
    /// round trip is measured).
    pub timeout: Duration,
    /// Sends of one request before the operation fails.
    pub attempts: u8,
    /// Sends of an operation's first request (the one that shows whether a server is there
    /// at all) before the operation fails; 0: as [`attempts`](Self::attempts). A caller that
    /// can fall back to another way sets it low and keeps `attempts` for a transfer under
    /// way.
    pub first_attempts: u8,
    /// The largest file [`FtpClient::read`] accepts: a larger announced size fails with
    /// [`FtpError::TooLarge`] before anything is allocated.
    pub max_read_size: u32,
    /// Read with BurstReadFile (gaps filled with ReadFile); `false` reads with ReadFile
    /// only.
    pub burst: bool,
    /// Listing entries accepted at most (a server listing forever fails).
    pub max_entries: usize,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(500),
            attempts: 5,
            first_attempts: 0,
            max_read_size: 16 << 20,
            burst: true,
            max_entries: 65_536,
        }
    }
}

/// What a finished operation produced.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FtpOutput {
    /// A directory's entries ([`FtpClient::list`]).
    Listing(Vec<DirEntry>),
    /// A file's contents ([`FtpClient::read`]).
    Data(Vec<u8>),
    /// A file's CRC32 as servers compute it ([`crc32`](super::crc32)).
    Crc32(u32),
    /// Done (write, remove, mkdir, rmdir, rename).
    Done,
}

/// How an operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FtpError {
    /// No reply after every attempt.
    #[error("no reply after {attempts} attempts")]
    TimedOut {
        /// Sends of the last request.
        attempts: u8,
    },
    /// The server refused.
    #[error("refused: {code:?} (errno {errno:?})")]
    Nak {
        /// The NAK code.
        code: NakCode,
        /// The errno of a FailErrno NAK.
        errno: Option<u8>,
    },
    /// The file is larger than [`ClientConfig::max_read_size`].
    #[error("file of {size} bytes is too large")]
    TooLarge {
        /// The size the server announced.
        size: u32,
    },
    /// The server's reply made no sense (a listing without end, an ACK without its data).
    #[error("malformed reply")]
    Protocol,
    /// [`FtpClient::cancel`].
    #[error("cancelled")]
    Cancelled,
}

/// Why an operation could not start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum StartError {
    /// Another operation is under way.
    #[error("another operation is under way")]
    Busy,
    /// The path (or both of a rename's) does not fit a payload's 239 data bytes.
    #[error("path too long")]
    PathTooLong,
}

/// What [`FtpClient::poll_event`] reports.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FtpEvent {
    /// Bytes transferred so far by a read or write, and the total.
    Progress {
        /// Bytes so far.
        done: u64,
        /// Bytes in all.
        total: u64,
    },
    /// The operation ended.
    Finished(Result<FtpOutput, FtpError>),
}

#[derive(Debug)]
struct Pending {
    req: Payload,
    sent: Instant,
    attempt: u8,
    deadline: Instant,
    /// Burst packets received for this request.
    burst_packets: u32,
    /// The operation's first request ([`ClientConfig::first_attempts`]).
    first: bool,
}

#[derive(Debug, PartialEq, Eq)]
enum Phase {
    Open,
    Transfer,
    Terminate,
}

#[derive(Debug)]
struct Write {
    phase: Phase,
    session: u8,
    data: Vec<u8>,
    acked: usize,
}

#[derive(Debug)]
enum Op {
    List {
        path: Vec<u8>,
        entries: Vec<DirEntry>,
    },
    Read(Read),
    Write(Write),
    Simple,
    Crc,
}

/// A MAVLink FTP client for one server, sans-IO like every [`Service`].
///
/// Start one operation ([`list`](Self::list), [`read`](Self::read),
/// [`write`](Self::write), [`remove`](Self::remove), [`mkdir`](Self::mkdir),
/// [`rmdir`](Self::rmdir), [`rename`](Self::rename), [`crc32`](Self::crc32)), drive it
/// with the [`Service`] calls, and take [`FtpEvent`]s from [`poll_event`](Self::poll_event)
/// until [`FtpEvent::Finished`]. Requests are resent after an adaptive timeout (RFC 6298
/// estimate, doubled per resend, at most [`ClientConfig::timeout`]) up to
/// [`ClientConfig::attempts`] times; replies are matched by sequence number, so late
/// duplicates are ignored. Reads keep only bytes inside the announced size, whatever
/// offsets the server sends; a NAK EndOfFile before that size ends the file there
/// (ArduPilot announces an estimate, 12 bytes a parameter, for `@PARAM/param.pck`).
#[derive(Debug)]
pub struct FtpClient {
    me: Address,
    server: Address,
    config: ClientConfig,
    rtt: Rtt,
    seq: u16,
    op: Option<Op>,
    pending: Option<Pending>,
    queue: VecDeque<Outgoing>,
    events: VecDeque<FtpEvent>,
}

fn path_bytes(path: &str) -> Result<Vec<u8>, StartError> {
    if path.len() > MAX_DATA {
        return Err(StartError::PathTooLong);
    }
    Ok(path.as_bytes().to_vec())
}

impl FtpClient {
    /// A client at `me` talking to the server at `server`.
    #[must_use]
    pub fn new(me: Address, server: Address, config: ClientConfig) -> Self {
        Self {
            me,
            server,
            config,
            rtt: Rtt::default(),
            seq: 0,
            op: None,
            pending: None,
            queue: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// Starts its sequence numbers after `seq`: its first request carries `seq + 1`.
    ///
    /// Give each client of one server a number where the last one stopped
    /// ([`last_seq`](Self::last_seq)), or one taken at random: ArduPilot answers a request
    /// whose sysid, compid, session and sequence number are those of the last request it
    /// answered by sending that old reply again, so a new client starting where a finished
    /// one started (same ids, session 0) can be given the answer to another question (a
    /// `FileNotFound` for every listing after one of a missing path, seen with SITL).
    #[must_use]
    pub const fn starting_after(mut self, seq: u16) -> Self {
        self.seq = seq;
        self
    }

    /// The sequence number of its last request.
    #[must_use]
    pub const fn last_seq(&self) -> u16 {
        self.seq
    }

    /// Whether an operation is under way.
    #[must_use]
    pub const fn is_busy(&self) -> bool {
        self.op.is_some()
    }

    /// The next event, if any.
    pub fn poll_event(&mut self) -> Option<FtpEvent> {
        self.events.pop_front()
    }

    fn start(&mut self, now: Instant, op: Op, req: Payload) -> Result<(), StartError> {
        if self.op.is_some() {
            return Err(StartError::Busy);
        }
        self.op = Some(op);
        self.send(now, req);
        if let Some(p) = self.pending.as_mut() {
            p.first = true;
        }
        Ok(())
    }

    fn request(opcode: Opcode, session: u8, offset: u32, data: &[u8]) -> Payload {
        Payload::request(0, session, opcode, offset, data)
    }

    /// Lists the directory at `path`.
    ///
    /// # Errors
    ///
    /// [`StartError`] if busy or the path is too long.
    pub fn list(&mut self, now: Instant, path: &str) -> Result<(), StartError> {
        let path = path_bytes(path)?;
        let req = Self::request(Opcode::ListDirectory, 0, 0, &path);
        self.start(
            now,
            Op::List {
                path,
                entries: Vec::new(),
            },
            req,
        )
    }

    /// Reads the file at `path` (OpenFileRO, then BurstReadFile or ReadFile, then
    /// TerminateSession).
    ///
    /// # Errors
    ///
    /// [`StartError`] if busy or the path is too long.
    pub fn read(&mut self, now: Instant, path: &str) -> Result<(), StartError> {
        let path = path_bytes(path)?;
        let op = Op::Read(Read::new(self.config.burst));
        self.start(now, op, Self::request(Opcode::OpenFileRO, 0, 0, &path))
    }

    /// Writes `contents` to the file at `path`, created or truncated (CreateFile, WriteFile
    /// chunks, TerminateSession).
    ///
    /// # Errors
    ///
    /// [`StartError`] if busy or the path is too long.
    pub fn write(&mut self, now: Instant, path: &str, contents: &[u8]) -> Result<(), StartError> {
        let path = path_bytes(path)?;
        let op = Op::Write(Write {
            phase: Phase::Open,
            session: 0,
            data: contents.to_vec(),
            acked: 0,
        });
        self.start(now, op, Self::request(Opcode::CreateFile, 0, 0, &path))
    }

    fn simple(&mut self, now: Instant, opcode: Opcode, path: &str) -> Result<(), StartError> {
        let path = path_bytes(path)?;
        self.start(now, Op::Simple, Self::request(opcode, 0, 0, &path))
    }

    /// Removes the file at `path`.
    ///
    /// # Errors
    ///
    /// [`StartError`] if busy or the path is too long.
    pub fn remove(&mut self, now: Instant, path: &str) -> Result<(), StartError> {
        self.simple(now, Opcode::RemoveFile, path)
    }

    /// Creates the directory at `path`.
    ///
    /// # Errors
    ///
    /// [`StartError`] if busy or the path is too long.
    pub fn mkdir(&mut self, now: Instant, path: &str) -> Result<(), StartError> {
        self.simple(now, Opcode::CreateDirectory, path)
    }

    /// Removes the empty directory at `path`.
    ///
    /// # Errors
    ///
    /// [`StartError`] if busy or the path is too long.
    pub fn rmdir(&mut self, now: Instant, path: &str) -> Result<(), StartError> {
        self.simple(now, Opcode::RemoveDirectory, path)
    }

    /// Renames `from` to `to`.
    ///
    /// # Errors
    ///
    /// [`StartError`] if busy or the paths are too long together.
    pub fn rename(&mut self, now: Instant, from: &str, to: &str) -> Result<(), StartError> {
        if from.len() + 1 + to.len() > MAX_DATA {
            return Err(StartError::PathTooLong);
        }
        let mut data = Vec::from(from.as_bytes());
        data.push(0);
        data.extend_from_slice(to.as_bytes());
        self.start(now, Op::Simple, Self::request(Opcode::Rename, 0, 0, &data))
    }

    /// Asks for the CRC32 of the file at `path`.
    ///
    /// # Errors
    ///
    /// [`StartError`] if busy or the path is too long.
    pub fn crc32(&mut self, now: Instant, path: &str) -> Result<(), StartError> {
        let path = path_bytes(path)?;
        self.start(
            now,
            Op::Crc,
            Self::request(Opcode::CalcFileCRC32, 0, 0, &path),
        )
    }

    /// Abandons the operation under way ([`FtpError::Cancelled`]); an open session is
    /// closed with one unacknowledged TerminateSession.
    pub fn cancel(&mut self, now: Instant) {
        let session = match &self.op {
            None => return,
            Some(Op::Read(r)) if r.phase != Phase::Open => Some(r.session),
            Some(Op::Write(w)) if w.phase != Phase::Open => Some(w.session),
            Some(_) => None,
        };
        if let Some(session) = session {
            self.send(
                now,
                Self::request(Opcode::TerminateSession, session, 0, &[]),
            );
        }
        self.finish(Err(FtpError::Cancelled));
    }

    fn send(&mut self, now: Instant, req: Payload) {
        self.pending = Some(self.pending_for(now, req));
    }

    /// Numbers and transmits `req`, and returns it as a request waiting for its reply.
    fn pending_for(&mut self, now: Instant, mut req: Payload) -> Pending {
        self.seq = self.seq.wrapping_add(1);
        req.seq = self.seq;
        self.transmit(&req);
        Pending {
            deadline: now + self.rtt.backoff(self.config.timeout, 1),
            req,
            sent: now,
            attempt: 1,
            burst_packets: 0,
            first: false,
        }
    }

    fn transmit(&mut self, req: &Payload) {
        self.queue.push_back(Outgoing {
            target: self.server,
            message: MavMessage::FileTransferProtocol(FileTransferProtocol {
                target_network: 0,
                target_system: self.server.system,
                target_component: self.server.component,
                payload: req.encode(),
            }),
        });
    }

    fn finish(&mut self, result: Result<FtpOutput, FtpError>) {
        self.op = None;
        self.pending = None;
        self.events.push_back(FtpEvent::Finished(result));
    }

    /// Handles one reply that matches the pending request.
    fn on_reply(&mut self, now: Instant, reply: &Payload) {
        let Some(op) = self.op.as_mut() else {
            return;
        };
        let nak = if reply.opcode == Opcode::Nak {
            Some(reply.nak().unwrap_or((NakCode::None, None)))
        } else {
            None
        };
        let refused = |(code, errno): (NakCode, Option<u8>)| FtpError::Nak { code, errno };
        match op {
            Op::Simple => match nak {
                Some(n) => self.finish(Err(refused(n))),
                None => self.finish(Ok(FtpOutput::Done)),
            },
            Op::Crc => match (nak, reply.data.get(..4)) {
                (Some(n), _) => self.finish(Err(refused(n))),
                (None, Some(b)) => {
                    let crc = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                    self.finish(Ok(FtpOutput::Crc32(crc)));
                }
                (None, None) => self.finish(Err(FtpError::Protocol)),
            },
            Op::List { path, entries } => match nak {
                Some((NakCode::Eof, _)) => {
                    let entries = core::mem::take(entries);
                    self.finish(Ok(FtpOutput::Listing(entries)));
                }
                Some(n) => self.finish(Err(refused(n))),
                None => {
                    let got = parse_entries(&reply.data);
                    if got.is_empty() || entries.len() + got.len() > self.config.max_entries {
                        self.finish(Err(FtpError::Protocol));
                        return;
                    }
                    entries.extend(got);
                    let next = u32::try_from(entries.len()).unwrap_or(u32::MAX);
                    let req = Self::request(Opcode::ListDirectory, 0, next, path);
                    self.send(now, req);
                }
            },
            Op::Write(w) => match (&w.phase, nak) {
                (Phase::Terminate, _) => self.finish(Ok(FtpOutput::Done)),
                (_, Some(n)) => self.finish(Err(refused(n))),
                (Phase::Open, None) => {
                    w.session = reply.session;
                    w.phase = Phase::Transfer;
                    self.next_write(now);
                }
                (Phase::Transfer, None) => {
                    let sent = self.pending.as_ref().map_or(0, |p| p.req.data.len());
                    w.acked += sent;
                    let (done, total) = (w.acked as u64, w.data.len() as u64);
                    self.events.push_back(FtpEvent::Progress { done, total });
                    self.next_write(now);
                }
            },
            Op::Read(r) => match (&r.phase, nak) {
                (Phase::Terminate, _) => self.read_done(),
                (Phase::Open, Some(n)) => self.finish(Err(refused(n))),
                (Phase::Open, None) => {
                    let Some(b) = reply.data.get(..4) else {
                        self.finish(Err(FtpError::Protocol));
                        return;
                    };
                    let size = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                    if size > self.config.max_read_size {
                        let req = Self::request(Opcode::TerminateSession, reply.session, 0, &[]);
                        self.transmit(&req);
                        self.finish(Err(FtpError::TooLarge { size }));
                        return;
                    }
                    r.opened(reply.session, size);
                    self.next_read(now);
                }
                (Phase::Transfer, _) => self.on_burst_reply(now, reply),
            },
        }
    }

    fn next_write(&mut self, now: Instant) {
        let Some(Op::Write(w)) = self.op.as_mut() else {
            return;
        };
        let req = match w.data.get(w.acked..) {
            Some(rest) if !rest.is_empty() => {
                let chunk = &rest[..rest.len().min(MAX_DATA)];
                let offset = u32::try_from(w.acked).unwrap_or(u32::MAX);
                Self::request(Opcode::WriteFile, w.session, offset, chunk)
            }
            _ => {
                w.phase = Phase::Terminate;
                Self::request(Opcode::TerminateSession, w.session, 0, &[])
            }
        };
        self.send(now, req);
    }
}

impl Service for FtpClient {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let MavMessage::FileTransferProtocol(m) = message else {
            return false;
        };
        if !from.is_reached_by(self.server)
            || !self
                .me
                .is_reached_by(Address::new(m.target_system, m.target_component))
        {
            return false;
        }
        let Ok(reply) = Payload::decode(&m.payload) else {
            return false;
        };
        if !matches!(reply.opcode, Opcode::Ack | Opcode::Nak) {
            return false;
        }
        if reply.req_opcode == Opcode::ReadFile && self.take_gap_reply(now, &reply) {
            return true;
        }
        let Some(p) = self.pending.as_ref() else {
            return false;
        };
        if reply.req_opcode != p.req.opcode {
            return false;
        }
        if p.req.opcode == Opcode::BurstReadFile {
            let distance = reply.seq.wrapping_sub(p.req.seq);
            if distance == 0 || distance > 0x8000 || reply.session != p.req.session {
                return false;
            }
        } else if reply.seq != p.req.seq.wrapping_add(1) {
            return false;
        } else if p.attempt == 1 {
            self.rtt.sample(p.sent, now);
        }
        self.on_reply(now, &reply);
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.gap_timeouts(now);
        let Some(p) = self.pending.as_mut() else {
            return;
        };
        if now < p.deadline {
            return;
        }
        if p.req.opcode == Opcode::BurstReadFile && p.burst_packets > 0 {
            // The burst went quiet after some data: ask for what is missing.
            self.pending = None;
            self.next_read(now);
            return;
        }
        let terminating = matches!(
            &self.op,
            Some(Op::Read(Read {
                phase: Phase::Terminate,
                ..
            })) | Some(Op::Write(Write {
                phase: Phase::Terminate,
                ..
            }))
        );
        let limit = match self.config.first_attempts {
            n if p.first && n > 0 => n,
            _ => self.config.attempts,
        };
        if p.attempt >= limit {
            let attempts = p.attempt;
            if terminating {
                // Everything is transferred; only closing the session went unanswered
                // (the server's idle timeout closes it).
                let reply = p.req.clone();
                self.on_reply(now, &reply);
            } else {
                self.finish(Err(FtpError::TimedOut { attempts }));
            }
            return;
        }
        p.attempt += 1;
        p.sent = now;
        p.deadline = now + self.rtt.backoff(self.config.timeout, p.attempt);
        let req = p.req.clone();
        self.transmit(&req);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.queue.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let main = self.pending.as_ref().map(|p| p.deadline);
        [main, self.gap_deadline()].into_iter().flatten().min()
    }
}
