//! mavlink-router's configuration format (`main.conf`), read as it is.
//!
//! A mavlink-router user can point `mavstack router --conf` at the file they already have. The
//! file is read the way mavlink-router's own parser reads it, and each endpoint section becomes a
//! mavstack link string (a connection string, then `?` and `&`-separated options):
//!
//! | section | link |
//! | --- | --- |
//! | `[UdpEndpoint NAME]`, `Mode = Server` or `Eavesdropping` | `udpin:ADDRESS:PORT` |
//! | `[UdpEndpoint NAME]`, `Mode = Normal` | `udpout:ADDRESS:PORT` |
//! | `[TcpEndpoint NAME]` | `tcp:ADDRESS:PORT` |
//! | `[UartEndpoint NAME]` | `serial:DEVICE:BAUD` |
//!
//! The options come in a fixed order: `name` (the section's NAME) first, then `version`, `key`,
//! `link_id`, `secure`, `trusted`, the twelve filters, `rate` and `bytes_per_s`. An IPv6 address
//! is written in brackets, as mavlink-router requires in the file: `udpin:[::]:14550`.
//!
//! # Syntax, as mavlink-router reads it
//!
//! - Lines are split at `\n` and trimmed of C whitespace (space, tab, CR, LF, VT, FF), so CRLF
//!   files work. A trimmed line that starts with `#` or `;` is a comment. There are no trailing
//!   comments: `Port = 5 # x` gives the value `5 # x`, which is an error here.
//! - A header is `[TYPE]` or `[TYPE NAME]`: the first `]` ends the line, no space after `[` or
//!   before `]`, one plain space at most, at most 100 characters inside the brackets.
//! - `KEY = VALUE` splits at the first `=`; both sides are trimmed; an empty key or value is an
//!   error. Nothing is unquoted: quotes are part of the value.
//! - Section types, section names, keys and enumerated values (`Mode`, `true`, ...) compare
//!   ASCII case-insensitively. A header seen again, in this file or an earlier one, reopens its
//!   section; a key seen again in a section replaces the earlier value.
//! - Numbers are C `strtoul`/`strtol` with base 0: decimal, `0x` hexadecimal, and a leading
//!   `0` means octal (`014550` is 6504, as mavlink-router reads it). Booleans are `true` or
//!   `false` in any case, or a number (non-zero is true).
//! - Lists are comma-separated decimal numbers; spaces around items are allowed and empty items
//!   are skipped (`1, 2,,3` is `1,2,3`). In the link they are written with bare commas.
//! - The legacy UDP key `Filter` fills the same list as `AllowMsgIdOut`; with both, the list is
//!   `Filter`'s items followed by `AllowMsgIdOut`'s, as in mavlink-router.
//! - A UDP endpoint in normal mode without `Port` gets 14550, or 14551 when a UDP endpoint
//!   mavlink-router collects before it (it visits sections newest first) already uses the same
//!   address with 14550.
//!
//! # Where this parser is stricter or more lenient than mavlink-router
//!
//! mavlink-router silently drops what it does not understand; a router that silently loses a
//! filter is worse than one that refuses to start, so this parser reports instead:
//!
//! - an unknown key (for the section's type) and an unknown section (including `[UdpEndpoint]`
//!   without a name) are errors; mavlink-router ignores both;
//! - a number out of range (a port above 65535, a component id above 255) is an error, where
//!   mavlink-router truncates it; a list item must be a decimal number (mavlink-router's `atoi`
//!   reads `abc` as 0 and `1 2` as 1); a negative value for an unsigned key is an error;
//! - a section NAME must not hold `&`, `?` or `=`, nor a `Device` those or `,`: they cannot go
//!   into a link string;
//! - a line after the last `\n` is read (mavlink-router drops it);
//! - an IPv6 address may use uppercase hex digits (mavlink-router's check wants lowercase);
//! - [`RouterConf::links`] lists the endpoints in the order their sections first appear
//!   (mavlink-router creates UART, then UDP, then TCP endpoints, each newest first).
//!
//! Keys that mavlink-router knows but that have no effect in mavstack are checked like the others
//! and recorded in [`General::ignored`] for a warning: `DebugLogLevel`, `SnifferSysid`,
//! `LogMode`, `MinFreeSpace`, `MaxLogFiles`, `LogSystemId`, `LogTelemetry` in `[General]`;
//! `FlowControl` and baud rates after the first for UART; `RetryTimeout` for TCP; `Group` for
//! every endpoint.
//!
//! # mavstack's own keys
//!
//! Any endpoint section may also hold `MavlinkVersion` (`1`, `2`, `auto`) → `version`,
//! `SigningKey` (64 hex digits) → `key`, `SigningLinkId` (0–255) → `link_id`, `Trusted` and
//! `Secure` (booleans) → `trusted`, `secure`, `RateLimit` (kept as written, e.g. `30:10,33:5`)
//! → `rate`, and `BytesPerSecond` → `bytes_per_s`. A signing key never appears in an error.

use core::fmt;
use std::path::PathBuf;

mod build;
mod keys;
mod read;
mod values;

use build::build;
use read::read_sections;

/// A parsed configuration: general settings and the links it defines.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RouterConf {
    /// The `[General]` section (defaults when the file has none).
    pub general: General,
    /// One link per endpoint section, in the order the sections first appear.
    pub links: Vec<ConfLink>,
}

/// The `[General]` section, as written: a key that is absent stays `None` (or `false`), so the
/// command line and mavstack's defaults can decide.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct General {
    /// `TcpServerPort`: the TCP server's port (mavlink-router's default is 5760; 0 disables it).
    pub tcp_server_port: Option<u16>,
    /// `Log`: the directory for flight-stack logs.
    pub log_dir: Option<PathBuf>,
    /// `DeduplicationPeriod`, in milliseconds (0 disables de-duplication).
    pub dedup_ms: Option<u64>,
    /// `ReportStats`: print link statistics (`mavstack router` prints its `--stats` lines once
    /// a second, unless `--stats` gives the period).
    pub report_stats: bool,
    /// `MavlinkDialect`, lowercase: `auto`, `common` or `ardupilotmega`.
    pub dialect: Option<String>,
    /// `(line, key)` of every key that is accepted but has no effect in mavstack, in file order,
    /// for a warning. `key` is mavlink-router's spelling; baud rates after the first are
    /// recorded as `Baud (rates after the first)`. With [`parse_dir`], lines are counted in the
    /// file that set the key.
    pub ignored: Vec<(usize, String)>,
}

/// One endpoint section, as a mavstack link.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfLink {
    /// The section's NAME, as first written.
    pub name: String,
    /// The line of the section's first header.
    pub line: usize,
    /// A mavstack link string: connection string, `?`, then `&`-separated options, e.g.
    /// `udpin:0.0.0.0:14550?name=gcs&version=1`.
    pub link: String,
}

/// A configuration error, at a line of the file.
///
/// `Display` writes `line N: message`; the caller puts the file name in front.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfError {
    /// The 1-based line the error is about.
    pub line: usize,
    /// What is wrong, naming the section, key and value (lowercase, no trailing period).
    pub message: String,
}

impl fmt::Display for ConfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

impl core::error::Error for ConfError {}

/// Fuzzing entry point: any bytes, as text, parse to a configuration or a positioned error,
/// never a panic; every link string produced parses as a link.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_router_conf(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    if let Ok(conf) = parse(&text) {
        for link in conf.links {
            assert!(
                crate::LinkSpec::parse(&link.link, &|_| None).is_ok(),
                "conf produced a link that does not parse: {}",
                link.link
            );
        }
    }
}

/// Parses one configuration file.
///
/// # Errors
///
/// A [`ConfError`] for the first problem found: a line that is not a header, `key = value`,
/// comment or blank; an unknown section or key; a bad value; a missing required key.
pub fn parse(text: &str) -> Result<RouterConf, ConfError> {
    parse_texts(&[text]).map_err(|(_, error)| error)
}

/// Parses several files `(name, text)` in the order given, merged the way mavlink-router merges
/// its main file and the files of its conf directory (which it reads in `strcmp` order of their
/// paths, after the main file): a header seen again reopens its section, so a later file adds
/// endpoints, adds keys to a section, or replaces single keys. A key before the first header of
/// its own file is an error, even when an earlier file ended inside a section.
///
/// # Errors
///
/// The name of the file the error is in, and the error (see [`parse`]). A missing required key
/// is reported at the section's first header.
pub fn parse_dir(files: &[(String, String)]) -> Result<RouterConf, (String, ConfError)> {
    let texts: Vec<&str> = files.iter().map(|(_, text)| text.as_str()).collect();
    parse_texts(&texts).map_err(|(file, error)| {
        let name = files
            .get(file)
            .map(|(name, _)| name.clone())
            .unwrap_or_default();
        (name, error)
    })
}

/// An error and the index of the file it is in.
type Failure = (usize, ConfError);

fn failure(file: usize, line: usize, message: String) -> Failure {
    (file, ConfError { line, message })
}

fn parse_texts(texts: &[&str]) -> Result<RouterConf, Failure> {
    let sections = read_sections(texts)?;
    build(&sections)
}

#[cfg(test)]
mod tests;
