//! Building: sections → the general settings and one link string per endpoint (options in
//! their fixed order, default UDP ports as mavlink-router assigns them).

use std::path::PathBuf;

use super::keys::{FILTERS, MAX_MSG_ID, Setting, lookup};
use super::read::{Entry, Kind, Section, is_c_space, shown, trim};
use super::values::{
    FORBIDDEN, c_bool, c_int, c_unsigned, check_address, join, number_list, one_of,
};
use super::{ConfLink, Failure, General, RouterConf, failure};

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

pub(super) fn build(sections: &[Section<'_>]) -> Result<RouterConf, Failure> {
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
