//! Input moderation: reading in bursts under a steady stream of input.

use core::time::Duration;

use mavstack_core::time::Instant;

/// How a node reads under a steady stream of input (see [`NodeBuilder::input_moderation`](crate::NodeBuilder::input_moderation)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum InputModeration {
    /// Every datagram is read as it comes.
    Off,
    /// Woken by a datagram, the node waits a millisecond on a tokio timer for the next ones,
    /// then reads and forwards them all at once. Friendly to other tasks on the runtime; the
    /// thread still wakes for each datagram's readiness during the wait.
    #[default]
    Timer,
    /// After reading a burst, the node's thread sleeps a millisecond (blocking it: no
    /// wake-ups at all while datagrams pile up in the socket buffer), then reads them all.
    /// For a node on a runtime of its own (the `mavstack router` daemon): other tasks on that
    /// thread wait for the millisecond too.
    Sleep,
}

/// Input moderation, as network cards do it: under a steady stream of input (more than
/// [`Moderation::BUSY_ABOVE`] datagrams a second) the node reads in bursts, one wake-up for
/// many frames instead of one each, at the price of at most [`Moderation::PAUSE`] of added
/// latency while the stream lasts. Below [`Moderation::CALM_BELOW`] a second it reads each
/// datagram as it comes.
///
/// The same measure says when the input is sparse (under [`Moderation::SPARSE_BELOW`] a
/// second, until it passes [`Moderation::DENSE_ABOVE`]): then a batch reader may wait beside
/// the node's thread, spending a little processor time per datagram for a faster hand-over
/// (see `batch`).
#[derive(Debug)]
pub(super) struct Moderation {
    pub(super) mode: InputModeration,
    /// Since when `inputs` counts.
    pub(super) since: Instant,
    pub(super) inputs: u64,
    pub(super) busy: bool,
    pub(super) sparse: bool,
}

impl Moderation {
    /// Inputs per second from which the node moderates.
    pub(super) const BUSY_ABOVE: u64 = 5_000;
    /// Inputs per second under which it stops.
    pub(super) const CALM_BELOW: u64 = 2_500;
    /// Inputs per second under which the input is sparse.
    pub(super) const SPARSE_BELOW: u64 = 300;
    /// Inputs per second from which it is no longer.
    pub(super) const DENSE_ABOVE: u64 = 600;
    /// How often the rate is measured (a stream that stops is seen within this).
    pub(super) const MEASURE: Duration = Duration::from_millis(10);
    /// The wait (tokio's timers tick in milliseconds).
    pub(super) const PAUSE: Duration = Duration::from_millis(1);
    /// Inputs in one turn from which the node reads on without sleeping (the stream brings
    /// more than this in a pause).
    pub(super) const BIG_BURST: u64 = 128;

    pub(super) const fn new(mode: InputModeration, now: Instant) -> Self {
        Self {
            mode,
            since: now,
            inputs: 0,
            busy: false,
            sparse: true,
        }
    }

    /// After a turn: whether [`InputModeration::Sleep`] sleeps through the next
    /// [`Moderation::PAUSE`] (busy, something was done, and the turn's burst was small
    /// enough for a pause to gather more; a burst of [`Moderation::BIG_BURST`] means the
    /// stream outruns the pause: read on).
    pub(super) fn pause_after(&self, busy: bool, worked: bool, inputs_before: u64) -> bool {
        let burst = self.inputs.saturating_sub(inputs_before);
        busy && worked && burst < Self::BIG_BURST && self.mode == InputModeration::Sleep
    }

    /// Updates the rate; whether the stream is steady enough to read in bursts.
    pub(super) fn busy(&mut self, now: Instant) -> bool {
        let elapsed = now.saturating_duration_since(self.since);
        if elapsed >= Self::MEASURE {
            let per_s = self.inputs.saturating_mul(1_000_000) / (elapsed.as_micros().max(1) as u64);
            self.busy = if self.busy {
                per_s >= Self::CALM_BELOW
            } else {
                per_s > Self::BUSY_ABOVE
            };
            self.sparse = if self.sparse {
                per_s <= Self::DENSE_ABOVE
            } else {
                per_s < Self::SPARSE_BELOW
            };
            self.since = now;
            self.inputs = 0;
        }
        self.mode != InputModeration::Off && self.busy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_input_is_sparse_below_300_a_second_until_it_passes_600() {
        let t0 = Instant::from_secs(1);
        let ms = Duration::from_millis;
        let mut m = Moderation::new(InputModeration::Timer, t0);
        assert!(m.sparse, "nothing yet");
        m.inputs = 5; // 500/s: still, by hysteresis
        m.busy(t0 + ms(10));
        assert!(m.sparse);
        m.inputs = 7; // 700/s
        m.busy(t0 + ms(20));
        assert!(!m.sparse);
        m.inputs = 4; // 400/s: not yet
        m.busy(t0 + ms(30));
        assert!(!m.sparse);
        m.inputs = 2; // 200/s
        m.busy(t0 + ms(40));
        assert!(m.sparse);
    }

    #[test]
    pub(super) fn moderation_starts_above_5000_inputs_a_second_and_stops_below_2500() {
        let t0 = Instant::from_secs(1);
        let ms = Duration::from_millis;
        let mut m = Moderation::new(InputModeration::Timer, t0);
        m.inputs = 40; // 4,000/s: not yet
        assert!(!m.busy(t0 + ms(10)));
        m.inputs = 60; // 6,000/s
        assert!(m.busy(t0 + ms(20)));
        m.inputs = 30; // 3,000/s: still, by hysteresis
        assert!(m.busy(t0 + ms(30)));
        m.inputs = 20; // 2,000/s
        assert!(!m.busy(t0 + ms(40)));
        // A stream that stopped is seen as soon as the next input comes.
        m.inputs = 60;
        assert!(m.busy(t0 + ms(50)));
        m.inputs = 1;
        assert!(!m.busy(t0 + ms(1050)));
        assert!(m.sparse, "one input in a second");
        let mut off = Moderation::new(InputModeration::Off, t0);
        off.inputs = 1_000;
        assert!(!off.busy(t0 + ms(10)));
    }
}
