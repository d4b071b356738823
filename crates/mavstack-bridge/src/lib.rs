//! Fleet links: a vehicle's MAVLink network onto an MQTT 5 broker (feature `mqtt`) or a
//! Zenoh network (feature `zenoh`), as one more link of a `mavstack` router or node.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! A bridge link is a router link whose far end is a broker connection instead of a
//! socket. Every frame the router sends to it is published on its own key, raw and byte for
//! byte (signatures kept, never converted: the link's version mode is
//! [`VersionMode::Transparent`](mavstack_router::VersionMode::Transparent)); frames
//! published to the vehicle's `in` key come into the router as if a peer had sent them.
//! The key layout (`docs/contracts/fleet-keys.md`), for fleet `F` and vehicle `V`:
//!
//! | key | what |
//! | --- | --- |
//! | `mav/F/V/{sysid}/{compid}/{MSG_NAME}` | every frame from the vehicle's network (unknown ids: the number) |
//! | `mav/F/V/in` | raw frames into the vehicle's network |
//! | `mav/F/V/{sysid}/{compid}/@cmd` | COMMAND_LONG/INT in (MQTT 5 response topic + correlation data; Zenoh: a query), COMMAND_ACK out |
//! | `mav/F/V/@alive` | MQTT: `online` / `offline`, retained, with a last will; Zenoh: a liveliness token |
//!
//! `V` is a stable vehicle id, not the sysid: a fleet reuses sysids. Telemetry goes at
//! QoS 0 (Zenoh: `Drop`) and is latest-wins per key when the broker is slow ([`outbox`]);
//! control traffic (commands, parameters, missions) goes at QoS 1 (Zenoh: `Block` on a
//! priority of its own) and is never dropped without being counted. Commands sent to `@cmd` are run by the bridge itself ([`command`]): it
//! resends them as a ground station does, matches the COMMAND_ACK by command and sender,
//! and answers each request once (intermediate IN_PROGRESS acks aside), with the ACK or a
//! timeout error.
//!
//! The sans-IO parts (keys, the outbox, the command tracker) take bytes and times and give
//! bytes back; [`open`] starts the tokio driver over rumqttc or the zenoh crate.
//!
//! The other side, a ground or cloud router, subscribes to one vehicle, a list or the whole
//! fleet (`vid=*`, `vid=a,b`, or `side=ground` for one) and presents each vehicle as a link
//! of its own to the local ground stations; what they send a vehicle goes to its `in` key.
//!
//! ```
//! use mavstack_bridge::{BridgeSpec, Side};
//! let spec = BridgeSpec::parse("mqtt://127.0.0.1:1883?fleet=demo&vid=truck-7").unwrap();
//! let Side::Vehicle(keys) = &spec.side else { panic!() };
//! assert_eq!(keys.alive(), "mav/demo/truck-7/@alive");
//! assert_eq!(spec.client_id, "mavstack-demo-truck-7");
//! let ground = BridgeSpec::parse("mqtt://127.0.0.1:1883?fleet=demo&vid=*").unwrap();
//! assert_eq!(ground.side, Side::Ground(vec![]));
//! ```
//!
//! ## Features
//! - `mqtt` (default): MQTT 5 links, through rumqttc.
//! - `tls`: `mqtts://` links (MQTT over TLS, through native-tls).
//! - `zenoh`: Zenoh links, through the zenoh crate.
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (`fuzzing::fuzz_bridge`).
#![forbid(unsafe_code)]

pub mod checksum;
pub mod command;
#[cfg(any(feature = "mqtt", feature = "zenoh"))]
mod driver;
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub mod fuzzing;
pub mod keys;
#[cfg(feature = "mqtt")]
mod mqtt;
pub mod outbox;
pub mod remap;
#[cfg(feature = "zenoh")]
mod zenoh;

#[cfg(any(feature = "mqtt", feature = "zenoh"))]
pub use driver::{Bridge, BridgeCounters, BridgeHandle, BridgeStats};
pub use keys::{KeyError, Keys, Topic};

/// A bridge link that could not be opened.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum OpenError {
    /// This build carries no links of that kind.
    #[error("link \"{name}\": this build has no {scheme} links (cargo feature \"{feature}\")")]
    NotBuilt {
        /// The link's name.
        name: String,
        /// `mqtt`, `zenoh`.
        scheme: &'static str,
        /// The feature that carries them.
        feature: &'static str,
    },
    /// A TLS file that cannot be read or used (`ca`, `client_cert`, `client_key`).
    #[error("link \"{name}\": {option} \"{path}\": {reason}")]
    Tls {
        /// The link's name.
        name: String,
        /// The option that named the file.
        option: &'static str,
        /// The file.
        path: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The Zenoh session's settings were refused (a bad `listen` endpoint).
    #[error("link \"{name}\": {reason}")]
    Zenoh {
        /// The link's name.
        name: String,
        /// What Zenoh said.
        reason: String,
    },
}

/// Opens the bridge link `spec` describes (MQTT or Zenoh); `dialect` names the messages
/// in the keys. The broker or Zenoh router is connected in the background, and again
/// whenever the connection drops: opening never waits for it. Needs a tokio runtime.
///
/// # Errors
/// [`OpenError`]: a kind of link this build does not carry, or Zenoh settings refused.
#[cfg(any(feature = "mqtt", feature = "zenoh"))]
pub fn open(
    spec: &BridgeSpec,
    dialect: mavstack_router::MessageTable,
) -> Result<Bridge, OpenError> {
    #[cfg(not(all(feature = "mqtt", feature = "zenoh", feature = "tls")))]
    let not_built = |scheme, feature| OpenError::NotBuilt {
        name: spec.name.clone(),
        scheme,
        feature,
    };
    match spec.transport {
        #[cfg(feature = "tls")]
        Transport::Mqtts => mqtt::open(spec, dialect),
        #[cfg(not(feature = "tls"))]
        Transport::Mqtts => Err(not_built("mqtts", "tls")),
        #[cfg(feature = "mqtt")]
        Transport::Mqtt => mqtt::open(spec, dialect),
        #[cfg(not(feature = "mqtt"))]
        Transport::Mqtt => Err(not_built("mqtt", "mqtt")),
        #[cfg(feature = "zenoh")]
        Transport::ZenohClient | Transport::ZenohPeer => zenoh::open(spec, dialect),
        #[cfg(not(feature = "zenoh"))]
        Transport::ZenohClient | Transport::ZenohPeer => Err(not_built("zenoh", "zenoh")),
    }
}

/// Which end of the broker a bridge link is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Side {
    /// On the vehicle: its network onto the vehicle's keys.
    Vehicle(Keys),
    /// On the ground: the vehicles named (every vehicle of the fleet when empty), each a
    /// link of the router.
    Ground(Vec<String>),
}

/// The link strings a bridge opens (the CLI sends these here instead of to the transport).
#[must_use]
pub fn is_bridge_link(text: &str) -> bool {
    ["mqtt://", "mqtts://", "zenoh://", "zenoh:"]
        .iter()
        .any(|p| text.starts_with(p))
}

/// What carries a bridge link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Transport {
    /// An MQTT 5 broker (`mqtt://HOST:PORT`, default port 1883).
    Mqtt,
    /// An MQTT 5 broker over TLS (`mqtts://HOST:PORT`, default port 8883): the server's
    /// certificate checked against the system's roots or `ca=FILE`, and a client
    /// certificate (`client_cert=FILE&client_key=FILE`) when the broker asks for one.
    Mqtts,
    /// A client of a Zenoh router (`zenoh://HOST:PORT`, default port 7447).
    ZenohClient,
    /// A Zenoh peer in this process (`zenoh:`): it finds other peers by scouting and can
    /// listen itself (`listen=tcp/ADDR:PORT`).
    ZenohPeer,
}

/// A parsed bridge link string: `mqtt://HOST:PORT?fleet=F&vid=V[&trusted=true][&user=U]
/// [&password=P][&client_id=C][&name=N][&max_vehicles=N]`,
/// `zenoh://HOST:PORT?fleet=F&vid=V[&trusted=true][&name=N]` or
/// `zenoh:?fleet=F&vid=V[&listen=ENDPOINT]...` (`max_vehicles`: ground side only).
#[derive(Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct BridgeSpec {
    /// What carries it.
    pub transport: Transport,
    /// The broker's (or Zenoh router's) host; empty for a Zenoh peer.
    pub host: String,
    /// The broker's port (default 1883 for MQTT, 7447 for Zenoh; 0 for a Zenoh peer).
    pub port: u16,
    /// Zenoh peer: the endpoint it listens on (`tcp/127.0.0.1:7448`), if any.
    pub listen: Option<String>,
    /// `mqtts://`: the CA certificate (PEM) the broker's certificate must chain to, instead
    /// of the system's roots.
    pub ca: Option<std::path::PathBuf>,
    /// `mqtts://`: the client certificate and its private key (PEM files).
    pub client_cert: Option<(std::path::PathBuf, std::path::PathBuf)>,
    /// The fleet.
    pub fleet: String,
    /// Which end it is.
    pub side: Side,
    /// Frames from the broker may be signed onto signed links.
    pub trusted: bool,
    /// MQTT user name and password.
    pub credentials: Option<(String, String)>,
    /// MQTT client id (default `mavstack-F-V`).
    pub client_id: String,
    /// The link's name in statistics and logs (default the string without its options).
    pub name: String,
    /// Ground side: vehicles that may be links of the router at once (default
    /// [`DEFAULT_MAX_VEHICLES`]); further ones are refused, counted and warned about, until
    /// a vehicle goes offline.
    pub max_vehicles: usize,
}

/// Vehicles a ground-side link makes links of at once unless `max_vehicles` says otherwise.
pub const DEFAULT_MAX_VEHICLES: usize = 64;

impl core::fmt::Debug for BridgeSpec {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        // The password never shows.
        f.debug_struct("BridgeSpec")
            .field("transport", &self.transport)
            .field("host", &self.host)
            .field("port", &self.port)
            .field("listen", &self.listen)
            .field("ca", &self.ca)
            .field("client_cert", &self.client_cert)
            .field("fleet", &self.fleet)
            .field("side", &self.side)
            .field("trusted", &self.trusted)
            .field("user", &self.credentials.as_ref().map(|(u, _)| u))
            .field("client_id", &self.client_id)
            .field("name", &self.name)
            .field("max_vehicles", &self.max_vehicles)
            .finish()
    }
}

/// A bridge link string that cannot be used.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BridgeSpecError {
    /// Not `mqtt://HOST:PORT`, `zenoh://HOST:PORT` nor `zenoh:`.
    #[error(
        "link \"{text}\": expected mqtt://HOST:PORT?fleet=F&vid=V, zenoh://HOST:PORT?... or zenoh:?..."
    )]
    Syntax {
        /// The link string (options left out).
        text: String,
    },
    /// A scheme this build does not carry.
    #[error("link \"{text}\": {scheme} links are not supported (mqtt:// and zenoh:// are)")]
    Unsupported {
        /// The link string (options left out).
        text: String,
        /// `mqtts`, `zenoh`.
        scheme: String,
    },
    /// A bad port.
    #[error("link \"{text}\": bad port \"{port}\"")]
    Port {
        /// The link string (options left out).
        text: String,
        /// What was given.
        port: String,
    },
    /// An unknown option or a bad value.
    #[error("link \"{text}\": option \"{option}\": {what}")]
    Option {
        /// The link string (options left out).
        text: String,
        /// The option's name.
        option: String,
        /// What is wrong.
        what: String,
    },
    /// `fleet` or `vid` missing or not a key segment.
    #[error("link \"{text}\": {source}")]
    Key {
        /// The link string (options left out).
        text: String,
        /// What is wrong.
        source: KeyError,
    },
}

impl BridgeSpec {
    /// Parses a bridge link string.
    ///
    /// # Errors
    /// [`BridgeSpecError`] naming the part that is wrong (a password never appears in it).
    pub fn parse(text: &str) -> Result<Self, BridgeSpecError> {
        let (conn, opts) = text.split_once('?').unwrap_or((text, ""));
        let shown = conn.to_owned();
        let (scheme, rest) = conn
            .split_once("://")
            .or_else(|| conn.split_once(':'))
            .ok_or_else(|| BridgeSpecError::Syntax {
                text: shown.clone(),
            })?;
        let transport = match (scheme, rest) {
            ("mqtt", _) if conn.starts_with("mqtt://") => Transport::Mqtt,
            ("mqtts", _) if conn.starts_with("mqtts://") => Transport::Mqtts,
            ("zenoh", _) if conn.starts_with("zenoh://") => Transport::ZenohClient,
            ("zenoh", "") => Transport::ZenohPeer,
            ("mqtt" | "mqtts" | "zenoh", _) => {
                return Err(BridgeSpecError::Syntax { text: shown });
            }
            _ => {
                return Err(BridgeSpecError::Unsupported {
                    text: shown,
                    scheme: scheme.to_owned(),
                });
            }
        };
        let default_port = match transport {
            Transport::Mqtt => 1883,
            Transport::Mqtts => 8883,
            _ => 7447,
        };
        let (host, port) = match rest.rsplit_once(':') {
            Some((h, p)) => {
                let port = p.parse::<u16>().ok().filter(|&p| p > 0).ok_or_else(|| {
                    BridgeSpecError::Port {
                        text: shown.clone(),
                        port: p.to_owned(),
                    }
                })?;
                (h, port)
            }
            None if transport == Transport::ZenohPeer => ("", 0),
            None => (rest, default_port),
        };
        let host = host.trim_start_matches('[').trim_end_matches(']');
        let peer = transport == Transport::ZenohPeer;
        if (host.is_empty() && !peer) || host.contains(['/', '?', '&', ' ']) {
            return Err(BridgeSpecError::Syntax { text: shown });
        }
        let option_err = |option: &str, what: &str| BridgeSpecError::Option {
            text: shown.clone(),
            option: option.to_owned(),
            what: what.to_owned(),
        };
        let (mut fleet, mut vid, mut trusted, mut ground) = (None, None, false, false);
        let (mut user, mut password, mut client_id, mut name) = (None, None, None, None);
        let mut listen = None;
        let mut max_vehicles = None;
        let (mut ca, mut client_cert, mut client_key) = (None, None, None);
        let mqtt = matches!(transport, Transport::Mqtt | Transport::Mqtts);
        let tls = transport == Transport::Mqtts;
        for opt in opts.split('&').filter(|o| !o.is_empty()) {
            let (k, v) = opt
                .split_once('=')
                .ok_or_else(|| option_err(opt, "expected name=value"))?;
            let slot = match k {
                "listen" if peer => &mut listen,
                "ca" if tls => &mut ca,
                "client_cert" if tls => &mut client_cert,
                "client_key" if tls => &mut client_key,
                "ca" | "client_cert" | "client_key" if !tls => {
                    return Err(option_err(k, "applies to mqtts:// links only"));
                }
                "user" | "password" | "client_id" | "listen" if !mqtt => {
                    return Err(option_err(
                        k,
                        "does not apply to this link (Zenoh access control is the Zenoh \
                         router's configuration; listen is for zenoh: peers)",
                    ));
                }
                "fleet" => &mut fleet,
                "vid" => &mut vid,
                "user" => &mut user,
                "password" => &mut password,
                "client_id" => &mut client_id,
                "name" => &mut name,
                "side" => {
                    ground = match v {
                        "ground" => true,
                        "vehicle" => false,
                        _ => return Err(option_err(k, "expected vehicle or ground")),
                    };
                    continue;
                }
                "max_vehicles" => {
                    if max_vehicles.is_some() {
                        return Err(option_err(k, "given twice"));
                    }
                    let n = v.parse::<usize>().ok().filter(|&n| n > 0);
                    max_vehicles =
                        Some(n.ok_or_else(|| option_err(k, "expected a number from 1 up"))?);
                    continue;
                }
                "trusted" => {
                    trusted = mavstack_router::options::parse_bool(v)
                        .ok_or_else(|| option_err(k, "expected true, 1, yes or false, 0, no"))?;
                    continue;
                }
                "version" | "key" | "link_id" | "secure" => {
                    return Err(option_err(
                        k,
                        "does not apply to a bridge link (frames cross it byte for byte)",
                    ));
                }
                _ => return Err(option_err(k, "unknown option")),
            };
            if slot.is_some() {
                return Err(option_err(k, "given twice"));
            }
            *slot = Some(v.to_owned());
        }
        let key_err = |source| BridgeSpecError::Key {
            text: shown.clone(),
            source,
        };
        let fleet = fleet.unwrap_or_default();
        let vid = vid.unwrap_or_default();
        let side = if ground || vid == "*" || vid.contains(',') {
            let vids: Vec<String> = if vid == "*" {
                Vec::new()
            } else {
                vid.split(',').map(str::to_owned).collect()
            };
            for v in &vids {
                Keys::new(&fleet, v).map_err(key_err)?;
            }
            if vids.is_empty() {
                Keys::new(&fleet, "all").map_err(key_err)?;
            }
            Side::Ground(vids)
        } else {
            Side::Vehicle(Keys::new(&fleet, &vid).map_err(key_err)?)
        };
        if max_vehicles.is_some() && matches!(side, Side::Vehicle(_)) {
            return Err(option_err(
                "max_vehicles",
                "applies to the ground side only (vid=*, a list, or side=ground)",
            ));
        }
        let credentials = match (user, password) {
            (Some(u), p) => Some((u, p.unwrap_or_default())),
            (None, Some(_)) => return Err(option_err("password", "needs user")),
            (None, None) => None,
        };
        if let Some(l) = &listen {
            let port = l.strip_prefix("tcp/").and_then(|a| a.rsplit_once(':'));
            if !port.is_some_and(|(h, p)| !h.is_empty() && p.parse::<u16>().is_ok()) {
                return Err(option_err("listen", "expected tcp/ADDRESS:PORT"));
            }
        }
        let client_cert = match (client_cert, client_key) {
            (Some(c), Some(k)) => Some((c.into(), k.into())),
            (None, None) => None,
            (Some(_), None) => return Err(option_err("client_cert", "needs client_key")),
            (None, Some(_)) => return Err(option_err("client_key", "needs client_cert")),
        };
        let client_id = client_id.unwrap_or_else(|| match &side {
            Side::Vehicle(keys) => format!("mavstack-{fleet}-{}", keys.vid()),
            Side::Ground(_) => format!("mavstack-{fleet}-ground-{}", std::process::id()),
        });
        Ok(Self {
            transport,
            host: host.to_owned(),
            port,
            listen,
            ca: ca.map(Into::into),
            client_cert,
            fleet,
            side,
            trusted,
            credentials,
            client_id,
            name: name.unwrap_or(shown),
            max_vehicles: max_vehicles.unwrap_or(DEFAULT_MAX_VEHICLES),
        })
    }

    /// The router's settings for this link: transparent framing, `trusted` as given; a
    /// vehicle's link also gets every frame of the network (a monitor), a ground link's
    /// vehicles are routed to like any link's peers.
    #[must_use]
    pub fn link_config(&self) -> mavstack_router::LinkConfig {
        let mut config = mavstack_router::LinkConfig::new(self.name.clone());
        config.version = mavstack_router::VersionMode::Transparent;
        config.trusted = self.trusted;
        config.monitor = matches!(self.side, Side::Vehicle(_));
        config
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_documented_form() {
        let s = BridgeSpec::parse(
            "mqtt://broker.local:8883?fleet=f1&vid=v-2&trusted=true&user=u&password=secret",
        )
        .unwrap();
        assert_eq!((s.host.as_str(), s.port), ("broker.local", 8883));
        let Side::Vehicle(keys) = &s.side else {
            panic!("a vehicle link: {s:?}")
        };
        assert_eq!(keys.input(), "mav/f1/v-2/in");
        assert!(s.trusted);
        assert_eq!(s.credentials, Some(("u".into(), "secret".into())));
        assert_eq!(s.name, "mqtt://broker.local:8883");
        assert!(!format!("{s:?}").contains("secret"));
        let c = s.link_config();
        assert_eq!(c.version, mavstack_router::VersionMode::Transparent);
        assert!(c.trusted && c.monitor);
        let g = BridgeSpec::parse("mqtt://h?fleet=a&vid=b,c-1").unwrap();
        assert_eq!(g.side, Side::Ground(vec!["b".into(), "c-1".into()]));
        assert!(!g.link_config().monitor);
        let one = BridgeSpec::parse("mqtt://h?fleet=a&vid=b&side=ground").unwrap();
        assert_eq!(one.side, Side::Ground(vec!["b".into()]));
        assert_eq!(
            BridgeSpec::parse("mqtt://h?fleet=a&vid=b").unwrap().port,
            1883
        );
        let z = BridgeSpec::parse("zenoh://10.0.0.2?fleet=a&vid=b").unwrap();
        assert_eq!(
            (z.transport, z.host.as_str(), z.port),
            (Transport::ZenohClient, "10.0.0.2", 7447)
        );
        let p = BridgeSpec::parse("zenoh:?fleet=a&vid=b&listen=tcp/127.0.0.1:7448").unwrap();
        assert_eq!(p.transport, Transport::ZenohPeer);
        assert_eq!(p.listen.as_deref(), Some("tcp/127.0.0.1:7448"));
        assert_eq!(p.name, "zenoh:");
    }

    /// `trusted` reads booleans as every link option does (docs/contracts/link-options.md).
    #[test]
    fn trusted_takes_the_link_options_booleans() {
        let trusted = |v: &str| {
            BridgeSpec::parse(&format!("mqtt://h:1?fleet=a&vid=b&trusted={v}"))
                .map(|s| s.trusted)
                .map_err(|e| e.to_string())
        };
        for (v, expected) in [
            ("true", true),
            ("1", true),
            ("yes", true),
            ("false", false),
            ("0", false),
            ("no", false),
        ] {
            assert_eq!(trusted(v), Ok(expected), "{v}");
        }
    }

    #[test]
    fn bad_strings_name_what_is_wrong() {
        let err = |t: &str| BridgeSpec::parse(t).unwrap_err().to_string();
        assert!(err("mqtt://h:1883?vid=b").contains("fleet"));
        assert!(err("mqtt://h:1883?fleet=a").contains("vid"));
        assert!(err("mqtt://h:1883?fleet=a/b&vid=c").contains("fleet"));
        assert!(err("mqtt://h:99999?fleet=a&vid=b").contains("port \"99999\""));
        assert!(err("mqtt://h:1?fleet=a&vid=b&key=00").contains("does not apply"));
        assert!(err("mqtt://h:1?fleet=a&vid=b&colour=red").contains("unknown option"));
        assert!(err("mqtt://h:1?fleet=a&vid=b&trusted=on").contains("true, 1, yes or false"));
        assert!(err("mqtt://h:1?fleet=a&vid=b,c/d").contains("vid \"c/d\""));
        assert!(err("mqtt://h:1?fleet=a&vid=b&side=sky").contains("vehicle or ground"));
        assert!(err("mqtt://h?fleet=a&vid=b&ca=/x.pem").contains("mqtts:// links only"));
        assert!(err("mqtts://h?fleet=a&vid=b&client_cert=/c.pem").contains("needs client_key"));
        let t = BridgeSpec::parse("mqtts://h?fleet=a&vid=b&ca=/ca.pem&client_cert=c&client_key=k")
            .unwrap();
        assert_eq!((t.transport, t.port), (Transport::Mqtts, 8883));
        assert_eq!(t.ca.as_deref(), Some(std::path::Path::new("/ca.pem")));
        assert!(t.client_cert.is_some());
        assert!(err("mqttx://h:8883?fleet=a&vid=b").contains("not supported"));
        assert!(err("zenoh://h:7447?fleet=a&vid=b&user=u").contains("does not apply"));
        assert!(err("zenoh://h?fleet=a&vid=b&listen=tcp/0.0.0.0:1").contains("does not apply"));
        assert!(err("zenoh:?fleet=a&vid=b&password=p").contains("does not apply"));
        assert!(err("zenoh:?fleet=a&vid=b&listen=udp/h:1").contains("tcp/ADDRESS:PORT"));
        let e = err("mqtt://h:1?fleet=a&vid=b&password=hunter2");
        assert!(e.contains("needs user") && !e.contains("hunter2"));
        assert!(is_bridge_link("mqtt://x") && !is_bridge_link("udpin:0.0.0.0:14550"));
        assert!(err("mqtt://h?fleet=a&vid=*&max_vehicles=0").contains("from 1 up"));
        assert!(err("mqtt://h?fleet=a&vid=*&max_vehicles=x").contains("from 1 up"));
        assert!(err("mqtt://h?fleet=a&vid=b&max_vehicles=3").contains("ground side only"));
        let g = BridgeSpec::parse("zenoh://h?fleet=a&vid=*&max_vehicles=3").unwrap();
        assert_eq!(g.max_vehicles, 3);
        let g = BridgeSpec::parse("mqtt://h?fleet=a&vid=*").unwrap();
        assert_eq!(g.max_vehicles, DEFAULT_MAX_VEHICLES);
    }
}
