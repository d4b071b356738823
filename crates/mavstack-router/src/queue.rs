//! A link's outgoing frames: two bounded queues, control traffic first.

use alloc::vec::Vec;

use mavstack_core::wire::MAX_FRAME_LEN;

#[derive(Clone)]
struct Slot {
    len: u16,
    buf: [u8; MAX_FRAME_LEN],
}

/// A FIFO of frames in slots that are written in place and grow up to the largest backlog
/// seen. An empty ring starts again at its first slot, so that a link that sends a frame at
/// a time uses the same (cached) memory for every frame.
#[derive(Clone, Default)]
struct Ring {
    slots: Vec<Slot>,
    head: usize,
    len: usize,
}

impl Ring {
    fn push(&mut self, bytes: &[u8], capacity: usize) -> bool {
        let Ok(len) = u16::try_from(bytes.len()) else {
            return false;
        };
        if self.len >= capacity || bytes.len() > MAX_FRAME_LEN {
            return false;
        }
        if self.len == 0 {
            self.head = 0;
        }
        if self.len == self.slots.len() {
            // Full storage: the oldest frame first again, then one more slot at the end.
            self.slots.rotate_left(self.head);
            self.head = 0;
            self.slots.push(Slot {
                len: 0,
                buf: [0; MAX_FRAME_LEN],
            });
        }
        let at = (self.head + self.len) % self.slots.len();
        let slot = &mut self.slots[at];
        slot.buf[..bytes.len()].copy_from_slice(bytes);
        slot.len = len;
        self.len += 1;
        true
    }

    fn pop_into(&mut self, out: &mut [u8; MAX_FRAME_LEN]) -> Option<usize> {
        if self.len == 0 {
            return None;
        }
        let slot = &self.slots[self.head];
        let len = usize::from(slot.len);
        out[..len].copy_from_slice(&slot.buf[..len]);
        self.head = (self.head + 1) % self.slots.len();
        self.len -= 1;
        Some(len)
    }
}

/// Frames waiting to be sent on one link: control traffic (commands, parameters, missions)
/// in a queue of its own that is always drained first, telemetry in another. Each is
/// bounded; a frame that does not fit is refused (the caller counts it).
#[derive(Clone, Default)]
pub(crate) struct OutQueue {
    control: Ring,
    telemetry: Ring,
}

/// Control frames that may wait per link, whatever the link's queue setting.
const CONTROL_CAPACITY: usize = 256;

impl OutQueue {
    /// Queues `bytes` (one frame, at most [`MAX_FRAME_LEN`]); false if its queue is full.
    pub(crate) fn push(&mut self, control: bool, bytes: &[u8], telemetry_capacity: usize) -> bool {
        if control {
            self.control.push(bytes, CONTROL_CAPACITY)
        } else {
            self.telemetry.push(bytes, telemetry_capacity)
        }
    }

    /// Moves the next frame into `out` and returns its length.
    pub(crate) fn pop_into(&mut self, out: &mut [u8; MAX_FRAME_LEN]) -> Option<usize> {
        self.control
            .pop_into(out)
            .or_else(|| self.telemetry.pop_into(out))
    }

    pub(crate) const fn is_empty(&self) -> bool {
        self.control.len == 0 && self.telemetry.len == 0
    }

    pub(crate) const fn len(&self) -> usize {
        self.control.len + self.telemetry.len
    }
}

impl core::fmt::Debug for OutQueue {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("OutQueue")
            .field("control", &self.control.len)
            .field("telemetry", &self.telemetry.len)
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::{CONTROL_CAPACITY, OutQueue};

    fn pop(q: &mut OutQueue) -> Option<alloc::vec::Vec<u8>> {
        let mut buf = [0u8; mavstack_core::wire::MAX_FRAME_LEN];
        q.pop_into(&mut buf).map(|n| buf[..n].to_vec())
    }

    #[test]
    fn control_first_fifo_each_through_growth_and_wrap() {
        let mut q = OutQueue::default();
        for round in 0..4u8 {
            // Interleave pushes and pops so that the rings wrap before they grow.
            assert!(q.push(false, &[round, 1], 5));
            assert!(q.push(false, &[round, 2, 2], 5));
            assert_eq!(pop(&mut q), Some(alloc::vec![round, 1]));
            assert!(q.push(true, &[round, 9], 5));
            assert!(q.push(false, &[round, 3], 5));
            assert!(q.push(false, &[round, 4], 5));
            assert!(q.push(false, &[round, 5], 5));
            assert!(q.push(false, &[round, 6], 5));
            assert!(!q.push(false, &[round, 7], 5), "telemetry bounded at 5");
            assert_eq!(q.len(), 6);
            assert_eq!(pop(&mut q), Some(alloc::vec![round, 9]));
            for i in 2..=6u8 {
                let want = if i == 2 {
                    alloc::vec![round, 2, 2]
                } else {
                    alloc::vec![round, i]
                };
                assert_eq!(pop(&mut q), Some(want));
            }
            assert!(q.is_empty());
            assert_eq!(pop(&mut q), None);
        }
        for i in 0..CONTROL_CAPACITY {
            assert!(q.push(true, &[u8::try_from(i % 256).unwrap_or(0)], 0));
        }
        assert!(!q.push(true, &[0], 0), "control bounded");
        assert!(!q.push(false, &[0], 0), "a telemetry capacity of 0 refuses");
        assert!(
            !OutQueue::default().push(true, &[0; 281], 0),
            "longer than a frame"
        );
    }
}
