//! Link options as written after a connection string: `version=1&name=legacy&key=…`
//! (`docs/contracts/link-options.md`).
//!
//! ```
//! use mavstack_router::options::parse;
//! use mavstack_router::VersionMode;
//! let link = parse("version=1&name=legacy&block_msg_out=30,33", "udpin:0.0.0.0:14550", &|_| None).unwrap();
//! assert_eq!((link.name.as_str(), link.version), ("legacy", VersionMode::Mavlink1));
//! assert!(!link.filters_out.passes(30, 1, 1));
//! let err = parse("version=3", "x", &|_| None).unwrap_err();
//! assert_eq!(err.to_string(), r#"link option "version": "3" is not 1, 2 or auto"#);
//! ```

use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;

use mavstack_channel::SigningConfig;
use mavstack_core::signing::SecretKey;

use crate::config::{IdFilter, LinkConfig, VersionMode};

/// A link option that cannot be used: its name and why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("link option \"{option}\": {reason}")]
pub struct OptionError {
    /// The option (as written).
    pub option: String,
    /// What is wrong with it.
    pub reason: String,
}

fn err(option: &str, reason: impl Into<String>) -> OptionError {
    OptionError {
        option: option.to_string(),
        reason: reason.into(),
    }
}

/// Every option name, in the order they are documented.
pub const NAMES: &[&str] = &[
    "version",
    "key",
    "link_id",
    "secure",
    "trusted",
    "name",
    "allow_msg_in",
    "block_msg_in",
    "allow_msg_out",
    "block_msg_out",
    "allow_src_sys_in",
    "block_src_sys_in",
    "allow_src_sys_out",
    "block_src_sys_out",
    "allow_src_comp_in",
    "block_src_comp_in",
    "allow_src_comp_out",
    "block_src_comp_out",
    "rate",
    "bytes_per_s",
    "queue",
    "pack",
    "isolate_peers",
];

/// Parses `options` (the text after `?`, `&`-separated `name=value` pairs; may be empty)
/// into a link named `default_name` unless a `name` option says otherwise. `message_id`
/// turns a message name (`ATTITUDE`) into its id, for the filters and `rate`; numbers are
/// always accepted.
///
/// # Errors
/// [`OptionError`] naming the first unknown option, bad value, repeated option, or
/// `version=1` together with `key` (MAVLink 1 cannot be signed).
pub fn parse(
    options: &str,
    default_name: &str,
    message_id: &dyn Fn(&str) -> Option<u32>,
) -> Result<LinkConfig, OptionError> {
    let mut link = LinkConfig::new(default_name);
    let mut seen: Vec<&str> = Vec::new();
    let mut key: Option<SecretKey> = None;
    let mut link_id: u8 = 0;
    for pair in options.split('&').filter(|p| !p.is_empty()) {
        let (name, value) = pair
            .split_once('=')
            .ok_or_else(|| err(pair, "expected name=value"))?;
        if !NAMES.contains(&name) {
            return Err(err(
                name,
                format!("unknown option; expected one of {}", NAMES.join(", ")),
            ));
        }
        if seen.contains(&name) {
            return Err(err(name, "given twice"));
        }
        seen.push(name);
        match name {
            "version" => {
                link.version = match value {
                    "1" => VersionMode::Mavlink1,
                    "2" => VersionMode::Mavlink2,
                    "auto" => VersionMode::Auto,
                    _ => return Err(err(name, format!("\"{value}\" is not 1, 2 or auto"))),
                };
            }
            "key" => {
                key = Some(SecretKey::from_hex(value).map_err(|e| {
                    err(
                        name,
                        format!("{e} (expected 64 hex digits, the 32-byte key)"),
                    )
                })?);
            }
            "link_id" => {
                link_id = value
                    .parse()
                    .map_err(|_| err(name, format!("\"{value}\" is not a number 0-255")))?;
            }
            "secure" => link.secure = boolean(name, value)?,
            "trusted" => link.trusted = boolean(name, value)?,
            "pack" => link.pack = boolean(name, value)?,
            "isolate_peers" => link.isolate_peers = boolean(name, value)?,
            "name" => {
                if value.is_empty() {
                    return Err(err(name, "empty"));
                }
                link.name = value.to_string();
            }
            "rate" => {
                for item in value.split(',') {
                    let (id, hz) = item.split_once(':').ok_or_else(|| {
                        err(
                            name,
                            format!("\"{item}\" is not MESSAGE:RATE (e.g. ATTITUDE:10)"),
                        )
                    })?;
                    let id = message(name, id, message_id)?;
                    let hz = hz.parse::<u32>().ok().filter(|&h| h > 0).ok_or_else(|| {
                        err(name, format!("\"{hz}\" is not a rate in Hz above 0"))
                    })?;
                    link.limits.per_message.push((id, hz));
                }
            }
            "bytes_per_s" => {
                link.limits.bytes_per_s = Some(
                    value
                        .parse::<u32>()
                        .ok()
                        .filter(|&b| b > 0)
                        .ok_or_else(|| {
                            err(name, format!("\"{value}\" is not a byte rate above 0"))
                        })?,
                );
            }
            "queue" => {
                link.queue_frames = value
                    .parse::<usize>()
                    .ok()
                    .filter(|&q| (1..=1 << 20).contains(&q))
                    .ok_or_else(|| {
                        err(
                            name,
                            format!("\"{value}\" is not a number of frames 1-1048576"),
                        )
                    })?;
            }
            _ => set_filter(&mut link, name, value, message_id)?,
        }
    }
    if let Some(key) = key {
        if link.version == VersionMode::Mavlink1 {
            return Err(err(
                "key",
                "a signed link is MAVLink 2: it cannot be combined with version=1",
            ));
        }
        link.signing = Some(SigningConfig::new(key, link_id));
    } else if seen.contains(&"link_id") {
        return Err(err("link_id", "only means something with a key"));
    }
    Ok(link)
}

/// A boolean as the link options spell it (`docs/contracts/link-options.md`): `true`, `1`,
/// `yes` or `false`, `0`, `no`. The one reading of booleans for every option mavstack
/// defines (link strings, bridge links); mavlink-router's own `main.conf` keys keep its
/// reading.
///
/// ```
/// use mavstack_router::options::parse_bool;
/// assert_eq!(parse_bool("yes"), Some(true));
/// assert_eq!(parse_bool("0"), Some(false));
/// assert_eq!(parse_bool("on"), None);
/// ```
#[must_use]
pub fn parse_bool(value: &str) -> Option<bool> {
    match value {
        "true" | "1" | "yes" => Some(true),
        "false" | "0" | "no" => Some(false),
        _ => None,
    }
}

/// What [`parse_bool`] says about option `name`, or why not.
fn boolean(name: &str, value: &str) -> Result<bool, OptionError> {
    parse_bool(value).ok_or_else(|| err(name, format!("\"{value}\" is not true or false")))
}

fn message(
    name: &str,
    text: &str,
    message_id: &dyn Fn(&str) -> Option<u32>,
) -> Result<u32, OptionError> {
    text.parse::<u32>()
        .ok()
        .filter(|&id| id <= 0xFF_FFFF)
        .or_else(|| message_id(text))
        .ok_or_else(|| {
            err(
                name,
                format!("\"{text}\" is neither a message id nor a message name"),
            )
        })
}

fn set_filter(
    link: &mut LinkConfig,
    name: &str,
    value: &str,
    message_id: &dyn Fn(&str) -> Option<u32>,
) -> Result<(), OptionError> {
    let (action, rest) = name.split_once('_').unwrap_or((name, ""));
    let (what, direction) = rest.rsplit_once('_').unwrap_or((rest, ""));
    let filters = if direction == "in" {
        &mut link.filters_in
    } else {
        &mut link.filters_out
    };
    let mut values = Vec::new();
    for item in value.split(',') {
        let v = match what {
            "msg" => message(name, item, message_id)?,
            _ => item
                .parse::<u8>()
                .map(u32::from)
                .map_err(|_| err(name, format!("\"{item}\" is not an id 0-255")))?,
        };
        values.push(v);
    }
    let filter: &mut IdFilter = match what {
        "msg" => &mut filters.msg,
        "src_sys" => &mut filters.src_sys,
        _ => &mut filters.src_comp,
    };
    if action == "allow" {
        filter.allow = Some(values);
    } else {
        filter.block = values;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn none(_: &str) -> Option<u32> {
        None
    }

    #[test]
    fn every_option() {
        let key = "00".repeat(32);
        let text = format!(
            "version=2&key={key}&link_id=3&secure=true&trusted=1&name=radio&allow_msg_in=0,30\
             &block_src_sys_out=5&rate=30:10,ATTITUDE:5&bytes_per_s=5760&queue=64"
        );
        let named = |n: &str| (n == "ATTITUDE").then_some(30);
        let link = parse(&text, "udpin:x", &named).unwrap();
        assert_eq!(link.name, "radio");
        assert_eq!(link.version, VersionMode::Mavlink2);
        assert_eq!(link.signing.as_ref().map(|s| s.link_id), Some(3));
        assert!(link.secure && link.trusted);
        assert_eq!(link.filters_in.msg.allow, Some(alloc::vec![0, 30]));
        assert!(!link.filters_out.passes(1, 5, 1));
        assert!(link.filters_out.passes(1, 6, 1));
        assert_eq!(link.limits.per_message, alloc::vec![(30, 10), (30, 5)]);
        assert_eq!(link.limits.bytes_per_s, Some(5760));
        assert_eq!(link.queue_frames, 64);
    }

    #[test]
    fn defaults_and_name() {
        let link = parse("", "udpin:0.0.0.0:14550", &none).unwrap();
        assert_eq!(link.name, "udpin:0.0.0.0:14550");
        assert_eq!(link.version, VersionMode::Auto);
        assert!(link.signing.is_none() && !link.trusted && !link.secure);
    }

    #[test]
    fn errors_name_the_option() {
        let key = "ab".repeat(32);
        let cases: [(String, &str); 14] = [
            (
                "foo=1".into(),
                "link option \"foo\": unknown option; expected one of version, key",
            ),
            (
                "version".into(),
                "link option \"version\": expected name=value",
            ),
            (
                "version=3".into(),
                "link option \"version\": \"3\" is not 1, 2 or auto",
            ),
            ("key=12".into(), "link option \"key\": "),
            (
                format!("version=1&key={key}"),
                "link option \"key\": a signed link is MAVLink 2",
            ),
            (
                "trusted=maybe".into(),
                "link option \"trusted\": \"maybe\" is not true or false",
            ),
            (
                format!("link_id=300&key={key}"),
                "link option \"link_id\": \"300\" is not a number 0-255",
            ),
            (
                "link_id=1".into(),
                "link option \"link_id\": only means something with a key",
            ),
            ("name=a&name=b".into(), "link option \"name\": given twice"),
            (
                "rate=30".into(),
                "link option \"rate\": \"30\" is not MESSAGE:RATE",
            ),
            (
                "rate=FOO:3".into(),
                "link option \"rate\": \"FOO\" is neither a message id nor a message name",
            ),
            (
                "rate=30:0".into(),
                "link option \"rate\": \"0\" is not a rate in Hz above 0",
            ),
            (
                "block_src_sys_in=256".into(),
                "link option \"block_src_sys_in\": \"256\" is not an id 0-255",
            ),
            (
                "bytes_per_s=-1".into(),
                "link option \"bytes_per_s\": \"-1\" is not a byte rate above 0",
            ),
        ];
        for (text, want) in cases {
            let got = parse(&text, "x", &none).unwrap_err().to_string();
            assert!(got.starts_with(want), "{text}: {got}");
        }
    }
}
