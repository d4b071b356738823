//! The FTP server role: [`FtpServer`] answers requests from a [`Backend`].

use alloc::collections::VecDeque;
use alloc::string::String;
use alloc::vec;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{FileTransferProtocol, MavMessage};

use super::backend::{Backend, BackendError, OpenMode, normalize_path};
use super::payload::{MAX_DATA, NakCode, Opcode, Payload, crc32};
use crate::{Address, Outgoing, Service};

/// Session `id` when `from` owns it.
fn owned<H>(sessions: &[Session<H>], from: Address, id: u8) -> Option<&Session<H>> {
    sessions.iter().find(|s| s.id == id && s.owner == from)
}

/// [`FtpServer`] settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServerConfig {
    /// Sessions open at once, over every client (at most 255).
    pub max_sessions: u8,
    /// A session with no request for this long is closed.
    pub session_timeout: Duration,
    /// Replies in one burst (BurstReadFile) before `burst_complete`.
    pub burst_packets: u16,
    /// Clients whose last request and reply are kept to answer retransmissions.
    pub max_clients: usize,
    /// Replies queued for [`Service::poll_transmit`] at most; more are dropped (the
    /// client's retransmission is answered from the replay cache).
    pub max_queue: usize,
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            max_sessions: 4,
            session_timeout: Duration::from_secs(5),
            burst_packets: 32,
            max_clients: 8,
            max_queue: 64,
        }
    }
}

#[derive(Debug)]
struct Burst {
    seq: u16,
    offset: u32,
    chunk: usize,
    left: u16,
}

#[derive(Debug)]
struct Session<H> {
    id: u8,
    owner: Address,
    handle: H,
    writable: bool,
    /// The path of a session opened with OpenFileRO.
    read_path: Option<String>,
    last: Instant,
    burst: Option<Burst>,
}

#[derive(Debug)]
struct Replay {
    client: Address,
    request: Payload,
    reply: Payload,
    at: Instant,
}

/// A MAVLink FTP server: answers FILE_TRANSFER_PROTOCOL requests addressed to it with
/// ACKs and NAKs from a [`Backend`].
///
/// - Sessions (OpenFileRO, OpenFileWO, CreateFile) are bounded by
///   [`ServerConfig::max_sessions`] and belong to the client that opened them: another
///   client's requests on them get NAK InvalidSession. ResetSessions closes only the
///   sender's sessions. Sessions idle for [`ServerConfig::session_timeout`] are closed.
///   OpenFileRO of a file the same client has open for reading answers with that session
///   (a retry whose first ACK was lost must not use up the sessions).
/// - A request equal to the sender's previous one (a retransmission), byte for byte and
///   within the session timeout, is answered with the previous reply, without doing it
///   again. BurstReadFile is not replayed but restarted. (ArduPilot replays on a matching
///   sequence number alone, whatever the request and however old: a new client whose
///   numbers start where the last one's did gets an answer to another question.)
/// - Bursts are produced lazily by [`Service::poll_transmit`], so memory stays bounded;
///   pacing them to the link is the driver's job.
/// - Paths are normalised with [`normalize_path`]: nothing outside the backend's root can
///   be named.
#[derive(Debug)]
pub struct FtpServer<B: Backend> {
    me: Address,
    config: ServerConfig,
    backend: B,
    sessions: Vec<Session<B::Handle>>,
    replays: VecDeque<Replay>,
    queue: VecDeque<Outgoing>,
}

fn reply(req: &Payload, opcode: Opcode, data: Vec<u8>) -> Payload {
    Payload {
        seq: req.seq.wrapping_add(1),
        session: req.session,
        opcode,
        req_opcode: req.opcode,
        burst_complete: false,
        offset: req.offset,
        data,
    }
}

/// A file size as OpenFileRO/OpenFileWO's ACK carries it.
fn size_bytes(size: u64) -> Vec<u8> {
    u32::try_from(size)
        .unwrap_or(u32::MAX)
        .to_le_bytes()
        .to_vec()
}

fn nak(req: &Payload, code: NakCode, errno: Option<u8>) -> Payload {
    let mut data = vec![code.to_u8()];
    data.extend(errno);
    reply(req, Opcode::Nak, data)
}

fn nak_err(req: &Payload, e: BackendError) -> Payload {
    let (code, errno) = e.nak();
    nak(req, code, errno)
}

fn message(to: Address, p: &Payload) -> Outgoing {
    Outgoing {
        target: to,
        message: MavMessage::FileTransferProtocol(FileTransferProtocol {
            target_network: 0,
            target_system: to.system,
            target_component: to.component,
            payload: p.encode(),
        }),
    }
}

/// `(old, new)` of a Rename request: `old\0new`.
fn two_paths(data: &[u8]) -> Option<(&[u8], &[u8])> {
    let nul = data.iter().position(|&b| b == 0)?;
    Some((&data[..nul], &data[nul + 1..]))
}

impl<B: Backend> FtpServer<B> {
    /// A server answering as `me` from `backend`.
    #[must_use]
    pub fn new(me: Address, config: ServerConfig, backend: B) -> Self {
        Self {
            me,
            config,
            backend,
            sessions: Vec::new(),
            replays: VecDeque::new(),
            queue: VecDeque::new(),
        }
    }

    /// The backend.
    #[must_use]
    pub const fn backend(&self) -> &B {
        &self.backend
    }

    /// The backend, mutably.
    pub const fn backend_mut(&mut self) -> &mut B {
        &mut self.backend
    }

    /// How many sessions are open.
    #[must_use]
    pub fn open_sessions(&self) -> usize {
        self.sessions.len()
    }

    fn close(&mut self, index: usize) {
        let s = self.sessions.swap_remove(index);
        self.backend.close(s.handle);
    }

    fn session(&mut self, from: Address, id: u8) -> Option<&mut Session<B::Handle>> {
        self.sessions
            .iter_mut()
            .find(|s| s.id == id && s.owner == from)
    }

    /// The id of a new session: the one the client asked for when no session has it (as
    /// ArduPilot does: pymavlink sends its first WriteFiles in its own session number before
    /// the CreateFile ACK comes), else the lowest free one; `None` when `max_sessions` are
    /// open.
    fn new_session_id(&self, wanted: u8) -> Option<u8> {
        if self.sessions.len() >= usize::from(self.config.max_sessions) {
            return None;
        }
        let free = |id: u8| self.sessions.iter().all(|s| s.id != id);
        if free(wanted) {
            Some(wanted)
        } else {
            (0..=u8::MAX).find(|&id| free(id))
        }
    }

    fn open(&mut self, now: Instant, from: Address, req: &Payload, mode: OpenMode) -> Payload {
        let path = match normalize_path(&req.data) {
            Ok(p) => p,
            Err(code) => return nak(req, code, None),
        };
        if let Some(s) = self.sessions.iter_mut().find(|s| {
            mode == OpenMode::Read
                && s.owner == from
                && s.read_path.as_deref() == Some(path.as_str())
        }) {
            // The same client opening the same file again: its first open's ACK was
            // lost (MAVProxy sends a new request number each time), so it gets that
            // session again rather than one more, until none is left.
            s.last = now;
            s.burst = None;
            let size = self.backend.size(&s.handle).unwrap_or(0);
            let mut ack = reply(req, Opcode::Ack, size_bytes(size));
            ack.session = s.id;
            return ack;
        }
        let Some(id) = self.new_session_id(req.session) else {
            return nak(req, NakCode::NoSessionsAvailable, None);
        };
        let handle = match self.backend.open(&path, mode) {
            Ok(h) => h,
            Err(e) => return nak_err(req, e),
        };
        let size = match self.backend.size(&handle) {
            Ok(s) => s,
            Err(e) => {
                self.backend.close(handle);
                return nak_err(req, e);
            }
        };
        self.sessions.push(Session {
            id,
            owner: from,
            handle,
            writable: mode != OpenMode::Read,
            read_path: (mode == OpenMode::Read).then(|| path.clone()),
            last: now,
            burst: None,
        });
        let mut ack = reply(req, Opcode::Ack, Vec::new());
        ack.session = id;
        if mode != OpenMode::Create {
            ack.data = size_bytes(size);
        }
        ack
    }

    fn with_path(
        &mut self,
        req: &Payload,
        op: impl FnOnce(&mut B, &str) -> Result<Vec<u8>, BackendError>,
    ) -> Payload {
        match normalize_path(&req.data) {
            Err(code) => nak(req, code, None),
            Ok(path) => match op(&mut self.backend, &path) {
                Ok(data) => reply(req, Opcode::Ack, data),
                Err(e) => nak_err(req, e),
            },
        }
    }

    fn list(&mut self, req: &Payload) -> Payload {
        let path = match normalize_path(&req.data) {
            Ok(p) => p,
            Err(code) => return nak(req, code, None),
        };
        let entries = match self.backend.list(&path) {
            Ok(e) => e,
            Err(e) => return nak_err(req, e),
        };
        let skip = usize::try_from(req.offset).unwrap_or(usize::MAX);
        let mut data = Vec::new();
        let mut one = Vec::new();
        for entry in entries.iter().skip(skip) {
            one.clear();
            entry.encode_into(&mut one);
            if data.len() + one.len() > MAX_DATA {
                if data.is_empty() {
                    // A name too long for one reply: say it is there, skip it.
                    data.extend_from_slice(b"S\0");
                }
                break;
            }
            data.extend_from_slice(&one);
        }
        if data.is_empty() {
            return nak(req, NakCode::Eof, None);
        }
        reply(req, Opcode::Ack, data)
    }

    fn crc(&mut self, req: &Payload) -> Payload {
        let path = match normalize_path(&req.data) {
            Ok(p) => p,
            Err(code) => return nak(req, code, None),
        };
        let handle = match self.backend.open(&path, OpenMode::Read) {
            Ok(h) => h,
            Err(e) => return nak_err(req, e),
        };
        let mut crc = 0;
        let mut offset = 0u64;
        let mut buf = [0u8; 256];
        let result = loop {
            match self.backend.read(&handle, offset, &mut buf) {
                Ok(0) => break Ok(crc),
                Ok(n) => {
                    crc = crc32(crc, &buf[..n.min(buf.len())]);
                    offset += u64::try_from(n).unwrap_or(u64::MAX);
                }
                Err(e) => break Err(e),
            }
        };
        self.backend.close(handle);
        match result {
            Ok(crc) => reply(req, Opcode::Ack, crc.to_le_bytes().to_vec()),
            Err(e) => nak_err(req, e),
        }
    }

    /// Does one request; `None` when the answer is a burst, sent by `poll_transmit`.
    fn execute(&mut self, now: Instant, from: Address, req: &Payload) -> Option<Payload> {
        if let Some(s) = self.session(from, req.session) {
            s.last = now;
        }
        let answer = match req.opcode {
            Opcode::None => reply(req, Opcode::Ack, Vec::new()),
            Opcode::TerminateSession => {
                match self
                    .sessions
                    .iter()
                    .position(|s| s.id == req.session && s.owner == from)
                {
                    Some(i) => {
                        self.close(i);
                        reply(req, Opcode::Ack, Vec::new())
                    }
                    None => nak(req, NakCode::InvalidSession, None),
                }
            }
            Opcode::ResetSessions => {
                while let Some(i) = self.sessions.iter().position(|s| s.owner == from) {
                    self.close(i);
                }
                reply(req, Opcode::Ack, Vec::new())
            }
            Opcode::ListDirectory => self.list(req),
            Opcode::OpenFileRO => self.open(now, from, req, OpenMode::Read),
            Opcode::OpenFileWO => self.open(now, from, req, OpenMode::Write),
            Opcode::CreateFile => self.open(now, from, req, OpenMode::Create),
            Opcode::ReadFile => self.read(from, req),
            Opcode::BurstReadFile => {
                let chunk = match req.data.len() {
                    0 => MAX_DATA,
                    n => n,
                };
                let left = self.config.burst_packets.max(1);
                match self.session(from, req.session) {
                    Some(s) => {
                        s.burst = Some(Burst {
                            seq: req.seq.wrapping_add(1),
                            offset: req.offset,
                            chunk,
                            left,
                        });
                        return None;
                    }
                    None => nak(req, NakCode::InvalidSession, None),
                }
            }
            Opcode::WriteFile => self.write(from, req),
            Opcode::RemoveFile => self.with_path(req, |b, p| b.remove(p).map(|()| Vec::new())),
            Opcode::CreateDirectory => self.with_path(req, |b, p| b.mkdir(p).map(|()| Vec::new())),
            Opcode::RemoveDirectory => self.with_path(req, |b, p| b.rmdir(p).map(|()| Vec::new())),
            Opcode::TruncateFile => {
                let len = u64::from(req.offset);
                self.with_path(req, |b, p| b.truncate(p, len).map(|()| Vec::new()))
            }
            Opcode::Rename => match two_paths(&req.data) {
                None => nak(req, NakCode::InvalidDataSize, None),
                Some((old, new)) => match (normalize_path(old), normalize_path(new)) {
                    (Ok(old), Ok(new)) => match self.backend.rename(&old, &new) {
                        Ok(()) => reply(req, Opcode::Ack, Vec::new()),
                        Err(e) => nak_err(req, e),
                    },
                    (Err(code), _) | (_, Err(code)) => nak(req, code, None),
                },
            },
            Opcode::CalcFileCRC32 => self.crc(req),
            Opcode::Ack | Opcode::Nak | Opcode::Unknown(_) => {
                nak(req, NakCode::UnknownCommand, None)
            }
        };
        Some(answer)
    }

    fn read(&mut self, from: Address, req: &Payload) -> Payload {
        let Some(s) = owned(&self.sessions, from, req.session) else {
            return nak(req, NakCode::InvalidSession, None);
        };
        let want = match req.data.len() {
            0 => MAX_DATA,
            n => n.min(MAX_DATA),
        };
        let mut buf = [0u8; MAX_DATA];
        match self
            .backend
            .read(&s.handle, u64::from(req.offset), &mut buf[..want])
        {
            Ok(0) => nak(req, NakCode::Eof, None),
            Ok(n) => reply(req, Opcode::Ack, buf[..n.min(want)].to_vec()),
            Err(e) => nak_err(req, e),
        }
    }

    fn write(&mut self, from: Address, req: &Payload) -> Payload {
        let Some(s) = owned(&self.sessions, from, req.session) else {
            return nak(req, NakCode::InvalidSession, None);
        };
        if !s.writable {
            return nak(req, NakCode::FileProtected, None);
        }
        match self
            .backend
            .write(&s.handle, u64::from(req.offset), &req.data)
        {
            Ok(()) => reply(req, Opcode::Ack, Vec::new()),
            Err(e) => nak_err(req, e),
        }
    }

    fn push(&mut self, out: Outgoing) {
        if self.queue.len() < self.config.max_queue {
            self.queue.push_back(out);
        }
    }

    /// The next burst packet of the first session streaming one.
    fn burst_packet(&mut self) -> Option<Outgoing> {
        let s = self.sessions.iter_mut().find(|s| s.burst.is_some())?;
        let b = s.burst.as_mut()?;
        let mut p = Payload {
            seq: b.seq,
            session: s.id,
            opcode: Opcode::Ack,
            req_opcode: Opcode::BurstReadFile,
            burst_complete: false,
            offset: b.offset,
            data: Vec::new(),
        };
        let mut buf = [0u8; MAX_DATA];
        let want = b.chunk.min(MAX_DATA);
        let done = match self
            .backend
            .read(&s.handle, u64::from(b.offset), &mut buf[..want])
        {
            Ok(0) => {
                p.opcode = Opcode::Nak;
                p.data = vec![NakCode::Eof.to_u8()];
                p.burst_complete = true;
                true
            }
            Ok(n) => {
                let n = n.min(want);
                p.data = buf[..n].to_vec();
                b.offset = b
                    .offset
                    .saturating_add(u32::try_from(n).unwrap_or(u32::MAX));
                b.seq = b.seq.wrapping_add(1);
                b.left = b.left.saturating_sub(1);
                p.burst_complete = b.left == 0;
                b.left == 0
            }
            Err(e) => {
                let (code, errno) = e.nak();
                p.opcode = Opcode::Nak;
                p.data = vec![code.to_u8()];
                p.data.extend(errno);
                p.burst_complete = true;
                true
            }
        };
        if done {
            s.burst = None;
        }
        Some(message(s.owner, &p))
    }
}

impl<B: Backend> Service for FtpServer<B> {
    fn handle_message(&mut self, now: Instant, from: Address, message_in: &MavMessage) -> bool {
        let MavMessage::FileTransferProtocol(m) = message_in else {
            return false;
        };
        if !self
            .me
            .is_reached_by(Address::new(m.target_system, m.target_component))
        {
            return false;
        }
        let Ok(req) = Payload::decode(&m.payload) else {
            // Answer what can be read of the header.
            let mut head = m.payload;
            head[4] = 0;
            let Ok(p) = Payload::decode(&head) else {
                return false;
            };
            if matches!(p.opcode, Opcode::Ack | Opcode::Nak) {
                return false;
            }
            let out = message(from, &nak(&p, NakCode::InvalidDataSize, None));
            self.push(out);
            return true;
        };
        if matches!(req.opcode, Opcode::Ack | Opcode::Nak) {
            // A reply: for a client, not for us.
            return false;
        }
        if let Some(r) = self.replays.iter().find(|r| {
            r.client == from
                && r.request == req
                && now.saturating_duration_since(r.at) < self.config.session_timeout
        }) {
            let out = message(from, &r.reply);
            if let Some(s) = self.session(from, req.session) {
                s.last = now;
            }
            self.push(out);
            return true;
        }
        self.replays.retain(|r| r.client != from);
        if let Some(answer) = self.execute(now, from, &req) {
            self.push(message(from, &answer));
            if self.config.max_clients > 0 {
                if self.replays.len() >= self.config.max_clients {
                    self.replays.pop_front();
                }
                self.replays.push_back(Replay {
                    client: from,
                    request: req,
                    reply: answer,
                    at: now,
                });
            }
        }
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        let limit = self.config.session_timeout;
        while let Some(i) = self
            .sessions
            .iter()
            .position(|s| now.saturating_duration_since(s.last) >= limit)
        {
            self.close(i);
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.queue.pop_front().or_else(|| self.burst_packet())
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.sessions
            .iter()
            .map(|s| s.last + self.config.session_timeout)
            .min()
    }
}
