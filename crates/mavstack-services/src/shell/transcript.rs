//! A command's output as text: the shell's bytes made safe to print, the echo of the command
//! and the prompt after it found.

use alloc::string::String;
use alloc::vec::Vec;

/// The prompts a shell ends its output with: NuttX's nsh on a flight controller, PX4 SITL's
/// pxh.
pub const PROMPTS: [&str; 2] = ["nsh> ", "pxh> "];

/// The most text a [`Transcript`] keeps; what comes after is counted, not kept.
pub const MAX_TRANSCRIPT: usize = 1 << 20;

/// How many characters of the newest text are kept to find the prompt in.
const TAIL: usize = 16;

/// Where an escape sequence is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
enum Escape {
    #[default]
    None,
    /// After ESC.
    Started,
    /// Inside `ESC [ ...` until its final byte.
    Csi,
}

/// Turns a shell's bytes into text that cannot move a terminal's cursor or colour it:
/// escape sequences (`ESC [ ... final`, and ESC with one byte) dropped, carriage returns and
/// NULs dropped, other control characters (C1 ones, encoded in UTF-8, too) U+FFFD, tabs and line feeds kept, UTF-8 decoded
/// across chunk boundaries (a broken sequence is U+FFFD).
#[derive(Clone, Debug, Default)]
pub(crate) struct Cleaner {
    escape: Escape,
    /// A UTF-8 sequence begun.
    utf8: Vec<u8>,
    /// Its length.
    need: usize,
}

impl Cleaner {
    pub(crate) fn feed(&mut self, bytes: &[u8], out: &mut impl FnMut(char)) {
        for &b in bytes {
            self.byte(b, out);
        }
    }

    /// A sequence left incomplete at the end.
    pub(crate) fn finish(&mut self, out: &mut impl FnMut(char)) {
        if !self.utf8.is_empty() {
            self.utf8.clear();
            out('\u{FFFD}');
        }
    }

    fn byte(&mut self, b: u8, out: &mut impl FnMut(char)) {
        match self.escape {
            Escape::None => {}
            Escape::Started => {
                self.escape = if b == b'[' { Escape::Csi } else { Escape::None };
                return;
            }
            Escape::Csi => {
                if (0x40..=0x7E).contains(&b) {
                    self.escape = Escape::None;
                }
                return;
            }
        }
        if !self.utf8.is_empty() {
            if b & 0xC0 == 0x80 {
                self.utf8.push(b);
                if self.utf8.len() == self.need {
                    match core::str::from_utf8(&self.utf8) {
                        // C1 controls (U+0080-U+009F, 8-bit CSI among them) too.
                        Ok(s) => s
                            .chars()
                            .map(|c| if c.is_control() { '\u{FFFD}' } else { c })
                            .for_each(&mut *out),
                        Err(_) => out('\u{FFFD}'),
                    }
                    self.utf8.clear();
                }
                return;
            }
            self.utf8.clear();
            out('\u{FFFD}');
        }
        match b {
            0x1B => self.escape = Escape::Started,
            b'\n' | b'\t' => out(char::from(b)),
            b'\r' | 0 => {}
            0x01..=0x1F | 0x7F => out('\u{FFFD}'),
            0x20..=0x7E => out(char::from(b)),
            0xC2..=0xDF => self.begin(b, 2),
            0xE0..=0xEF => self.begin(b, 3),
            0xF0..=0xF4 => self.begin(b, 4),
            _ => out('\u{FFFD}'),
        }
    }

    fn begin(&mut self, b: u8, need: usize) {
        self.utf8.push(b);
        self.need = need;
    }
}

/// The output of one command, as the shell sends it back: the echo of the command line, the
/// command's output, then the prompt. Fed the shell's bytes in any pieces, it says when the
/// prompt has come after the echo ([`is_complete`](Self::is_complete)) and gives the output
/// between them ([`text`](Self::text)), safe to print.
#[derive(Clone, Debug)]
pub struct Transcript {
    /// The echo looked for: the command and a line feed.
    echo: String,
    cleaner: Cleaner,
    /// The text so far (up to [`MAX_TRANSCRIPT`] bytes).
    text: String,
    /// The newest characters, kept past the limit too.
    tail: String,
    /// Where the output starts: after the echo, once found.
    after_echo: Option<usize>,
    /// Characters not kept for the limit.
    cut: u64,
    /// Bytes fed.
    bytes: u64,
}

impl Transcript {
    /// A transcript of `command` (one line).
    #[must_use]
    pub fn new(command: &str) -> Self {
        let mut echo = String::from(command);
        echo.push('\n');
        Self {
            echo,
            cleaner: Cleaner::default(),
            text: String::new(),
            tail: String::new(),
            after_echo: None,
            cut: 0,
            bytes: 0,
        }
    }

    /// Takes the next bytes the shell sent.
    pub fn push(&mut self, bytes: &[u8]) {
        self.bytes += bytes.len() as u64;
        let before = self.text.len();
        let Self {
            cleaner,
            text,
            tail,
            cut,
            ..
        } = self;
        cleaner.feed(bytes, &mut |c| {
            if text.len() + c.len_utf8() <= MAX_TRANSCRIPT {
                text.push(c);
            } else {
                *cut += 1;
            }
            if tail.chars().count() >= TAIL {
                tail.remove(0);
            }
            tail.push(c);
        });
        if self.after_echo.is_none() {
            // The echo may straddle what came before: look from its length back.
            let from = before.saturating_sub(self.echo.len());
            let from = (0..=from)
                .rev()
                .find(|&i| self.text.is_char_boundary(i))
                .unwrap_or(0);
            if let Some(at) = self.text[from..].find(self.echo.as_str()) {
                self.after_echo = Some(from + at + self.echo.len());
            }
        }
    }

    /// Bytes fed so far.
    #[must_use]
    pub const fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Whether the shell echoed the command line.
    #[must_use]
    pub const fn echoed(&self) -> bool {
        self.after_echo.is_some()
    }

    /// Whether the output is whole: the echo came, and a prompt ends what came after it.
    #[must_use]
    pub fn is_complete(&self) -> bool {
        let Some(after) = self.after_echo else {
            return false;
        };
        let prompt = PROMPTS.iter().find(|p| self.tail.ends_with(*p));
        prompt.is_some_and(|p| self.cut > 0 || self.text.len() >= after + p.len())
    }

    /// Characters of output not kept, past [`MAX_TRANSCRIPT`].
    #[must_use]
    pub const fn cut(&self) -> u64 {
        self.cut
    }

    /// The command's output: what came between the echo and the prompt (all of it when
    /// there was no echo), without a prompt at its end; lines end in `\n`.
    #[must_use]
    pub fn text(&self) -> String {
        let mut text = self.text.clone();
        self.cleaner.clone().finish(&mut |c| text.push(c));
        let from = self.after_echo.unwrap_or(0);
        let mut out = String::from(&text[from..]);
        if self.cut == 0
            && let Some(p) = PROMPTS.iter().find(|p| out.ends_with(*p))
        {
            out.truncate(out.len() - p.len());
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fed(command: &str, pieces: &[&[u8]]) -> Transcript {
        let mut t = Transcript::new(command);
        for p in pieces {
            t.push(p);
        }
        t
    }

    #[test]
    fn the_output_between_echo_and_prompt() {
        let t = fed(
            "ver all",
            &[
                b"ver a",
                b"ll\r\nHW arch: PX4_SITL\r\n",
                b"PX4 git-hash: 1\npx",
                b"h> ",
            ],
        );
        assert!(t.echoed() && t.is_complete());
        assert_eq!(t.text(), "HW arch: PX4_SITL\nPX4 git-hash: 1\n");
    }

    #[test]
    fn a_banner_and_its_prompt_before_the_echo_do_not_end_it() {
        let mut t = fed("help", &[b"\nNuttShell (NSH) NuttX-11.0.0\nnsh> "]);
        assert!(!t.is_complete());
        t.push(b"help\n  commands:\n");
        assert!(!t.is_complete());
        t.push(b"nsh> ");
        assert!(t.is_complete());
        assert_eq!(t.text(), "  commands:\n");
    }

    #[test]
    fn escapes_and_controls_cannot_reach_a_terminal() {
        let t = fed(
            "x",
            &[
                b"x\n\x1b[K\x1b[2Jred\x1b[31m\x07 \xc3",
                b"\xa9 \xff\xe2\x82",
                b"nsh> ",
            ],
        );
        assert!(t.is_complete());
        assert_eq!(t.text(), "red\u{fffd} é \u{fffd}\u{fffd}");
        let t = fed("x", &[b"x\n\xe2\x82"]);
        assert_eq!(t.text(), "\u{fffd}");
        // U+009B, a CSI of its own to some terminals.
        let t = fed("x", &[b"x\n\xc2\x9b2J"]);
        assert_eq!(t.text(), "\u{fffd}2J");
    }

    #[test]
    fn without_an_echo_all_of_it() {
        let t = fed("ver", &[b"PX4 version: 1.16.0\nnsh> "]);
        assert!(!t.echoed() && !t.is_complete());
        assert_eq!(t.text(), "PX4 version: 1.16.0\n");
    }

    #[test]
    fn past_the_limit_counted_and_still_complete() {
        let mut t = Transcript::new("cat big");
        t.push(b"cat big\n");
        let line = [b'a'; 1000];
        for _ in 0..1100 {
            t.push(&line);
        }
        t.push(b"nsh> ");
        assert!(t.is_complete());
        assert!(t.cut() > 0);
        assert!(t.text().len() <= MAX_TRANSCRIPT);
    }
}
