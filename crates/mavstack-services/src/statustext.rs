//! STATUSTEXT as lines a person can read: the text made safe to show, and long texts (sent
//! in chunks with an `id` and `chunk_seq`, MAVLink 2 only) put back together.
//!
//! Flight stacks say why they refuse in STATUSTEXT (ArduPilot's `PreArm: ...` lines come with
//! a COMMAND_ACK that only says FAILED), so a ground station that shows a refusal needs these
//! lines. The text is `char[50]`: cut at the first NUL, or all 50 bytes when there is none;
//! bytes that are not ASCII become U+0080–U+00FF (one character per byte, as the JSON lines
//! contract maps `char[N]`), and control characters become U+FFFD, so that no vehicle can
//! move a terminal's cursor or colour its output.
//!
//! ```
//! use mavstack_dialects::common::{MavSeverity, Statustext};
//! use mavstack_services::statustext::{Lines, text_of};
//! let mut text = [0u8; 50];
//! text[..8].copy_from_slice(b"PreArm: ");
//! text[8..10].copy_from_slice(b"\x1b[");
//! assert_eq!(text_of(&text), "PreArm: \u{fffd}[");
//!
//! let mut lines = Lines::default();
//! let chunk = |seq: u8, s: &[u8]| {
//!     let mut text = [0u8; 50];
//!     text[..s.len()].copy_from_slice(s);
//!     Statustext { severity: MavSeverity::WARNING, text, id: 7, chunk_seq: seq }
//! };
//! assert_eq!(lines.push((1, 1), &chunk(0, &[b'a'; 50])), None);
//! let line = lines.push((1, 1), &chunk(1, b"b")).unwrap();
//! assert_eq!(line.text.len(), 51);
//! ```

use alloc::string::String;
use alloc::vec::Vec;

use mavstack_dialects::common::{MavSeverity, Statustext};

/// Texts being put back together at once; a new one beyond this drops the oldest.
pub const MAX_PENDING: usize = 8;

/// Longest line kept from chunks (the protocol allows 255 chunks; flight stacks send a few).
pub const MAX_LINE: usize = 50 * 8;

/// One whole STATUSTEXT line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Line {
    /// Its sender `(sysid, compid)`.
    pub from: (u8, u8),
    /// Its severity.
    pub severity: MavSeverity,
    /// The text, safe to print.
    pub text: String,
}

/// A `char[N]` text as a string safe to show: cut at the first NUL, bytes that are not ASCII
/// as U+0080–U+00FF, tabs and line breaks as spaces, other control characters as U+FFFD.
#[must_use]
pub fn text_of(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    bytes[..end]
        .iter()
        .map(|&b| match char::from(b) {
            '\t' | '\n' | '\r' => ' ',
            c if c.is_control() => '\u{fffd}',
            c => c,
        })
        .collect()
}

/// A whole line as shown: without the spaces it ends with (PX4 ends the STATUSTEXT copy of
/// an event's text with a tab).
fn finished(mut text: String) -> String {
    text.truncate(text.trim_end().len());
    text
}

/// Chunked texts in progress.
#[derive(Debug)]
struct Pending {
    from: (u8, u8),
    id: u16,
    next: u8,
    severity: MavSeverity,
    text: String,
}

/// Puts STATUSTEXT messages together into [`Line`]s.
#[derive(Debug, Default)]
pub struct Lines {
    pending: Vec<Pending>,
}

impl Lines {
    /// Takes one STATUSTEXT from `from`; returns the line it completes, if any. A text with
    /// `id` 0 is a line of its own; chunks of one `id` end with a chunk shorter than 50
    /// bytes. A chunk that does not follow the last one seen of its text ends that text with
    /// what it has (a lost chunk costs its own part, not the line).
    pub fn push(&mut self, from: (u8, u8), m: &Statustext) -> Option<Line> {
        let part = text_of(&m.text);
        let last_chunk = m.text.contains(&0);
        if m.id == 0 {
            return Some(Line {
                from,
                severity: m.severity,
                text: finished(part),
            });
        }
        let at = self
            .pending
            .iter()
            .position(|p| p.from == from && p.id == m.id);
        let mut p = match at {
            Some(i) => self.pending.remove(i),
            None => Pending {
                from,
                id: m.id,
                next: 0,
                severity: m.severity,
                text: String::new(),
            },
        };
        if p.next != m.chunk_seq && !p.text.is_empty() {
            p.text.push('…');
        }
        if p.text.len() + part.len() <= MAX_LINE {
            p.text.push_str(&part);
        }
        p.next = m.chunk_seq.wrapping_add(1);
        if last_chunk || p.text.len() >= MAX_LINE {
            return Some(Line {
                from,
                severity: p.severity,
                text: finished(p.text),
            });
        }
        if self.pending.len() == MAX_PENDING {
            self.pending.remove(0);
        }
        self.pending.push(p);
        None
    }

    /// Ends every text in progress with what it has (a sender that stopped mid-text).
    pub fn flush(&mut self) -> impl Iterator<Item = Line> + '_ {
        self.pending.drain(..).map(|p| Line {
            from: p.from,
            severity: p.severity,
            text: finished(p.text),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::format;

    fn chunk(id: u16, seq: u8, s: &[u8]) -> Statustext {
        let mut text = [0u8; 50];
        let n = s.len().min(50);
        text[..n].copy_from_slice(&s[..n]);
        Statustext {
            severity: MavSeverity::CRITICAL,
            text,
            id,
            chunk_seq: seq,
        }
    }

    #[test]
    fn fifty_bytes_without_nul_are_all_kept() {
        assert_eq!(text_of(&[b'x'; 50]).len(), 50);
        let mut lines = Lines::default();
        let line = lines.push((1, 1), &chunk(0, 0, &[b'x'; 50])).unwrap();
        assert_eq!(line.text, "x".repeat(50));
    }

    #[test]
    fn bytes_that_are_not_utf8_and_controls_are_shown_safely() {
        assert_eq!(text_of(b"a\xff\xc3(\x07b\0zz"), "a\u{ff}\u{c3}(\u{fffd}b");
        assert_eq!(text_of(b"a\tb\r\n\0"), "a b  ");
    }

    /// PX4 sends the STATUSTEXT copy of an event's text with a tab at its end.
    #[test]
    fn a_line_ends_without_its_trailing_tab() {
        let mut lines = Lines::default();
        let line = lines
            .push((1, 1), &chunk(0, 0, b"Arming denied: check failed\t"))
            .unwrap();
        assert_eq!(line.text, "Arming denied: check failed");
    }

    #[test]
    fn chunks_of_two_senders_do_not_mix_and_a_gap_is_marked() {
        let mut lines = Lines::default();
        assert!(lines.push((1, 1), &chunk(3, 0, &[b'a'; 50])).is_none());
        assert!(lines.push((2, 1), &chunk(3, 0, &[b'b'; 50])).is_none());
        let a = lines.push((1, 1), &chunk(3, 2, b"end")).unwrap();
        assert_eq!(a.text, format!("{}…end", "a".repeat(50)));
        let rest: Vec<Line> = lines.flush().collect();
        assert_eq!(rest.len(), 1);
        assert_eq!(rest[0].from, (2, 1));
    }

    #[test]
    fn pending_texts_are_bounded() {
        let mut lines = Lines::default();
        for id in 1..=100u16 {
            assert!(lines.push((1, 1), &chunk(id, 0, &[b'a'; 50])).is_none());
        }
        assert_eq!(lines.flush().count(), MAX_PENDING);
    }
}
