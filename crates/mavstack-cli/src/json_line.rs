//! Whole JSON lines: each line goes out with its newline in one write.
//!
//! `println!` writes a value and its newline as separate pieces: through stdout's 1,024-byte
//! line buffer a longer line goes out in several writes, and on unbuffered stderr the newline
//! always goes alone. A reader following a growing file (or a log line from another thread)
//! can then land between the pieces. Lines built whole here cannot be cut that way.

use core::fmt::Display;
use std::io::{self, Write};

/// Writes `line` and a newline to `out` in one `write_all`, then flushes.
///
/// # Errors
/// What `out` returns.
pub(crate) fn write(out: &mut impl Write, line: &impl Display) -> io::Result<()> {
    let mut text = line.to_string();
    text.push('\n');
    out.write_all(text.as_bytes())?;
    out.flush()
}

/// Writes `line` to stdout whole.
///
/// # Errors
/// What stdout returns (a closed pipe, a full disk).
pub(crate) fn to_stdout(line: &impl Display) -> io::Result<()> {
    write(&mut io::stdout().lock(), line)
}

/// Writes `line` to stderr whole; a stderr that cannot be written has nowhere to say so.
pub(crate) fn to_stderr(line: &impl Display) {
    let _ = write(&mut io::stderr().lock(), line);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts the writes that reach it.
    #[derive(Default)]
    struct Writes(Vec<Vec<u8>>);

    impl Write for Writes {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            self.0.push(buf.to_vec());
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_long_line_and_its_newline_go_in_one_write() {
        let long = serde_json::json!({ "links": "x".repeat(4000) });
        let mut out = Writes::default();
        write(&mut out, &long).expect("written");
        assert_eq!(out.0.len(), 1);
        let text = String::from_utf8(out.0.remove(0)).expect("utf-8");
        assert!(text.ends_with("}\n"));
        assert_eq!(
            serde_json::from_str::<serde_json::Value>(text.trim_end()).expect("json"),
            long
        );
    }
}
