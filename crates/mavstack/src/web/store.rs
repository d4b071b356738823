//! The latest message of each type from each component, as `GET /mavlink` shows it, and
//! what the status page keeps beyond it: the recent track and the last STATUSTEXT lines of
//! each component.
//!
//! Frames are kept as their payload; JSON is made only when a client asks.

use std::collections::{BTreeMap, VecDeque};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use mavstack_core::Message as _;
use mavstack_dialects::common::{GlobalPositionInt, Heartbeat, Statustext};
use serde_json::{Map, Value as Json};

use super::json::{Header, JsonMapping};

/// Track points kept per component (one a second at most: ten minutes).
pub(crate) const TRACK_POINTS: usize = 600;
/// STATUSTEXT lines kept per component.
pub(crate) const TEXT_LINES: usize = 12;

/// One message type from one component: its latest payload and when it came.
#[derive(Debug)]
struct Entry {
    msg_id: u32,
    payload: Vec<u8>,
    first: SystemTime,
    last: SystemTime,
    first_mono: Instant,
    last_mono: Instant,
    counter: u64,
}

/// A STATUSTEXT line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct TextLine {
    /// MAV_SEVERITY (0 emergency to 7 debug).
    pub(crate) severity: u8,
    /// The text.
    pub(crate) text: String,
    /// When it came (seconds since the Unix epoch).
    pub(crate) unix_s: u64,
}

/// What a component has said.
#[derive(Debug, Default)]
struct Component {
    /// By message name.
    messages: BTreeMap<String, Entry>,
    /// (lat, lon in degrees, height above home in metres), one a second at most.
    track: VecDeque<(f64, f64, f64)>,
    track_at: Option<Instant>,
    texts: VecDeque<TextLine>,
}

/// Every component heard, by system and component id.
#[derive(Debug, Default)]
pub(crate) struct Store {
    components: BTreeMap<(u8, u8), Component>,
}

impl Store {
    /// Keeps message `msg_id` (named `name`) from `header`'s sender.
    pub(crate) fn update(&mut self, header: Header, name: &str, msg_id: u32, payload: &[u8]) {
        let now = SystemTime::now();
        let mono = Instant::now();
        let component = self
            .components
            .entry((header.system_id, header.component_id))
            .or_default();
        match component.messages.get_mut(name) {
            Some(e) => {
                e.msg_id = msg_id;
                e.payload.clear();
                e.payload.extend_from_slice(payload);
                e.last = now;
                e.last_mono = mono;
                e.counter = e.counter.wrapping_add(1);
            }
            None => {
                component.messages.insert(
                    name.to_owned(),
                    Entry {
                        msg_id,
                        payload: payload.to_vec(),
                        first: now,
                        last: now,
                        first_mono: mono,
                        last_mono: mono,
                        counter: 1,
                    },
                );
            }
        }
        if msg_id == GlobalPositionInt::ID {
            let p = GlobalPositionInt::decode(payload);
            let due = component
                .track_at
                .is_none_or(|t| mono.duration_since(t).as_secs_f64() >= 1.0);
            if due && (p.lat != 0 || p.lon != 0) {
                component.track_at = Some(mono);
                if component.track.len() == TRACK_POINTS {
                    component.track.pop_front();
                }
                component.track.push_back((
                    f64::from(p.lat) / 1e7,
                    f64::from(p.lon) / 1e7,
                    f64::from(p.relative_alt) / 1000.0,
                ));
            }
        } else if msg_id == Statustext::ID {
            let s = Statustext::decode(payload);
            let end = s.text.iter().position(|&b| b == 0).unwrap_or(s.text.len());
            if component.texts.len() == TEXT_LINES {
                component.texts.pop_front();
            }
            component.texts.push_back(TextLine {
                severity: s.severity.0,
                text: String::from_utf8_lossy(&s.text[..end]).into_owned(),
                unix_s: now.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs()),
            });
        }
    }

    /// `/mavlink`'s whole object:
    /// `{"vehicles":{"S":{"id":S,"components":{"C":{"id":C,"messages":{NAME:…}}}}}}`.
    pub(crate) fn all_json(&self, mapping: &JsonMapping) -> Json {
        let mut vehicles: BTreeMap<u8, Map<String, Json>> = BTreeMap::new();
        for (&(s, c), component) in &self.components {
            let mut messages = Map::new();
            for (name, e) in &component.messages {
                if let Some(v) = entry_json(mapping, e) {
                    messages.insert(name.clone(), v);
                }
            }
            let mut comp = Map::new();
            comp.insert("id".into(), c.into());
            comp.insert("messages".into(), Json::Object(messages));
            vehicles
                .entry(s)
                .or_default()
                .insert(c.to_string(), Json::Object(comp));
        }
        let mut out = Map::new();
        for (s, components) in vehicles {
            let mut v = Map::new();
            v.insert("components".into(), Json::Object(components));
            v.insert("id".into(), s.into());
            out.insert(s.to_string(), Json::Object(v));
        }
        let mut root = Map::new();
        root.insert("vehicles".into(), Json::Object(out));
        Json::Object(root)
    }

    /// `{"message","status"}` of message `name` from component `(s, c)`, if heard.
    pub(crate) fn message_json(
        &self,
        mapping: &JsonMapping,
        s: u8,
        c: u8,
        name: &str,
    ) -> Option<Json> {
        let e = self.components.get(&(s, c))?.messages.get(name)?;
        entry_json(mapping, e)
    }

    /// Every component whose HEARTBEAT was seen: (sysid, compid, the latest, its age in
    /// seconds).
    pub(crate) fn heartbeats(&self) -> Vec<(u8, u8, Heartbeat, f64)> {
        self.components
            .iter()
            .filter_map(|(&(s, c), component)| {
                let e = component.messages.get("HEARTBEAT")?;
                Some((
                    s,
                    c,
                    Heartbeat::decode(&e.payload),
                    e.last_mono.elapsed().as_secs_f64(),
                ))
            })
            .collect()
    }

    /// The recent track of component `(s, c)`: (lat, lon, height above home).
    pub(crate) fn track(&self, s: u8, c: u8) -> Vec<(f64, f64, f64)> {
        self.components
            .get(&(s, c))
            .map(|c| c.track.iter().copied().collect())
            .unwrap_or_default()
    }

    /// The last STATUSTEXT lines of component `(s, c)`, oldest first.
    pub(crate) fn texts(&self, s: u8, c: u8) -> Vec<TextLine> {
        self.components
            .get(&(s, c))
            .map(|c| c.texts.iter().cloned().collect())
            .unwrap_or_default()
    }
}

fn entry_json(mapping: &JsonMapping, e: &Entry) -> Option<Json> {
    let message = mapping.message_json(e.msg_id, &e.payload)?;
    let elapsed = e.last_mono.duration_since(e.first_mono).as_secs_f64();
    // Messages a second between the first and the latest (1.0.2 divides the count by whole
    // seconds, which reads high and is infinite in the first second).
    let frequency = if elapsed > 0.0 {
        e.counter.saturating_sub(1) as f64 / elapsed
    } else {
        0.0
    };
    let mut time = Map::new();
    time.insert("counter".into(), e.counter.into());
    time.insert("first_update".into(), rfc3339(e.first).into());
    time.insert(
        "frequency".into(),
        serde_json::Number::from_f64(f64::from(frequency as f32)).map_or(Json::Null, Json::Number),
    );
    time.insert("last_update".into(), rfc3339(e.last).into());
    let mut status = Map::new();
    status.insert("time".into(), Json::Object(time));
    let mut out = Map::new();
    out.insert("message".into(), message);
    out.insert("status".into(), Json::Object(status));
    Some(Json::Object(out))
}

/// `t` as RFC 3339 in UTC the way chrono writes it (`2026-03-29T16:13:09.123+00:00`: 3, 6
/// or 9 digits of fraction, as few as say it exactly; none for a whole second).
pub(crate) fn rfc3339(t: SystemTime) -> String {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs();
    let nanos = d.subsec_nanos();
    let (y, m, day) = civil_from_days(secs / 86_400);
    let rem = secs % 86_400;
    let fraction = if nanos == 0 {
        String::new()
    } else if nanos.is_multiple_of(1_000_000) {
        format!(".{:03}", nanos / 1_000_000)
    } else if nanos.is_multiple_of(1_000) {
        format!(".{:06}", nanos / 1_000)
    } else {
        format!(".{nanos:09}")
    };
    format!(
        "{y:04}-{m:02}-{day:02}T{:02}:{:02}:{:02}{fraction}+00:00",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// (year, month, day) of a count of days since 1970-01-01 (Howard Hinnant's algorithm).
const fn civil_from_days(days: u64) -> (u64, u64, u64) {
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_are_civil() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        // 2026-03-29 is day 20,541.
        assert_eq!(civil_from_days(20_541), (2026, 3, 29));
        let t = UNIX_EPOCH + core::time::Duration::new(20_541 * 86_400 + 58_389, 123_000_000);
        assert_eq!(rfc3339(t), "2026-03-29T16:13:09.123+00:00");
        let t = UNIX_EPOCH + core::time::Duration::new(0, 1);
        assert_eq!(rfc3339(t), "1970-01-01T00:00:00.000000001+00:00");
    }
}
