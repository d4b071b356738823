//! What waits for a slow broker: two lanes.
//!
//! Control frames (commands, parameters, missions, replies) wait in arrival order and go
//! first; none is dropped unless the lane is full, and then it is counted. Telemetry is
//! latest-wins per key: a newer frame on a key replaces the waiting one (counted per key),
//! so a slow broker gets the freshest state of each message instead of an ever older
//! backlog, and a radio link is never held up by it.
//!
//! ```
//! use mavstack_bridge::outbox::{Lane, Outbox};
//! let mut out = Outbox::new(16, 16);
//! out.push(Lane::Telemetry, "k/ATTITUDE".into(), None, vec![1]);
//! out.push(Lane::Telemetry, "k/ATTITUDE".into(), None, vec![2]);
//! out.push(Lane::Control, "k/COMMAND_ACK".into(), None, vec![3]);
//! assert_eq!(out.pop().map(|m| m.payload), Some(vec![3]));
//! assert_eq!(out.pop().map(|m| m.payload), Some(vec![2]));
//! assert_eq!(out.replaced(), 1);
//! ```

use std::collections::{BTreeMap, HashMap, VecDeque};

/// Which lane a publish takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Lane {
    /// Commands, parameters, missions and their answers: QoS 1, in order, never replaced.
    Control,
    /// Everything else: QoS 0, latest-wins per key.
    Telemetry,
}

/// One publish.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Outgoing {
    /// Its lane.
    pub lane: Lane,
    /// The key latest-wins goes by (and the topic, unless `topic` says otherwise).
    pub key: String,
    /// The topic, when several keys share one (frames from many sources into one `in`).
    pub topic: Option<String>,
    /// The bytes.
    pub payload: Vec<u8>,
}

impl Outgoing {
    /// Where it is published.
    #[must_use]
    pub fn topic(&self) -> &str {
        self.topic.as_deref().unwrap_or(&self.key)
    }
}

/// The two lanes (see the module's documentation).
#[derive(Debug)]
pub struct Outbox {
    control: VecDeque<Outgoing>,
    /// Telemetry keys in the order they first waited, and the frame waiting on each.
    order: VecDeque<String>,
    waiting: HashMap<String, (Option<String>, Vec<u8>)>,
    control_cap: usize,
    telemetry_cap: usize,
    replaced: u64,
    replaced_by_key: BTreeMap<String, u64>,
    dropped_control: u64,
    dropped_telemetry: u64,
}

impl Outbox {
    /// Lanes of at most `control_cap` frames and `telemetry_cap` keys.
    #[must_use]
    pub fn new(control_cap: usize, telemetry_cap: usize) -> Self {
        Self {
            control: VecDeque::new(),
            order: VecDeque::new(),
            waiting: HashMap::new(),
            control_cap: control_cap.max(1),
            telemetry_cap: telemetry_cap.max(1),
            replaced: 0,
            replaced_by_key: BTreeMap::new(),
            dropped_control: 0,
            dropped_telemetry: 0,
        }
    }

    /// Queues a publish on `key` (published on `topic` when given). False when it was
    /// dropped (its lane is full; counted).
    pub fn push(
        &mut self,
        lane: Lane,
        key: String,
        topic: Option<String>,
        payload: Vec<u8>,
    ) -> bool {
        match lane {
            Lane::Control => {
                if self.control.len() >= self.control_cap {
                    self.dropped_control += 1;
                    return false;
                }
                self.control.push_back(Outgoing {
                    lane,
                    key,
                    topic,
                    payload,
                });
            }
            Lane::Telemetry => {
                if let Some(slot) = self.waiting.get_mut(&key) {
                    *slot = (topic, payload);
                    self.replaced += 1;
                    *self.replaced_by_key.entry(key).or_default() += 1;
                    return true;
                }
                if self.order.len() >= self.telemetry_cap {
                    self.dropped_telemetry += 1;
                    return false;
                }
                self.order.push_back(key.clone());
                self.waiting.insert(key, (topic, payload));
            }
        }
        true
    }

    /// The next publish: control first, then the oldest waiting telemetry key.
    pub fn pop(&mut self) -> Option<Outgoing> {
        if let Some(c) = self.control.pop_front() {
            return Some(c);
        }
        let key = self.order.pop_front()?;
        let (topic, payload) = self.waiting.remove(&key)?;
        Some(Outgoing {
            lane: Lane::Telemetry,
            key,
            topic,
            payload,
        })
    }

    /// Puts back a publish [`Outbox::pop`] gave that could not go; it goes next.
    pub fn unpop(&mut self, out: Outgoing) {
        match out.lane {
            Lane::Control => self.control.push_front(out),
            Lane::Telemetry => {
                if !self.waiting.contains_key(&out.key) {
                    self.order.push_front(out.key.clone());
                    self.waiting.insert(out.key, (out.topic, out.payload));
                }
            }
        }
    }

    /// Nothing waits.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.control.is_empty() && self.order.is_empty()
    }

    /// Telemetry frames replaced by a newer one on their key.
    #[must_use]
    pub const fn replaced(&self) -> u64 {
        self.replaced
    }

    /// The same per key.
    #[must_use]
    pub const fn replaced_by_key(&self) -> &BTreeMap<String, u64> {
        &self.replaced_by_key
    }

    /// Frames dropped because their lane was full: (control, telemetry).
    #[must_use]
    pub const fn dropped(&self) -> (u64, u64) {
        (self.dropped_control, self.dropped_telemetry)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_keeps_order_and_is_never_replaced() {
        let mut out = Outbox::new(3, 8);
        for i in 0..3 {
            assert!(out.push(Lane::Control, "k".into(), None, vec![i]));
        }
        assert!(!out.push(Lane::Control, "k".into(), None, vec![9]));
        assert_eq!(out.dropped(), (1, 0));
        let got: Vec<u8> = core::iter::from_fn(|| out.pop())
            .map(|o| o.payload[0])
            .collect();
        assert_eq!(got, [0, 1, 2]);
    }

    #[test]
    fn telemetry_keeps_the_newest_per_key_in_first_come_order() {
        let mut out = Outbox::new(4, 2);
        out.push(Lane::Telemetry, "a".into(), Some("in".into()), vec![1]);
        out.push(Lane::Telemetry, "b".into(), None, vec![2]);
        out.push(Lane::Telemetry, "a".into(), Some("in".into()), vec![3]);
        assert!(!out.push(Lane::Telemetry, "c".into(), None, vec![4]));
        let first = out.pop().unwrap();
        assert_eq!((first.topic(), first.payload[0]), ("in", 3));
        out.unpop(first);
        assert_eq!(out.pop().map(|o| o.payload), Some(vec![3]));
        assert_eq!(out.pop().map(|o| o.payload), Some(vec![2]));
        assert!(out.is_empty());
        assert_eq!(out.replaced_by_key().get("a"), Some(&1));
        assert_eq!(out.dropped(), (0, 1));
    }
}
