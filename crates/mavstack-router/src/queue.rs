//! A link's outgoing frames: two bounded queues, control traffic first.

use alloc::collections::VecDeque;

use mavstack_core::wire::MAX_FRAME_LEN;

#[derive(Clone)]
struct Slot {
    len: u16,
    buf: [u8; MAX_FRAME_LEN],
}

/// Frames waiting to be sent on one link: control traffic (commands, parameters, missions)
/// in a queue of its own that is always drained first, telemetry in another. Each is
/// bounded; a frame that does not fit is refused (the caller counts it).
#[derive(Clone, Default)]
pub(crate) struct OutQueue {
    control: VecDeque<Slot>,
    telemetry: VecDeque<Slot>,
}

/// Control frames that may wait per link, whatever the link's queue setting.
const CONTROL_CAPACITY: usize = 256;

impl OutQueue {
    /// Queues `bytes` (one frame, at most [`MAX_FRAME_LEN`]); false if its queue is full.
    pub(crate) fn push(&mut self, control: bool, bytes: &[u8], telemetry_capacity: usize) -> bool {
        let (queue, capacity) = if control {
            (&mut self.control, CONTROL_CAPACITY)
        } else {
            (&mut self.telemetry, telemetry_capacity)
        };
        if queue.len() >= capacity || bytes.len() > MAX_FRAME_LEN {
            return false;
        }
        let mut slot = Slot {
            len: 0,
            buf: [0; MAX_FRAME_LEN],
        };
        slot.buf[..bytes.len()].copy_from_slice(bytes);
        // At most MAX_FRAME_LEN (280): fits.
        slot.len = u16::try_from(bytes.len()).unwrap_or(0);
        queue.push_back(slot);
        true
    }

    /// Moves the next frame into `out` and returns its length.
    pub(crate) fn pop_into(&mut self, out: &mut [u8; MAX_FRAME_LEN]) -> Option<usize> {
        let slot = self
            .control
            .pop_front()
            .or_else(|| self.telemetry.pop_front())?;
        let len = usize::from(slot.len);
        out[..len].copy_from_slice(&slot.buf[..len]);
        Some(len)
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.control.is_empty() && self.telemetry.is_empty()
    }

    pub(crate) fn len(&self) -> usize {
        self.control.len() + self.telemetry.len()
    }
}

impl core::fmt::Debug for OutQueue {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("OutQueue")
            .field("control", &self.control.len())
            .field("telemetry", &self.telemetry.len())
            .finish()
    }
}
