//! The MAVLink shell: SERIAL_CONTROL to the SHELL device, as PX4's nsh (and SITL's pxh)
//! over MAVLink expects it, in the client role.
//!
//! What goes to the shell is sent in SERIAL_CONTROL messages of up to [`CHUNK_LEN`] = 70
//! bytes, device SHELL (10), flags EXCLUSIVE | RESPOND: PX4 starts a shell for the first
//! one, writes each to it, and keeps it for as long as messages come with RESPOND. What the
//! shell prints comes back as SERIAL_CONTROL with the REPLY flag, up to 70 bytes each. The
//! client also polls (an empty SERIAL_CONTROL with the same flags) every
//! [`ShellConfig::poll_busy`] while the shell is talking and every
//! [`ShellConfig::poll_idle`] otherwise, for autopilots that answer only when asked.
//! [`ShellClient::close`] sends one without RESPOND, after which PX4 stops the shell.
//!
//! ```text
//!  ground station                                   autopilot
//!  SERIAL_CONTROL dev=SHELL EXCLUSIVE|RESPOND "ver all\n"   ─►  (shell started)
//!  ◄─  SERIAL_CONTROL REPLY "ver all\nHW arch: ..."  (≤ 70 bytes each)
//!  SERIAL_CONTROL dev=SHELL EXCLUSIVE|RESPOND count=0 (poll) ─►
//!  ◄─  SERIAL_CONTROL REPLY "...nsh> "
//!  SERIAL_CONTROL dev=SHELL flags=0 count=0 (close)          ─►  (shell stopped)
//! ```
//!
//! [`ShellClient`] is a session (bytes in, bytes out: an interactive terminal);
//! [`ShellCommand`] runs one command line on it and gives its output as text, whole once
//! the prompt follows the command's echo ([`Transcript`]).
//!
//! The vendored common.xml's SERIAL_CONTROL has no `target_system`/`target_component`
//! (newer versions add them as extensions): messages go out without them, which PX4 takes
//! as meant for it, and replies are matched by their sender. ArduPilot has no SHELL device
//! (its SERIAL_CONTROL reaches serial ports only) and does not answer.

mod transcript;

pub use transcript::{MAX_TRANSCRIPT, PROMPTS, Transcript};

use alloc::collections::VecDeque;
use alloc::string::String;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{MavMessage, SerialControl, SerialControlDev, SerialControlFlag};

use crate::{Address, Outgoing, Service};

/// The bytes one SERIAL_CONTROL carries.
pub const CHUNK_LEN: usize = 70;

/// Settings of a [`ShellClient`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShellConfig {
    /// The device (default SERIAL_CONTROL_DEV_SHELL).
    pub device: SerialControlDev,
    /// How often to poll while the shell is talking (default 50 ms).
    pub poll_busy: Duration,
    /// How often to poll otherwise (default 200 ms).
    pub poll_idle: Duration,
    /// How long after its last output the shell counts as talking (default 1 s).
    pub busy_for: Duration,
    /// A command that gets no output at all within this fails (default 5 s).
    pub answer_within: Duration,
    /// A command whose echo never came is taken as done after this long without output
    /// (default 2 s).
    pub quiet: Duration,
}

impl Default for ShellConfig {
    fn default() -> Self {
        Self {
            device: SerialControlDev::SHELL,
            poll_busy: Duration::from_millis(50),
            poll_idle: Duration::from_millis(200),
            busy_for: Duration::from_secs(1),
            answer_within: Duration::from_secs(5),
            quiet: Duration::from_secs(2),
        }
    }
}

/// What a [`ShellClient`] has counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShellStats {
    /// SERIAL_CONTROL messages sent with data.
    pub chunks_sent: u64,
    /// Bytes sent.
    pub bytes_sent: u64,
    /// Polls sent.
    pub polls: u64,
    /// Replies taken.
    pub replies: u64,
    /// Bytes received.
    pub bytes_received: u64,
    /// Replies whose `count` was over 70 (taken as 70).
    pub oversized: u64,
}

/// A session with a system's shell: bytes to it with [`write`](Self::write), its output
/// with [`poll_output`](Self::poll_output), polling on the timer, and
/// [`close`](Self::close) at the end. A [`Service`].
#[derive(Clone, Debug)]
pub struct ShellClient {
    target: Address,
    config: ShellConfig,
    out: VecDeque<Outgoing>,
    output: VecDeque<Vec<u8>>,
    /// When the next poll is due, while open.
    next_poll: Option<Instant>,
    last_output: Option<Instant>,
    stats: ShellStats,
}

impl ShellClient {
    /// A session with the shell of `target` (component 0: whichever component answers).
    #[must_use]
    pub const fn new(target: Address, config: ShellConfig) -> Self {
        Self {
            target,
            config,
            out: VecDeque::new(),
            output: VecDeque::new(),
            next_poll: None,
            last_output: None,
            stats: ShellStats {
                chunks_sent: 0,
                bytes_sent: 0,
                polls: 0,
                replies: 0,
                bytes_received: 0,
                oversized: 0,
            },
        }
    }

    /// Sends `bytes` to the shell, in order, in chunks of up to 70 bytes; opens the session
    /// (polling starts) if it was not.
    pub fn write(&mut self, now: Instant, bytes: &[u8]) {
        for chunk in bytes.chunks(CHUNK_LEN) {
            let flags =
                SerialControlFlag(SerialControlFlag::EXCLUSIVE.0 | SerialControlFlag::RESPOND.0);
            self.send(flags, chunk);
            self.stats.chunks_sent += 1;
            self.stats.bytes_sent += chunk.len() as u64;
        }
        self.next_poll = Some(now + self.poll_interval(now));
    }

    /// Opens the session without sending anything (the first poll goes now).
    pub fn open(&mut self, now: Instant) {
        if self.next_poll.is_none() {
            self.next_poll = Some(now);
        }
    }

    /// Ends the session: one SERIAL_CONTROL without RESPOND, after which PX4 stops the
    /// shell; polling stops.
    pub fn close(&mut self) {
        if self.next_poll.take().is_some() {
            self.send(SerialControlFlag(0), &[]);
        }
    }

    /// Whether the session is open.
    #[must_use]
    pub const fn is_open(&self) -> bool {
        self.next_poll.is_some()
    }

    /// The next bytes the shell printed, in order.
    pub fn poll_output(&mut self) -> Option<Vec<u8>> {
        self.output.pop_front()
    }

    /// When the shell last printed something.
    #[must_use]
    pub const fn last_output(&self) -> Option<Instant> {
        self.last_output
    }

    /// What it has counted.
    #[must_use]
    pub const fn stats(&self) -> ShellStats {
        self.stats
    }

    fn poll_interval(&self, now: Instant) -> Duration {
        let busy = self
            .last_output
            .is_some_and(|t| now.saturating_duration_since(t) < self.config.busy_for);
        if busy {
            self.config.poll_busy
        } else {
            self.config.poll_idle
        }
    }

    fn send(&mut self, flags: SerialControlFlag, bytes: &[u8]) {
        let mut data = [0u8; CHUNK_LEN];
        data[..bytes.len()].copy_from_slice(bytes);
        self.out.push_back(Outgoing {
            target: self.target,
            message: MavMessage::SerialControl(SerialControl {
                device: self.config.device,
                flags,
                timeout: 0,
                baudrate: 0,
                count: bytes.len() as u8,
                data,
            }),
        });
    }
}

impl Service for ShellClient {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let MavMessage::SerialControl(m) = message else {
            return false;
        };
        let ours = from.system == self.target.system
            && (self.target.component == 0 || from.component == self.target.component);
        if !ours || m.flags.0 & SerialControlFlag::REPLY.0 == 0 || m.device != self.config.device {
            return false;
        }
        self.stats.replies += 1;
        let count = usize::from(m.count);
        if count > CHUNK_LEN {
            self.stats.oversized += 1;
        }
        let bytes = &m.data[..count.min(CHUNK_LEN)];
        if !bytes.is_empty() {
            self.stats.bytes_received += bytes.len() as u64;
            self.last_output = Some(now);
            self.output.push_back(bytes.to_vec());
        }
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        if let Some(due) = self.next_poll
            && now >= due
        {
            let flags =
                SerialControlFlag(SerialControlFlag::EXCLUSIVE.0 | SerialControlFlag::RESPOND.0);
            self.send(flags, &[]);
            self.stats.polls += 1;
            self.next_poll = Some(now + self.poll_interval(now));
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.next_poll
    }
}

/// Why a shell command gave no output.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ShellError {
    /// Nothing came back at all.
    #[error(
        "no answer from the shell within {seconds:.1} s (SERIAL_CONTROL to the SHELL device: \
         PX4 answers it, ArduPilot has no such device)"
    )]
    NoAnswer {
        /// How long it waited.
        seconds: f64,
    },
    /// The command line cannot be sent as one line.
    #[error("a shell command is one line: it cannot hold a line break")]
    LineBreak,
}

/// One command line run on a system's shell: sent with a line feed, its output collected
/// until the prompt follows its echo, then the session closed. A [`Service`]: drive it and
/// read [`poll_result`](Self::poll_result).
#[derive(Clone, Debug)]
pub struct ShellCommand {
    client: ShellClient,
    transcript: Transcript,
    sent: Instant,
    result: Option<Result<String, ShellError>>,
    taken: bool,
}

impl ShellCommand {
    /// Starts `command` (one line) on the shell of `target`.
    ///
    /// # Errors
    /// [`ShellError::LineBreak`] when `command` holds `\n` or `\r` (nothing is sent).
    pub fn start(
        now: Instant,
        target: Address,
        config: ShellConfig,
        command: &str,
    ) -> Result<Self, ShellError> {
        if command.contains(['\n', '\r']) {
            return Err(ShellError::LineBreak);
        }
        let mut client = ShellClient::new(target, config);
        let mut line = String::from(command);
        line.push('\n');
        client.write(now, line.as_bytes());
        Ok(Self {
            client,
            transcript: Transcript::new(command),
            sent: now,
            result: None,
            taken: false,
        })
    }

    /// The output once the command is done (or why there is none); `None` before. Given
    /// once.
    pub fn poll_result(&mut self) -> Option<Result<String, ShellError>> {
        if self.taken {
            return None;
        }
        let result = self.result.clone()?;
        self.taken = true;
        Some(result)
    }

    /// Gives up: the session is closed (one SERIAL_CONTROL without RESPOND), and there will
    /// be no result.
    pub fn cancel(&mut self) {
        self.taken = true;
        self.client.close();
    }

    /// The transcript so far (bytes received, whether echoed, the text).
    #[must_use]
    pub const fn transcript(&self) -> &Transcript {
        &self.transcript
    }

    /// The session's counts.
    #[must_use]
    pub const fn stats(&self) -> ShellStats {
        self.client.stats()
    }

    fn finish(&mut self, result: Result<String, ShellError>) {
        if self.result.is_none() {
            self.result = Some(result);
            self.client.close();
        }
    }

    /// When it gives up: no answer at all, or (without an echo) quiet for long enough.
    fn deadline(&self) -> Option<Instant> {
        if self.result.is_some() {
            return None;
        }
        let config = &self.client.config;
        match self.client.last_output() {
            None => Some(self.sent + config.answer_within),
            Some(_) if self.transcript.echoed() => None,
            Some(t) => Some(t + config.quiet),
        }
    }
}

impl Service for ShellCommand {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if self.result.is_some() || !self.client.handle_message(now, from, message) {
            return false;
        }
        while let Some(bytes) = self.client.poll_output() {
            self.transcript.push(&bytes);
        }
        if self.transcript.is_complete() {
            let text = self.transcript.text();
            self.finish(Ok(text));
        }
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.client.handle_timeout(now);
        if let Some(deadline) = self.deadline()
            && now >= deadline
        {
            if self.client.last_output().is_none() {
                let seconds = self.client.config.answer_within.as_secs_f64();
                self.finish(Err(ShellError::NoAnswer { seconds }));
            } else {
                let text = self.transcript.text();
                self.finish(Ok(text));
            }
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.client.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        crate::earliest(self.client.poll_timeout(), self.deadline())
    }
}

/// The fuzz target `serial_control`: SERIAL_CONTROL replies made from arbitrary data
/// reach a shell session and a command, with the properties (a bug panics):
///
/// - the session's output is exactly the data of the replies it should take (REPLY flag,
///   the SHELL device, from the target), `count` capped at 70, in order; everything else
///   is ignored;
/// - a command's output sent as the echo, a body, and the prompt, cut into replies of the
///   sizes the data chooses, comes back as the body, and the command is done;
/// - any bytes in a transcript give text without control characters other than line feeds
///   and tabs.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_serial_control(data: &[u8]) {
    let target = Address::new(1, 1);
    let now = Instant::from_secs(1);
    let reply = |flags: u8, device: u8, count: u8, bytes: &[u8]| {
        let mut d = [0u8; CHUNK_LEN];
        let n = bytes.len().min(CHUNK_LEN);
        d[..n].copy_from_slice(&bytes[..n]);
        MavMessage::SerialControl(SerialControl {
            device: SerialControlDev(device),
            flags: SerialControlFlag(flags),
            timeout: 0,
            baudrate: 0,
            count,
            data: d,
        })
    };

    let mut session = ShellClient::new(target, ShellConfig::default());
    session.open(now);
    let mut want = Vec::new();
    let mut rest = data;
    while let [control, count, tail @ ..] = rest {
        let n = usize::from(*count).min(CHUNK_LEN).min(tail.len());
        let (bytes, after) = tail.split_at(n);
        rest = after;
        let from = if control & 0x80 != 0 {
            Address::new(2, 1)
        } else {
            target
        };
        let device = if control & 0x40 != 0 { 2 } else { 10 };
        let flags = control & 0x1F;
        let taken = from == target && device == 10 && flags & 1 != 0;
        session.handle_message(now, from, &reply(flags, device, *count, bytes));
        if taken {
            want.extend_from_slice(&bytes[..n.min(usize::from(*count))]);
            let pad = usize::from(*count).min(CHUNK_LEN).saturating_sub(n);
            want.extend(core::iter::repeat_n(0u8, pad));
        }
    }
    let got: Vec<u8> = core::iter::from_fn(|| session.poll_output())
        .flatten()
        .collect();
    assert_eq!(got, want);

    let body: String = data
        .iter()
        .map(|&b| {
            if b % 11 == 0 {
                '\n'
            } else {
                char::from(b'a' + b % 26)
            }
        })
        .collect();
    let mut whole = String::from("ver all\n");
    whole.push_str(&body);
    whole.push_str("nsh> ");
    let Ok(mut command) = ShellCommand::start(now, target, ShellConfig::default(), "ver all")
    else {
        unreachable!("one line")
    };
    let bytes = whole.as_bytes();
    let mut at = 0;
    let mut i = 0;
    while at < bytes.len() {
        let size = data
            .get(i)
            .map_or(CHUNK_LEN, |&b| usize::from(b) % CHUNK_LEN + 1);
        let end = (at + size).min(bytes.len());
        let piece = &bytes[at..end];
        command.handle_message(now, target, &reply(1, 10, piece.len() as u8, piece));
        at = end;
        i += 1;
    }
    assert_eq!(command.poll_result(), Some(Ok(body)));

    let mut any = Transcript::new("x");
    any.push(data);
    let text = any.text();
    assert!(
        !text
            .chars()
            .any(|c| c.is_control() && c != '\n' && c != '\t'),
        "{text:?}"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serial(m: &Outgoing) -> &SerialControl {
        match &m.message {
            MavMessage::SerialControl(s) => s,
            other => panic!("{other:?}"),
        }
    }

    fn reply(bytes: &[u8]) -> MavMessage {
        let mut data = [0u8; CHUNK_LEN];
        data[..bytes.len()].copy_from_slice(bytes);
        MavMessage::SerialControl(SerialControl {
            device: SerialControlDev::SHELL,
            flags: SerialControlFlag::REPLY,
            timeout: 0,
            baudrate: 0,
            count: bytes.len() as u8,
            data,
        })
    }

    #[test]
    fn writes_go_in_70_byte_chunks_with_exclusive_and_respond() {
        let mut c = ShellClient::new(Address::new(1, 1), ShellConfig::default());
        let line: Vec<u8> = (0..200u8).map(|i| b'a' + i % 26).collect();
        c.write(Instant::ZERO, &line);
        let sent: Vec<Outgoing> = core::iter::from_fn(|| c.poll_transmit()).collect();
        let counts: Vec<u8> = sent.iter().map(|o| serial(o).count).collect();
        assert_eq!(counts, [70, 70, 60]);
        let mut joined = Vec::new();
        for o in &sent {
            let s = serial(o);
            assert_eq!(s.device, SerialControlDev::SHELL);
            assert_eq!(s.flags.0, 2 | 4);
            joined.extend_from_slice(&s.data[..usize::from(s.count)]);
        }
        assert_eq!(joined, line);
    }

    #[test]
    fn polls_faster_while_the_shell_talks_and_close_stops_them() {
        let target = Address::new(1, 1);
        let mut c = ShellClient::new(target, ShellConfig::default());
        let t0 = Instant::from_secs(10);
        c.write(t0, b"help\n");
        while c.poll_transmit().is_some() {}
        assert_eq!(c.poll_timeout(), Some(t0 + Duration::from_millis(200)));
        c.handle_message(t0, target, &reply(b"help\n"));
        let t1 = t0 + Duration::from_millis(200);
        c.handle_timeout(t1);
        let poll = c.poll_transmit().unwrap();
        assert_eq!((serial(&poll).count, serial(&poll).flags.0), (0, 6));
        assert_eq!(c.poll_timeout(), Some(t1 + Duration::from_millis(50)));
        // Replies from others, or without REPLY, are not the shell's output.
        c.handle_message(t1, Address::new(2, 1), &reply(b"other"));
        let mut echo = reply(b"me");
        if let MavMessage::SerialControl(s) = &mut echo {
            s.flags = SerialControlFlag::RESPOND;
        }
        c.handle_message(t1, target, &echo);
        assert_eq!(c.poll_output(), Some(b"help\n".to_vec()));
        assert_eq!(c.poll_output(), None);
        c.close();
        let close = c.poll_transmit().unwrap();
        assert_eq!((serial(&close).count, serial(&close).flags.0), (0, 0));
        assert_eq!(c.poll_timeout(), None);
        assert_eq!(c.stats().polls, 1);
    }

    #[test]
    fn a_command_ends_at_the_prompt_and_closes() {
        let target = Address::new(1, 1);
        let t0 = Instant::from_secs(1);
        let mut cmd = ShellCommand::start(t0, target, ShellConfig::default(), "ver all").unwrap();
        while cmd.poll_transmit().is_some() {}
        for piece in [&b"ver all\nHW arch: SIM\n"[..], b"nsh> "] {
            cmd.handle_message(t0, target, &reply(piece));
        }
        assert_eq!(cmd.poll_result(), Some(Ok("HW arch: SIM\n".into())));
        assert_eq!(cmd.poll_result(), None);
        let close = cmd.poll_transmit().unwrap();
        assert_eq!(serial(&close).flags.0, 0);
        assert_eq!(cmd.poll_timeout(), None);
    }

    #[test]
    fn a_silent_shell_is_no_answer_and_a_command_is_one_line() {
        let target = Address::new(1, 1);
        let t0 = Instant::from_secs(1);
        let mut cmd = ShellCommand::start(t0, target, ShellConfig::default(), "ver").unwrap();
        let mut now = t0;
        while cmd.poll_result().is_none() {
            now = cmd.poll_timeout().unwrap();
            cmd.handle_timeout(now);
        }
        assert_eq!(now, t0 + Duration::from_secs(5));
        assert!(cmd.stats().polls > 20);
        let err = ShellCommand::start(t0, target, ShellConfig::default(), "a\nb").unwrap_err();
        assert_eq!(err, ShellError::LineBreak);
    }
}
