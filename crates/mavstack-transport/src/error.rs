//! The errors of connections: opening, running, sending and receiving.
//!
//! Each operation has its own narrow error. A frame with a bad checksum or an unknown id is
//! never an error here: it is a counter (see [`crate::frame::FrameStats`]).

use std::io;

/// Why an operating-system operation failed, in a few lowercase words
/// (`"address in use"`, `"no such file"`, `"connection refused"`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Reason {
    kind: io::ErrorKind,
    text: String,
}

impl Reason {
    /// The reason for an I/O error.
    #[must_use]
    pub fn from_io(error: &io::Error) -> Self {
        let kind = error.kind();
        let text = match kind {
            io::ErrorKind::AddrInUse => "address in use".to_owned(),
            io::ErrorKind::AddrNotAvailable => "address not available".to_owned(),
            io::ErrorKind::NotFound => "no such file".to_owned(),
            io::ErrorKind::PermissionDenied => "permission denied".to_owned(),
            io::ErrorKind::ConnectionRefused => "connection refused".to_owned(),
            io::ErrorKind::ConnectionReset => "connection reset".to_owned(),
            io::ErrorKind::TimedOut => "timed out".to_owned(),
            io::ErrorKind::IsADirectory => "is a directory".to_owned(),
            _ => plain(&error.to_string()),
        };
        Self { kind, text }
    }

    /// The reason for a serial-port error.
    #[must_use]
    pub fn from_serial(error: &tokio_serial::Error) -> Self {
        match error.kind {
            tokio_serial::ErrorKind::Io(kind) => {
                Self::from_io(&io::Error::new(kind, error.description.clone()))
            }
            tokio_serial::ErrorKind::NoDevice => Self {
                kind: io::ErrorKind::NotFound,
                text: plain(&error.description),
            },
            tokio_serial::ErrorKind::InvalidInput => Self {
                kind: io::ErrorKind::InvalidInput,
                text: plain(&error.description),
            },
            tokio_serial::ErrorKind::Unknown => Self {
                kind: io::ErrorKind::Other,
                text: plain(&error.description),
            },
        }
    }

    /// A reason with the given text.
    pub(crate) fn new(kind: io::ErrorKind, text: impl Into<String>) -> Self {
        Self {
            kind,
            text: text.into(),
        }
    }

    /// The kind of I/O error.
    #[must_use]
    pub fn kind(&self) -> io::ErrorKind {
        self.kind
    }
}

impl From<&io::Error> for Reason {
    fn from(error: &io::Error) -> Self {
        Self::from_io(error)
    }
}

impl core::fmt::Display for Reason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&self.text)
    }
}

/// An operating system's message as a lowercase phrase: no `(os error N)`, no final period.
fn plain(text: &str) -> String {
    let text = text.split(" (os error").next().unwrap_or(text).trim();
    let text = text.strip_suffix('.').unwrap_or(text);
    let mut chars = text.chars();
    match chars.next() {
        Some(first) if !chars.as_str().starts_with(|c: char| c.is_ascii_uppercase()) => {
            first.to_lowercase().chain(chars).collect()
        }
        _ => text.to_owned(),
    }
}

/// Why a connection could not be opened. The message names the thing that failed:
/// `cannot bind udp 127.0.0.1:14550: address in use`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum OpenError {
    /// A host name did not resolve.
    #[error("cannot resolve {what}: {reason}")]
    Resolve {
        /// The link, e.g. `tcp example.invalid:5760`.
        what: String,
        /// Why.
        reason: Reason,
    },
    /// A local address could not be bound.
    #[error("cannot bind {what}: {reason}")]
    Bind {
        /// The link, e.g. `udp 127.0.0.1:14550`.
        what: String,
        /// Why.
        reason: Reason,
    },
    /// A TCP connection could not be made.
    #[error("cannot connect {what}: {reason}")]
    Connect {
        /// The link, e.g. `tcp 127.0.0.1:5760`.
        what: String,
        /// Why.
        reason: Reason,
    },
    /// A serial device could not be opened or configured.
    #[error("cannot open serial {device}: {reason}")]
    Serial {
        /// The device path.
        device: String,
        /// Why.
        reason: Reason,
    },
    /// A file could not be opened.
    #[error("cannot open file {path}: {reason}")]
    File {
        /// The path as given.
        path: String,
        /// Why.
        reason: Reason,
    },
    /// The blocking API could not start its runtime thread.
    #[error("cannot start the connection's runtime: {reason}")]
    Runtime {
        /// Why.
        reason: Reason,
    },
}

/// Why a running connection stopped (see [`crate::Connection::close`]).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LinkError {
    /// Reading failed for good.
    #[error("cannot read {what}: {reason}")]
    Read {
        /// The link, e.g. `file flight.tlog`.
        what: String,
        /// Why.
        reason: Reason,
    },
    /// Writing failed for good.
    #[error("cannot write {what}: {reason}")]
    Write {
        /// The link, e.g. `file out.tlog`.
        what: String,
        /// Why.
        reason: Reason,
    },
    /// The driver task panicked or was cancelled (a bug).
    #[error("the connection's driver task failed: {reason}")]
    Driver {
        /// What the runtime said.
        reason: String,
    },
}

/// Why a command could not be handed to the connection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SendError {
    /// The connection's driver has stopped (the link ended, or failed).
    #[error("connection closed")]
    Closed,
}

/// Why [`crate::Connection::try_send`] did not take a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TrySendError {
    /// The command queue is full; try again later or use `send`.
    #[error("command queue full")]
    Full,
    /// The connection's driver has stopped.
    #[error("connection closed")]
    Closed,
}

/// Why [`crate::Connection::try_recv`] returned no event.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TryRecvError {
    /// No event is waiting.
    #[error("no event waiting")]
    Empty,
    /// The connection has ended and every event was received.
    #[error("connection closed")]
    Closed,
}

/// Why [`crate::blocking::Connection::recv_timeout`] returned no event.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RecvTimeoutError {
    /// No event came in time.
    #[error("timed out waiting for an event")]
    Timeout,
    /// The connection has ended and every event was received.
    #[error("connection closed")]
    Closed,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_are_short_and_lowercase() {
        let e = io::Error::from(io::ErrorKind::AddrInUse);
        assert_eq!(Reason::from_io(&e).to_string(), "address in use");
        let e = io::Error::other("Something Odd happened (os error 99)");
        assert_eq!(Reason::from_io(&e).to_string(), "something Odd happened");
        let e = io::Error::other("EOF.");
        assert_eq!(Reason::from_io(&e).to_string(), "EOF");
        let e = OpenError::Bind {
            what: "udp 127.0.0.1:14550".into(),
            reason: Reason::from_io(&io::Error::from(io::ErrorKind::AddrInUse)),
        };
        assert_eq!(
            e.to_string(),
            "cannot bind udp 127.0.0.1:14550: address in use"
        );
    }
}
