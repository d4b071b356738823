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
use core::net::{Ipv4Addr, Ipv6Addr};
use std::path::PathBuf;

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

// ---------------------------------------------------------------------------------------------
// Reading: lines → sections of key/value entries.

/// The longest text mavlink-router accepts between `[` and `]`.
const MAX_SECTION_NAME: usize = 100;

/// C `isspace` in the C locale.
fn is_c_space(c: char) -> bool {
    matches!(c, ' ' | '\t' | '\n' | '\r' | '\x0b' | '\x0c')
}

fn trim(s: &str) -> &str {
    s.trim_matches(is_c_space)
}

/// `s` quoted for a message, cut short when it is long.
fn shown(s: &str) -> String {
    const MAX_SHOWN: usize = 60;
    match s.char_indices().nth(MAX_SHOWN) {
        Some((cut, _)) => format!("{:?}...", &s[..cut]),
        None => format!("{s:?}"),
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    General,
    Uart,
    Udp,
    Tcp,
}

impl Kind {
    fn label(self) -> &'static str {
        match self {
            Self::General => "General",
            Self::Uart => "UartEndpoint",
            Self::Udp => "UdpEndpoint",
            Self::Tcp => "TcpEndpoint",
        }
    }
}

/// A key's last value in a section, and where it was set.
struct Entry<'a> {
    key: &'a str,
    value: &'a str,
    file: usize,
    line: usize,
}

/// A section, merged over every header that names it.
struct Section<'a> {
    kind: Kind,
    /// The text between the brackets of the first header (what headers are compared by).
    header: &'a str,
    /// The NAME part (empty for `[General]`).
    name: &'a str,
    file: usize,
    line: usize,
    entries: Vec<Entry<'a>>,
}

impl Section<'_> {
    /// How messages name the section: `General` or `UdpEndpoint "alpha"`.
    fn context(&self) -> String {
        match self.kind {
            Kind::General => "General".to_owned(),
            kind => format!("{} {:?}", kind.label(), self.name),
        }
    }
}

fn read_sections<'a>(texts: &[&'a str]) -> Result<Vec<Section<'a>>, Failure> {
    let mut sections: Vec<Section<'a>> = Vec::new();
    for (file, text) in texts.iter().enumerate() {
        // A file starts outside any section, whatever the previous file ended in.
        let mut current: Option<usize> = None;
        for (index, raw) in text.split('\n').enumerate() {
            let line = index + 1;
            let trimmed = trim(raw);
            if trimmed.is_empty() || trimmed.starts_with(['#', ';']) {
                continue;
            }
            if trimmed.starts_with('[') {
                let (kind, header, name) =
                    parse_header(trimmed).map_err(|message| failure(file, line, message))?;
                let found = sections
                    .iter()
                    .position(|s| s.header.eq_ignore_ascii_case(header));
                current = Some(found.unwrap_or_else(|| {
                    sections.push(Section {
                        kind,
                        header,
                        name,
                        file,
                        line,
                        entries: Vec::new(),
                    });
                    sections.len() - 1
                }));
                continue;
            }
            let Some((key, value)) = trimmed.split_once('=') else {
                return Err(failure(
                    file,
                    line,
                    format!(
                        "expected a [section] header, KEY = VALUE or a comment, found {}",
                        shown(trimmed)
                    ),
                ));
            };
            let (key, value) = (trim(key), trim(value));
            if key.is_empty() {
                return Err(failure(
                    file,
                    line,
                    format!("missing key before '=' in {}", shown(trimmed)),
                ));
            }
            let Some(section) = current.and_then(|i| sections.get_mut(i)) else {
                return Err(failure(
                    file,
                    line,
                    format!("key {} comes before any [section] header", shown(key)),
                ));
            };
            if value.is_empty() {
                return Err(failure(
                    file,
                    line,
                    format!("{}: {} has no value", section.context(), shown(key)),
                ));
            }
            match section
                .entries
                .iter_mut()
                .find(|e| e.key.eq_ignore_ascii_case(key))
            {
                Some(entry) => {
                    *entry = Entry {
                        key,
                        value,
                        file,
                        line,
                    }
                }
                None => section.entries.push(Entry {
                    key,
                    value,
                    file,
                    line,
                }),
            }
        }
    }
    Ok(sections)
}

/// Checks a trimmed line that starts with `[`; returns the section's type, the text between the
/// brackets and its NAME.
fn parse_header(line: &str) -> Result<(Kind, &str, &str), String> {
    let Some(close) = line.find(']') else {
        return Err(format!("section header {} has no closing ']'", shown(line)));
    };
    if close + 1 != line.len() {
        return Err(format!(
            "unexpected text after ']' in section header {}",
            shown(line)
        ));
    }
    let inner = &line[1..close];
    if inner.starts_with(is_c_space) || inner.ends_with(is_c_space) {
        return Err(format!(
            "section header {} has a space after '[' or before ']'",
            shown(line)
        ));
    }
    if inner.chars().any(|c| is_c_space(c) && c != ' ') {
        return Err(format!(
            "section header {} holds whitespace other than a space",
            shown(line)
        ));
    }
    if inner.matches(' ').count() > 1 {
        return Err(format!(
            "section header {} has more than one space: a section name cannot contain spaces",
            shown(line)
        ));
    }
    if inner.len() > MAX_SECTION_NAME {
        return Err(format!(
            "section header {} is longer than {MAX_SECTION_NAME} characters",
            shown(line)
        ));
    }
    let (type_name, name) = match inner.split_once(' ') {
        Some((type_name, name)) => (type_name, Some(name)),
        None => (inner, None),
    };
    let kind = [Kind::General, Kind::Uart, Kind::Udp, Kind::Tcp]
        .into_iter()
        .find(|kind| kind.label().eq_ignore_ascii_case(type_name));
    match (kind, name) {
        (None, _) => Err(format!(
            "unknown section {}; expected [General], [UartEndpoint NAME], [UdpEndpoint NAME] \
             or [TcpEndpoint NAME]",
            shown(line)
        )),
        (Some(Kind::General), Some(_)) => Err(format!(
            "section {} has a name; [General] takes none",
            shown(line)
        )),
        (Some(Kind::General), None) => Ok((Kind::General, inner, "")),
        (Some(kind), None) => Err(format!(
            "section {} needs a name: [{} NAME]",
            shown(line),
            kind.label()
        )),
        (Some(kind), Some(name)) => {
            if name.contains(['&', '?', '=']) {
                return Err(format!(
                    "{} {}: a name must not contain '&', '?' or '='",
                    kind.label(),
                    shown(name)
                ));
            }
            Ok((kind, inner, name))
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Keys.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Setting {
    TcpServerPort,
    ReportStats,
    DebugLogLevel,
    DeduplicationPeriod,
    SnifferSysid,
    Log,
    LogMode,
    MavlinkDialect,
    MinFreeSpace,
    MaxLogFiles,
    LogSystemId,
    LogTelemetry,
    Device,
    Baud,
    FlowControl,
    Mode,
    Address,
    Port,
    Filter,
    RetryTimeout,
    Group,
    /// One of [`FILTERS`], by index.
    MsgFilter(usize),
    MavlinkVersion,
    SigningKey,
    SigningLinkId,
    Trusted,
    Secure,
    RateLimit,
    BytesPerSecond,
}

const GENERAL_KEYS: &[(&str, Setting)] = &[
    ("TcpServerPort", Setting::TcpServerPort),
    ("ReportStats", Setting::ReportStats),
    ("DebugLogLevel", Setting::DebugLogLevel),
    ("DeduplicationPeriod", Setting::DeduplicationPeriod),
    ("SnifferSysid", Setting::SnifferSysid),
    ("Log", Setting::Log),
    ("LogMode", Setting::LogMode),
    ("MavlinkDialect", Setting::MavlinkDialect),
    ("MinFreeSpace", Setting::MinFreeSpace),
    ("MaxLogFiles", Setting::MaxLogFiles),
    ("LogSystemId", Setting::LogSystemId),
    ("LogTelemetry", Setting::LogTelemetry),
];

const UART_KEYS: &[(&str, Setting)] = &[
    ("Device", Setting::Device),
    ("Baud", Setting::Baud),
    ("FlowControl", Setting::FlowControl),
];

const UDP_KEYS: &[(&str, Setting)] = &[
    ("Address", Setting::Address),
    ("Mode", Setting::Mode),
    ("Port", Setting::Port),
    ("Filter", Setting::Filter),
];

const TCP_KEYS: &[(&str, Setting)] = &[
    ("Address", Setting::Address),
    ("Port", Setting::Port),
    ("RetryTimeout", Setting::RetryTimeout),
];

/// Keys of every endpoint section besides the filters: mavlink-router's `Group`, then mavstack's.
const ENDPOINT_KEYS: &[(&str, Setting)] = &[
    ("Group", Setting::Group),
    ("MavlinkVersion", Setting::MavlinkVersion),
    ("SigningKey", Setting::SigningKey),
    ("SigningLinkId", Setting::SigningLinkId),
    ("Trusted", Setting::Trusted),
    ("Secure", Setting::Secure),
    ("RateLimit", Setting::RateLimit),
    ("BytesPerSecond", Setting::BytesPerSecond),
];

/// The largest message id: 24 bits.
const MAX_MSG_ID: u32 = 0xFF_FFFF;

/// A filter key, the link option it becomes, and the largest id it holds.
struct FilterKey {
    conf: &'static str,
    option: &'static str,
    max: u32,
}

/// The filters, in the order their options are written. `Filter` (UDP only) adds to the first.
const FILTERS: [FilterKey; 12] = [
    FilterKey {
        conf: "AllowMsgIdOut",
        option: "allow_msg_out",
        max: MAX_MSG_ID,
    },
    FilterKey {
        conf: "BlockMsgIdOut",
        option: "block_msg_out",
        max: MAX_MSG_ID,
    },
    FilterKey {
        conf: "AllowSrcCompOut",
        option: "allow_src_comp_out",
        max: 255,
    },
    FilterKey {
        conf: "BlockSrcCompOut",
        option: "block_src_comp_out",
        max: 255,
    },
    FilterKey {
        conf: "AllowSrcSysOut",
        option: "allow_src_sys_out",
        max: 255,
    },
    FilterKey {
        conf: "BlockSrcSysOut",
        option: "block_src_sys_out",
        max: 255,
    },
    FilterKey {
        conf: "AllowMsgIdIn",
        option: "allow_msg_in",
        max: MAX_MSG_ID,
    },
    FilterKey {
        conf: "BlockMsgIdIn",
        option: "block_msg_in",
        max: MAX_MSG_ID,
    },
    FilterKey {
        conf: "AllowSrcCompIn",
        option: "allow_src_comp_in",
        max: 255,
    },
    FilterKey {
        conf: "BlockSrcCompIn",
        option: "block_src_comp_in",
        max: 255,
    },
    FilterKey {
        conf: "AllowSrcSysIn",
        option: "allow_src_sys_in",
        max: 255,
    },
    FilterKey {
        conf: "BlockSrcSysIn",
        option: "block_src_sys_in",
        max: 255,
    },
];

/// A key of a section type, as mavlink-router spells it.
fn lookup(kind: Kind, key: &str) -> Option<(&'static str, Setting)> {
    let specific = match kind {
        Kind::General => return find_key(GENERAL_KEYS, key),
        Kind::Uart => UART_KEYS,
        Kind::Udp => UDP_KEYS,
        Kind::Tcp => TCP_KEYS,
    };
    find_key(specific, key)
        .or_else(|| find_key(ENDPOINT_KEYS, key))
        .or_else(|| {
            FILTERS
                .iter()
                .enumerate()
                .find(|(_, f)| f.conf.eq_ignore_ascii_case(key))
                .map(|(i, f)| (f.conf, Setting::MsgFilter(i)))
        })
}

fn find_key(table: &[(&'static str, Setting)], key: &str) -> Option<(&'static str, Setting)> {
    table
        .iter()
        .find(|(name, _)| name.eq_ignore_ascii_case(key))
        .copied()
}

// ---------------------------------------------------------------------------------------------
// Values.

/// C `strtoul(s, _, 0)` over the whole of `s`, without its wrap-around of negative numbers.
fn c_unsigned(s: &str) -> Option<u64> {
    let s = s.strip_prefix('+').unwrap_or(s);
    let (digits, radix) = if let Some(hex) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        (hex, 16)
    } else if s.len() > 1 && s.starts_with('0') {
        (&s[1..], 8)
    } else {
        (s, 10)
    };
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return None;
    }
    u64::from_str_radix(digits, radix).ok()
}

/// C `strtol(s, _, 0)` over the whole of `s`, in the range of a 32-bit `int`.
fn c_int(s: &str) -> Option<i32> {
    match s.strip_prefix('-') {
        Some(rest) if !rest.starts_with(['+', '-']) => {
            let magnitude = i64::try_from(c_unsigned(rest)?).ok()?;
            i32::try_from(-magnitude).ok()
        }
        Some(_) => None,
        None => i32::try_from(c_unsigned(s)?).ok(),
    }
}

/// mavlink-router's boolean: `true`, `false` (any case) or a number, non-zero being true.
fn c_bool(s: &str) -> Option<bool> {
    if s.eq_ignore_ascii_case("true") {
        Some(true)
    } else if s.eq_ignore_ascii_case("false") {
        Some(false)
    } else {
        c_int(s).map(|n| n != 0)
    }
}

/// A comma-separated list of decimal numbers in `min..=max`; empty items are skipped.
fn number_list(value: &str, min: u32, max: u32) -> Result<Vec<u32>, String> {
    let mut items = Vec::new();
    for item in value.split(',').map(trim).filter(|item| !item.is_empty()) {
        let number = Some(item)
            .filter(|item| item.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|item| item.parse::<u32>().ok())
            .filter(|n| (min..=max).contains(n));
        let Some(number) = number else {
            let hint = if item.contains(['#', ';']) {
                "; a comment must be on a line of its own"
            } else if item.contains(is_c_space) {
                "; separate items with commas"
            } else {
                ""
            };
            return Err(format!(
                "item {} is not a number {min}-{max}{hint}",
                shown(item)
            ));
        };
        items.push(number);
    }
    Ok(items)
}

/// Two lists of numbers, one after the other, with bare commas.
fn join(first: &[u32], second: &[u32]) -> String {
    let items: Vec<String> = first.iter().chain(second).map(u32::to_string).collect();
    items.join(",")
}

/// mavlink-router's address check: four dotted groups of 1-3 digits, or an IPv6 address in
/// brackets. Hostnames are not accepted.
fn check_address(value: &str) -> Result<(), &'static str> {
    if let Some(inner) = value.strip_prefix('[').and_then(|v| v.strip_suffix(']')) {
        return match inner.parse::<Ipv6Addr>() {
            Ok(_) => Ok(()),
            Err(_) => Err("is not an IPv6 address"),
        };
    }
    let dotted = value.split('.').count() == 4
        && value
            .split('.')
            .all(|g| (1..=3).contains(&g.len()) && g.bytes().all(|b| b.is_ascii_digit()));
    if dotted && value.parse::<Ipv4Addr>().is_ok() {
        Ok(())
    } else if value.parse::<Ipv6Addr>().is_ok() {
        Err("is an IPv6 address without brackets; write it as [ADDRESS]")
    } else {
        Err("is not an IPv4 address or an IPv6 address in brackets")
    }
}

/// The choice `value` names, ignoring ASCII case.
fn one_of(choices: &[&'static str], value: &str) -> Option<&'static str> {
    choices
        .iter()
        .find(|c| c.eq_ignore_ascii_case(value))
        .copied()
}

/// Characters a value must not hold to be a link option (or the device in `serial:DEVICE:BAUD`).
const FORBIDDEN: [char; 4] = [',', '&', '?', '='];

// ---------------------------------------------------------------------------------------------
// Building: sections → general settings and links.

/// The mode of a UDP endpoint.
#[derive(Clone, Copy, PartialEq, Eq)]
enum UdpMode {
    /// `Normal`: send to a fixed address.
    Client,
    /// `Server` or `Eavesdropping`: bind and answer the last sender.
    Server,
}

/// An endpoint section's settings, before its link is written.
struct Endpoint<'a> {
    section: &'a Section<'a>,
    /// `Device` or `Address`.
    host: Option<&'a str>,
    /// `Port` or the first `Baud`.
    number: Option<u32>,
    mode: Option<UdpMode>,
    version: Option<&'static str>,
    /// `SigningKey`, and the file and line that set it.
    key: Option<(&'a str, usize, usize)>,
    link_id: Option<u8>,
    secure: Option<bool>,
    trusted: Option<bool>,
    filters: [Vec<u32>; 12],
    legacy_filter: Vec<u32>,
    rate: Option<String>,
    bytes_per_s: Option<u64>,
}

/// Where [`General::ignored`] entries are collected: file, line, key.
type Ignored = Vec<(usize, usize, String)>;

fn build(sections: &[Section<'_>]) -> Result<RouterConf, Failure> {
    let mut general = General::default();
    let mut ignored: Ignored = Vec::new();
    let mut endpoints = Vec::new();
    for section in sections {
        if section.kind == Kind::General {
            read_general(section, &mut general, &mut ignored)?;
        } else {
            endpoints.push(read_endpoint(section, &mut ignored)?);
        }
    }
    assign_udp_ports(&mut endpoints);
    ignored.sort_by_key(|&(file, line, _)| (file, line));
    general.ignored = ignored
        .into_iter()
        .map(|(_, line, key)| (line, key))
        .collect();
    let links = endpoints.iter().map(Endpoint::link).collect();
    Ok(RouterConf { general, links })
}

fn read_general(
    section: &Section<'_>,
    general: &mut General,
    ignored: &mut Ignored,
) -> Result<(), Failure> {
    let context = section.context();
    for entry in &section.entries {
        let fail = |what: &str| failure(entry.file, entry.line, format!("{context}: {what}"));
        let Some((name, key)) = lookup(Kind::General, entry.key) else {
            return Err(fail(&format!("unknown key {}", shown(entry.key))));
        };
        let value = entry.value;
        let bad = |what: &str| fail(&format!("{name} {} {what}", shown(value)));
        let unsigned = || c_unsigned(value).ok_or_else(|| bad("is not an unsigned number"));
        let choice =
            |choices: &[&'static str], what: &str| one_of(choices, value).ok_or_else(|| bad(what));
        let mut ignore = || ignored.push((entry.file, entry.line, name.to_owned()));
        match key {
            Setting::TcpServerPort => {
                let port = c_unsigned(value).and_then(|p| u16::try_from(p).ok());
                general.tcp_server_port = Some(port.ok_or_else(|| bad("is not a number 0-65535"))?);
            }
            Setting::ReportStats => {
                general.report_stats =
                    c_bool(value).ok_or_else(|| bad("is not true, false or a number"))?;
            }
            Setting::DeduplicationPeriod => general.dedup_ms = Some(unsigned()?),
            Setting::Log => general.log_dir = Some(PathBuf::from(value)),
            Setting::MavlinkDialect => {
                let dialect = choice(
                    &["auto", "common", "ardupilotmega"],
                    "is not auto, common or ardupilotmega",
                )?;
                general.dialect = Some(dialect.to_owned());
            }
            Setting::DebugLogLevel => {
                choice(
                    &["error", "warning", "info", "debug", "trace"],
                    "is not error, warning, info, debug or trace",
                )?;
                ignore();
            }
            Setting::LogMode => {
                choice(&["always", "while-armed"], "is not always or while-armed")?;
                ignore();
            }
            Setting::SnifferSysid | Setting::MinFreeSpace | Setting::MaxLogFiles => {
                unsigned()?;
                ignore();
            }
            Setting::LogSystemId => {
                c_int(value)
                    .filter(|id| (1..=255).contains(id))
                    .ok_or_else(|| bad("is not a number 1-255"))?;
                ignore();
            }
            Setting::LogTelemetry => {
                c_bool(value).ok_or_else(|| bad("is not true, false or a number"))?;
                ignore();
            }
            _ => return Err(fail(&format!("unknown key {}", shown(entry.key)))),
        }
    }
    Ok(())
}

fn read_endpoint<'a>(
    section: &'a Section<'a>,
    ignored: &mut Ignored,
) -> Result<Endpoint<'a>, Failure> {
    let mut ep = Endpoint::new(section);
    for entry in &section.entries {
        ep.apply(entry, ignored)?;
    }
    ep.finish()?;
    Ok(ep)
}

impl<'a> Endpoint<'a> {
    fn new(section: &'a Section<'a>) -> Self {
        Self {
            section,
            host: None,
            number: None,
            mode: None,
            version: None,
            key: None,
            link_id: None,
            secure: None,
            trusted: None,
            filters: Default::default(),
            legacy_filter: Vec::new(),
            rate: None,
            bytes_per_s: None,
        }
    }

    /// Checks one key of the section and keeps its value.
    fn apply(&mut self, entry: &Entry<'a>, ignored: &mut Ignored) -> Result<(), Failure> {
        let context = self.section.context();
        let fail = |what: &str| failure(entry.file, entry.line, format!("{context}: {what}"));
        let Some((name, setting)) = lookup(self.section.kind, entry.key) else {
            return Err(fail(&format!("unknown key {}", shown(entry.key))));
        };
        let value = entry.value;
        let bad = |what: &str| fail(&format!("{name} {} {what}", shown(value)));
        let boolean = || c_bool(value).ok_or_else(|| bad("is not true, false or a number"));
        let list = |min, max| {
            number_list(value, min, max)
                .map_err(|what| fail(&format!("{name} {}: {what}", shown(value))))
        };
        let mut ignore = |label: &str| ignored.push((entry.file, entry.line, label.to_owned()));
        match setting {
            Setting::Device => {
                if value.contains(FORBIDDEN) {
                    return Err(bad("must not contain ',', '&', '?' or '='"));
                }
                self.host = Some(value);
            }
            Setting::Baud => {
                let bauds = list(1, u32::MAX)?;
                if bauds.len() > 1 {
                    ignore("Baud (rates after the first)");
                }
                self.number = bauds.first().copied();
            }
            Setting::FlowControl => {
                boolean()?;
                ignore(name);
            }
            Setting::Mode => {
                self.mode = Some(if value.eq_ignore_ascii_case("normal") {
                    UdpMode::Client
                } else if value.eq_ignore_ascii_case("server")
                    || value.eq_ignore_ascii_case("eavesdropping")
                {
                    UdpMode::Server
                } else {
                    return Err(bad("is not normal, server or eavesdropping"));
                });
            }
            Setting::Address => {
                check_address(value).map_err(bad)?;
                self.host = Some(value);
            }
            Setting::Port => {
                let port = c_unsigned(value)
                    .and_then(|p| u32::try_from(p).ok())
                    .filter(|p| (1..=65535).contains(p));
                self.number = Some(port.ok_or_else(|| bad("is not a number 1-65535"))?);
            }
            Setting::Filter => self.legacy_filter = list(0, MAX_MSG_ID)?,
            Setting::MsgFilter(index) => {
                let max = FILTERS.get(index).map_or(0, |f| f.max);
                let items = list(0, max)?;
                if let Some(slot) = self.filters.get_mut(index) {
                    *slot = items;
                }
            }
            Setting::RetryTimeout => {
                c_int(value).ok_or_else(|| bad("is not a whole number of seconds"))?;
                ignore(name);
            }
            Setting::Group => ignore(name),
            Setting::MavlinkVersion => {
                let version = one_of(&["1", "2", "auto"], value);
                self.version = Some(version.ok_or_else(|| bad("is not 1, 2 or auto"))?);
            }
            Setting::SigningKey => {
                // The key is a secret: the message describes it without showing it.
                let length = value.chars().count();
                if length != 64 || !value.bytes().all(|b| b.is_ascii_hexdigit()) {
                    let found = if length == 64 {
                        "a character that is not a hex digit".to_owned()
                    } else {
                        format!("{length} characters")
                    };
                    return Err(fail(&format!(
                        "{name} is not 64 hex digits (found {found})"
                    )));
                }
                self.key = Some((value, entry.file, entry.line));
            }
            Setting::SigningLinkId => {
                let id = c_unsigned(value).and_then(|id| u8::try_from(id).ok());
                self.link_id = Some(id.ok_or_else(|| bad("is not a number 0-255"))?);
            }
            Setting::Trusted => self.trusted = Some(boolean()?),
            Setting::Secure => self.secure = Some(boolean()?),
            Setting::RateLimit => {
                if value.contains(['&', '?', '=']) {
                    return Err(bad("must not contain '&', '?' or '='"));
                }
                let items: Vec<&str> = value
                    .split(',')
                    .map(trim)
                    .filter(|i| !i.is_empty())
                    .collect();
                if let Some(item) = items.iter().find(|i| i.contains(is_c_space)) {
                    return Err(bad(&format!(
                        "has an item {} with a space; separate items with commas",
                        shown(item)
                    )));
                }
                self.rate = Some(items.join(",")).filter(|rate| !rate.is_empty());
            }
            Setting::BytesPerSecond => {
                let bytes = c_unsigned(value).ok_or_else(|| bad("is not an unsigned number"))?;
                self.bytes_per_s = Some(bytes);
            }
            _ => return Err(fail(&format!("unknown key {}", shown(entry.key)))),
        }
        Ok(())
    }

    /// Checks the required keys once the whole section is read, and fills defaults.
    fn finish(&mut self) -> Result<(), Failure> {
        let section = self.section;
        let context = section.context();
        let missing = |what: &str| {
            let message = format!("{context}: missing required key {what}");
            failure(section.file, section.line, message)
        };
        match (section.kind, self.mode) {
            (Kind::Uart, _) if self.host.is_none() => return Err(missing("Device")),
            (Kind::Uart, _) => self.number = self.number.or(Some(DEFAULT_BAUD)),
            (Kind::Udp | Kind::Tcp | Kind::General, _) if self.host.is_none() => {
                return Err(missing("Address"));
            }
            (Kind::Udp, None) => return Err(missing("Mode (normal, server or eavesdropping)")),
            (Kind::Udp, Some(UdpMode::Server)) if self.number.is_none() => {
                return Err(missing("Port (required in server mode)"));
            }
            (Kind::Tcp | Kind::General, _) if self.number.is_none() => {
                return Err(missing("Port"));
            }
            _ => {}
        }
        if let (Some("1"), Some((_, file, line))) = (self.version, self.key) {
            let message = format!("{context}: SigningKey needs MAVLink 2 but MavlinkVersion is 1");
            return Err(failure(file, line, message));
        }
        if self.link_id.is_some() && self.key.is_none() {
            let message = format!("{context}: SigningLinkId without a SigningKey");
            return Err(failure(section.file, section.line, message));
        }
        Ok(())
    }

    /// The link string, once every port is known.
    fn link(&self) -> ConfLink {
        let host = self.host.unwrap_or_default();
        let number = self.number.unwrap_or_default();
        let connection = match (self.section.kind, self.mode) {
            (Kind::Uart, _) => mavstack_transport::ConnSpec::Serial {
                device: host.to_owned(),
                baud: number,
            }
            .to_string(),
            (Kind::Udp, Some(UdpMode::Server)) => format!("udpin:{host}:{number}"),
            (Kind::Udp, _) => format!("udpout:{host}:{number}"),
            (Kind::Tcp | Kind::General, _) => format!("tcp:{host}:{number}"),
        };
        let mut options = vec![format!("name={}", self.section.name)];
        if let Some(version) = self.version {
            options.push(format!("version={version}"));
        }
        if let Some((key, _, _)) = self.key {
            options.push(format!("key={key}"));
        }
        if let Some(id) = self.link_id {
            options.push(format!("link_id={id}"));
        }
        if let Some(secure) = self.secure {
            options.push(format!("secure={secure}"));
        }
        if let Some(trusted) = self.trusted {
            options.push(format!("trusted={trusted}"));
        }
        for (index, (filter, items)) in FILTERS.iter().zip(&self.filters).enumerate() {
            // `Filter` is mavlink-router's older name for the first list; its items come first.
            let legacy: &[u32] = if index == 0 { &self.legacy_filter } else { &[] };
            if !legacy.is_empty() || !items.is_empty() {
                options.push(format!("{}={}", filter.option, join(legacy, items)));
            }
        }
        if let Some(rate) = &self.rate {
            options.push(format!("rate={rate}"));
        }
        if let Some(bytes) = self.bytes_per_s {
            options.push(format!("bytes_per_s={bytes}"));
        }
        ConfLink {
            name: self.section.name.to_owned(),
            line: self.section.line,
            link: format!("{connection}?{}", options.join("&")),
        }
    }
}

/// mavlink-router's baud rate when `Baud` is absent.
const DEFAULT_BAUD: u32 = 115_200;

/// The first port mavlink-router gives a normal-mode UDP endpoint without `Port`.
const AUTO_UDP_PORT: u32 = 14550;

/// Gives normal-mode UDP endpoints without `Port` mavlink-router's automatic port: it visits
/// the UDP sections newest first and moves to 14551 when one visited before has the same
/// address with 14550 (once: it is not a search for a free port).
fn assign_udp_ports(endpoints: &mut [Endpoint<'_>]) {
    let mut visited: Vec<(&str, u32)> = Vec::new();
    for ep in endpoints
        .iter_mut()
        .rev()
        .filter(|ep| ep.section.kind == Kind::Udp)
    {
        let host = ep.host.unwrap_or_default();
        let port = *ep.number.get_or_insert_with(|| {
            let taken = visited
                .iter()
                .any(|&(h, p)| h == host && p == AUTO_UDP_PORT);
            if taken {
                AUTO_UDP_PORT + 1
            } else {
                AUTO_UDP_PORT
            }
        });
        visited.push((host, port));
    }
}

#[cfg(test)]
mod tests;
