//! The key layout of one vehicle (MQTT topics are the same strings).
//!
//! ```
//! use mavstack_bridge::{Keys, Topic};
//! let keys = Keys::new("fleet1", "v42").unwrap();
//! assert_eq!(keys.message(1, 1, Some("ATTITUDE"), 30), "mav/fleet1/v42/1/1/ATTITUDE");
//! assert_eq!(keys.message(1, 1, None, 99_999), "mav/fleet1/v42/1/1/99999");
//! assert_eq!(keys.parse("mav/fleet1/v42/in"), Some(Topic::In));
//! assert_eq!(keys.parse("mav/fleet1/v42/1/0/@cmd"), Some(Topic::Command { sysid: 1, compid: 0 }));
//! assert_eq!(keys.parse("mav/fleet1/v43/in"), None);
//! ```

use core::fmt::Write as _;

/// A fleet or vehicle id that cannot be a key segment.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum KeyError {
    /// Missing or empty.
    #[error("{what} is required (letters, digits, '_' and '-')")]
    Missing {
        /// `fleet` or `vid`.
        what: &'static str,
    },
    /// A character that is not a letter, a digit, `_` or `-` (MQTT and Zenoh wildcards and
    /// separators among them).
    #[error("{what} \"{value}\": only letters, digits, '_' and '-' may appear")]
    BadChar {
        /// `fleet` or `vid`.
        what: &'static str,
        /// What was given.
        value: String,
    },
}

/// What a topic the bridge subscribed to is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Topic {
    /// `mav/F/V/in`: raw frames into the vehicle's network.
    In,
    /// `mav/F/V/{sysid}/{compid}/@cmd`: a command request for that component.
    Command {
        /// The key's target system.
        sysid: u8,
        /// The key's target component.
        compid: u8,
    },
}

/// What a ground bridge hears about a vehicle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FleetTopic<'a> {
    /// A frame of its network (`mav/F/V/{sysid}/{compid}/{NAME}`).
    Frame {
        /// The vehicle id.
        vid: &'a str,
    },
    /// Its `@alive` key.
    Alive {
        /// The vehicle id.
        vid: &'a str,
    },
}

/// What `topic` is for a ground bridge of `fleet`: a vehicle's frame or liveliness (its
/// `in` and `@cmd` keys, and anything else, are not).
///
/// ```
/// use mavstack_bridge::keys::{FleetTopic, fleet_topic};
/// assert_eq!(fleet_topic("f", "mav/f/v9/1/1/ATTITUDE"), Some(FleetTopic::Frame { vid: "v9" }));
/// assert_eq!(fleet_topic("f", "mav/f/v9/@alive"), Some(FleetTopic::Alive { vid: "v9" }));
/// assert_eq!(fleet_topic("f", "mav/f/v9/1/1/@cmd"), None);
/// ```
#[must_use]
pub fn fleet_topic<'a>(fleet: &str, topic: &'a str) -> Option<FleetTopic<'a>> {
    let rest = topic
        .strip_prefix("mav/")?
        .strip_prefix(fleet)?
        .strip_prefix('/')?;
    let (vid, rest) = rest.split_once('/')?;
    if check("vid", vid).is_err() {
        return None;
    }
    if rest == "@alive" {
        return Some(FleetTopic::Alive { vid });
    }
    let mut parts = rest.split('/');
    let (sysid, compid, name) = (parts.next()?, parts.next()?, parts.next()?);
    if parts.next().is_some()
        || name.is_empty()
        || !name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
        || segment_id(sysid).is_none()
        || segment_id(compid).is_none()
    {
        return None;
    }
    Some(FleetTopic::Frame { vid })
}

/// A sysid or compid segment as the keys write it: decimal, no sign, no leading zero (so
/// that one component has one key: `01` and `+1` are not `1`).
fn segment_id(text: &str) -> Option<u8> {
    let canonical = !text.is_empty()
        && text.bytes().all(|b| b.is_ascii_digit())
        && (text == "0" || !text.starts_with('0'));
    canonical.then(|| text.parse().ok()).flatten()
}

/// The keys of vehicle `vid` in fleet `fleet`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Keys {
    fleet: String,
    vid: String,
    /// `mav/F/V`.
    prefix: String,
}

fn check(what: &'static str, value: &str) -> Result<(), KeyError> {
    if value.is_empty() {
        return Err(KeyError::Missing { what });
    }
    if !value
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
    {
        return Err(KeyError::BadChar {
            what,
            value: value.to_owned(),
        });
    }
    Ok(())
}

impl Keys {
    /// The keys of `vid` in `fleet`.
    ///
    /// # Errors
    /// [`KeyError`]: an empty id, or one with a character other than letters, digits, `_`
    /// and `-`.
    pub fn new(fleet: &str, vid: &str) -> Result<Self, KeyError> {
        check("fleet", fleet)?;
        check("vid", vid)?;
        Ok(Self {
            fleet: fleet.to_owned(),
            vid: vid.to_owned(),
            prefix: format!("mav/{fleet}/{vid}"),
        })
    }

    /// The fleet id.
    #[must_use]
    pub fn fleet(&self) -> &str {
        &self.fleet
    }

    /// The vehicle id.
    #[must_use]
    pub fn vid(&self) -> &str {
        &self.vid
    }

    /// The key of a frame from `(sysid, compid)`: the message's name, or its id when the
    /// dialect does not know it.
    #[must_use]
    pub fn message(&self, sysid: u8, compid: u8, name: Option<&str>, msg_id: u32) -> String {
        let mut key = String::with_capacity(self.prefix.len() + 32);
        // Writing to a String cannot fail.
        let _ = match name {
            Some(name) => write!(key, "{}/{sysid}/{compid}/{name}", self.prefix),
            None => write!(key, "{}/{sysid}/{compid}/{msg_id}", self.prefix),
        };
        key
    }

    /// `mav/F/V/in`.
    #[must_use]
    pub fn input(&self) -> String {
        format!("{}/in", self.prefix)
    }

    /// The MQTT filter of every command key of the vehicle: `mav/F/V/+/+/@cmd`.
    #[must_use]
    pub fn commands_filter(&self) -> String {
        format!("{}/+/+/@cmd", self.prefix)
    }

    /// The command key of `(sysid, compid)`.
    #[must_use]
    pub fn command(&self, sysid: u8, compid: u8) -> String {
        format!("{}/{sysid}/{compid}/@cmd", self.prefix)
    }

    /// The MQTT filter of every frame of the vehicle's network: `mav/F/V/+/+/+`.
    #[must_use]
    pub fn frames_filter(&self) -> String {
        format!("{}/+/+/+", self.prefix)
    }

    /// `mav/F/V/@alive`.
    #[must_use]
    pub fn alive(&self) -> String {
        format!("{}/@alive", self.prefix)
    }

    /// What `topic` is, if it is one of this vehicle's input keys.
    #[must_use]
    pub fn parse(&self, topic: &str) -> Option<Topic> {
        let rest = topic
            .strip_prefix(self.prefix.as_str())?
            .strip_prefix('/')?;
        if rest == "in" {
            return Some(Topic::In);
        }
        let mut parts = rest.split('/');
        let (sysid, compid, last) = (parts.next()?, parts.next()?, parts.next()?);
        if last != "@cmd" || parts.next().is_some() {
            return None;
        }
        Some(Topic::Command {
            sysid: segment_id(sysid)?,
            compid: segment_id(compid)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_that_would_break_the_layout_are_refused() {
        for bad in ["", "a/b", "a+b", "#", "a b", "é"] {
            assert!(Keys::new(bad, "v").is_err(), "{bad:?}");
            assert!(Keys::new("f", bad).is_err(), "{bad:?}");
        }
        assert!(Keys::new("Fleet_1", "truck-07").is_ok());
    }

    #[test]
    fn only_own_input_keys_parse() {
        let k = Keys::new("f", "v").unwrap();
        assert_eq!(
            k.parse(&k.command(255, 190)),
            Some(Topic::Command {
                sysid: 255,
                compid: 190
            })
        );
        for other in [
            "mav/f/v",
            "mav/f/v/",
            "mav/f/vv/in",
            "mav/f/v/1/1/ATTITUDE",
            "mav/f/v/1/1/@cmd/x",
            "mav/f/v/256/1/@cmd",
            "mav/f/v/01/1/@cmd",
            "mav/f/v/+1/1/@cmd",
            "mav/f/v/@alive",
        ] {
            assert_eq!(k.parse(other), None, "{other}");
        }
    }
}
