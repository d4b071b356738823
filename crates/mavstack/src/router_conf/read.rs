//! Reading: lines → sections of key/value entries, as mavlink-router splits them (comments,
//! headers, `KEY = VALUE`, sections reopened by a later header or file).

use super::{Failure, failure};

/// The longest text mavlink-router accepts between `[` and `]`.
const MAX_SECTION_NAME: usize = 100;

/// C `isspace` in the C locale.
pub(super) fn is_c_space(c: char) -> bool {
    matches!(c, ' ' | '\t' | '\n' | '\r' | '\x0b' | '\x0c')
}

pub(super) fn trim(s: &str) -> &str {
    s.trim_matches(is_c_space)
}

/// `s` quoted for a message, cut short when it is long.
pub(super) fn shown(s: &str) -> String {
    const MAX_SHOWN: usize = 60;
    match s.char_indices().nth(MAX_SHOWN) {
        Some((cut, _)) => format!("{:?}...", &s[..cut]),
        None => format!("{s:?}"),
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
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
pub(super) struct Entry<'a> {
    pub(super) key: &'a str,
    pub(super) value: &'a str,
    pub(super) file: usize,
    pub(super) line: usize,
}

/// A section, merged over every header that names it.
pub(super) struct Section<'a> {
    pub(super) kind: Kind,
    /// The text between the brackets of the first header (what headers are compared by).
    pub(super) header: &'a str,
    /// The NAME part (empty for `[General]`).
    pub(super) name: &'a str,
    pub(super) file: usize,
    pub(super) line: usize,
    pub(super) entries: Vec<Entry<'a>>,
}

impl Section<'_> {
    /// How messages name the section: `General` or `UdpEndpoint "alpha"`.
    pub(super) fn context(&self) -> String {
        match self.kind {
            Kind::General => "General".to_owned(),
            kind => format!("{} {:?}", kind.label(), self.name),
        }
    }
}

pub(super) fn read_sections<'a>(texts: &[&'a str]) -> Result<Vec<Section<'a>>, Failure> {
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
