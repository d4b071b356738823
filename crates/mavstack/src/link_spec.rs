//! A link as written on a command line: a connection string, then `?` and `&`-separated
//! link options (`docs/contracts/link-options.md`).
//!
//! ```
//! use mavstack::LinkSpec;
//! let spec = LinkSpec::parse("udpin:0.0.0.0:14550?version=1&name=legacy", &|_| None).unwrap();
//! assert_eq!(spec.config.name, "legacy");
//! assert_eq!(spec.conn.to_string(), "udpin:0.0.0.0:14550");
//! let err = LinkSpec::parse("udpin:0.0.0.0:14550?version=3", &|_| None).unwrap_err();
//! assert_eq!(err.to_string(), r#"link "udpin:0.0.0.0:14550?version=3": link option "version": "3" is not 1, 2 or auto"#);
//! let key = "ab".repeat(32);
//! let err = LinkSpec::parse(&format!("udpin:0.0.0.0:1?key={key}&version=1"), &|_| None).unwrap_err();
//! assert!(!err.to_string().contains(&key), "keys never appear in messages");
//! let spec = LinkSpec::parse("udpin:0.0.0.0:14550?max_peers=8&name=gcs", &|_| None).unwrap();
//! assert_eq!((spec.max_peers, spec.config.name.as_str()), (8, "gcs"));
//! let err = LinkSpec::parse("udpin:0.0.0.0:14550?max_peers=0", &|_| None).unwrap_err();
//! assert_eq!(err.to_string(), r#"link "udpin:0.0.0.0:14550?max_peers=0": link option "max_peers": "0" is not a number 1-65535"#);
//! ```

use mavstack_core::MessageTable;
use mavstack_router::{LinkConfig, OptionError, options};
use mavstack_transport::{ConnSpec, ConnSpecError};

/// A link to open: where, and how the router treats it.
#[derive(Clone, Debug)]
pub struct LinkSpec {
    /// Where the link goes.
    pub conn: ConnSpec,
    /// Its options (name, version, key, filters...).
    pub config: LinkConfig,
    /// The most peers a UDP link keeps (the `max_peers` option, 1-65535; default
    /// [`mavstack_transport::Link::DEFAULT_MAX_PEERS`]). Other kinds of link refuse the
    /// option.
    pub max_peers: usize,
    /// The link as written, its key redacted ([`redacted`](Self::redacted)).
    shown: String,
}

/// A link string that cannot be used.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LinkSpecError {
    /// The connection string.
    #[error("link \"{text}\": {source}")]
    Conn {
        /// The whole link string.
        text: String,
        /// What is wrong.
        source: ConnSpecError,
    },
    /// An option.
    #[error("link \"{text}\": {source}")]
    Option {
        /// The whole link string.
        text: String,
        /// What is wrong.
        source: OptionError,
    },
}

/// `text` with the value of a `key` option replaced by `<redacted>`: link strings appear in
/// errors and logs, keys never do.
///
/// ```
/// let key = "ab".repeat(32);
/// let shown = mavstack::redacted(&format!("udpin:0.0.0.0:14550?name=gcs&key={key}"));
/// assert_eq!(shown, "udpin:0.0.0.0:14550?name=gcs&key=<redacted>");
/// ```
#[must_use]
pub fn redacted(text: &str) -> String {
    let Some((conn, opts)) = text.split_once('?') else {
        return text.to_owned();
    };
    let opts: Vec<String> = opts
        .split('&')
        .map(|o| match o.split_once('=') {
            Some(("key", _)) => "key=<redacted>".to_owned(),
            _ => o.to_owned(),
        })
        .collect();
    format!("{conn}?{}", opts.join("&"))
}

impl LinkSpec {
    /// Parses `text` for links of dialect `table`: message names in filters and `rate`
    /// resolve in it, without regard to case (`docs/contracts/link-options.md`).
    ///
    /// ```
    /// use mavstack::LinkSpec;
    /// use mavstack::core::MessageTable;
    /// let common = MessageTable::of::<mavstack::dialects::common::MavMessage>();
    /// let spec = LinkSpec::parse_in("udpin:0.0.0.0:14550?block_msg_out=attitude", &common).unwrap();
    /// assert!(!spec.config.filters_out.msg.passes(30));
    /// let err = LinkSpec::parse_in("udpin:0.0.0.0:14550?block_msg_out=NOT_A_MESSAGE", &common);
    /// assert!(err.unwrap_err().to_string().contains("\"NOT_A_MESSAGE\""));
    /// ```
    ///
    /// # Errors
    /// [`LinkSpecError`] naming the connection string or the option at fault.
    pub fn parse_in(text: &str, table: &MessageTable) -> Result<Self, LinkSpecError> {
        Self::parse(text, &|name| {
            table
                .entries()
                .iter()
                .find(|m| m.name.eq_ignore_ascii_case(name))
                .map(|m| m.id)
        })
    }

    /// Parses `text`. `message_id` turns a message name into its id (filters and `rate`
    /// take names as well as numbers).
    ///
    /// # Errors
    /// [`LinkSpecError`] naming the connection string or the option at fault.
    pub fn parse(
        text: &str,
        message_id: &dyn Fn(&str) -> Option<u32>,
    ) -> Result<Self, LinkSpecError> {
        let (conn_text, opts) = text.split_once('?').unwrap_or((text, ""));
        let conn: ConnSpec = conn_text.parse().map_err(|source| LinkSpecError::Conn {
            text: redacted(text),
            source,
        })?;
        let option_error = |source| LinkSpecError::Option {
            text: redacted(text),
            source,
        };
        let (max_peers, rest) = take_max_peers(opts, &conn).map_err(option_error)?;
        let config = options::parse(&rest, &conn.to_string(), message_id).map_err(|mut e| {
            // The router's options do not know the one the transport takes.
            if e.reason.starts_with("unknown option; expected one of") {
                e.reason.push_str(", max_peers");
            }
            option_error(e)
        })?;
        Ok(Self {
            conn,
            config,
            max_peers: max_peers.unwrap_or(mavstack_transport::Link::DEFAULT_MAX_PEERS),
            shown: redacted(text),
        })
    }

    /// The link as it was written, with the value of its `key` option (if any) replaced by
    /// `<redacted>`: how a link appears in errors, logs and JSON.
    ///
    /// ```
    /// use mavstack::LinkSpec;
    /// let key = "0123456789abcdef".repeat(4);
    /// let spec = LinkSpec::parse(&format!("tcp:127.0.0.1:5760?key={key}"), &|_| None).unwrap();
    /// assert_eq!(spec.redacted(), "tcp:127.0.0.1:5760?key=<redacted>");
    /// ```
    #[must_use]
    pub fn redacted(&self) -> &str {
        &self.shown
    }
}

/// Takes the `max_peers` option out of `opts`: its value (1-65535, UDP links only) and the
/// other options.
fn take_max_peers(opts: &str, conn: &ConnSpec) -> Result<(Option<usize>, String), OptionError> {
    const NAME: &str = "max_peers";
    let err = |reason: String| OptionError {
        option: NAME.to_owned(),
        reason,
    };
    let mut max_peers = None;
    let mut rest = Vec::new();
    for pair in opts.split('&') {
        let Some(value) = pair.strip_prefix("max_peers=") else {
            if pair == NAME {
                return Err(err("expected name=value".to_owned()));
            }
            rest.push(pair);
            continue;
        };
        if max_peers.is_some() {
            return Err(err("given twice".to_owned()));
        }
        let n = value
            .parse::<u16>()
            .ok()
            .filter(|&n| n >= 1)
            .ok_or_else(|| err(format!("\"{value}\" is not a number 1-65535")))?;
        max_peers = Some(usize::from(n));
    }
    if max_peers.is_some()
        && !matches!(
            conn,
            ConnSpec::UdpIn { .. } | ConnSpec::UdpOut { .. } | ConnSpec::UdpBcast { .. }
        )
    {
        return Err(err("only UDP links have peers to bound".to_owned()));
    }
    Ok((max_peers, rest.join("&")))
}

/// Fuzzing entry point for link strings (connection string and options): any text parses to
/// a link or to an error, never a panic; a parsed connection writes back to a string that
/// parses to the same connection; and neither an error nor the redacted text ever shows the
/// value of a `key` option.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_link_spec(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let shown = match LinkSpec::parse(&text, &|name| (name == "ATTITUDE").then_some(30)) {
        Ok(spec) => {
            let written = spec.conn.to_string();
            assert_eq!(
                written.parse::<ConnSpec>().as_ref(),
                Ok(&spec.conn),
                "a connection does not read back from {written:?}"
            );
            redacted(&text)
        }
        Err(e) => e.to_string(),
    };
    let opts = text.split_once('?').map_or("", |(_, o)| o);
    for key in opts.split('&').filter_map(|o| o.strip_prefix("key=")) {
        // Only real keys (64 hex digits) count: shorter values can be spelled by chance by
        // the text around `key=***` or by the escapes of a quoted string, and a key that is
        // also written (all but a character of it) elsewhere in the text may be shown for that.
        let others = text.replacen(&format!("key={key}"), "", 1);
        let real = key.len() == 64 && key.bytes().all(|b| b.is_ascii_hexdigit());
        let elsewhere = real && (others.contains(&key[1..]) || others.contains(&key[..63]));
        if real && !elsewhere {
            assert!(!shown.contains(key), "a key shown in {shown:?}");
        }
    }
}
