//! A fixed-capacity FIFO with no heap: the event and transmit queues of the state machines.

/// A ring buffer of at most `N` items.
#[derive(Clone, Debug)]
pub(crate) struct Queue<T, const N: usize> {
    items: [Option<T>; N],
    head: usize,
    len: usize,
}

impl<T, const N: usize> Queue<T, N> {
    /// An empty queue.
    pub(crate) fn new() -> Self {
        Self {
            items: core::array::from_fn(|_| None),
            head: 0,
            len: 0,
        }
    }

    /// Appends `item`, or gives it back when the queue is full.
    pub(crate) fn push(&mut self, item: T) -> Result<(), T> {
        if self.len == N {
            return Err(item);
        }
        self.items[(self.head + self.len) % N] = Some(item);
        self.len += 1;
        Ok(())
    }

    /// Appends an item written in place by `fill`, which is given the place as it is: empty,
    /// or holding an item [`pop_slot`](Self::pop_slot) lent and left there, whose room `fill`
    /// may reuse. Whether an item was appended (not when full, nor when `fill` left the place
    /// empty).
    pub(crate) fn push_with(&mut self, fill: impl FnOnce(&mut Option<T>)) -> bool {
        if self.len == N {
            return false;
        }
        let slot = &mut self.items[(self.head + self.len) % N];
        fill(slot);
        if slot.is_none() {
            return false;
        }
        self.len += 1;
        true
    }

    /// The oldest item, left in the queue.
    pub(crate) fn peek(&self) -> Option<&T> {
        if self.len == 0 {
            return None;
        }
        self.items.get(self.head).and_then(Option::as_ref)
    }

    /// Removes the oldest item.
    pub(crate) fn pop(&mut self) -> Option<T> {
        self.pop_slot().and_then(Option::take)
    }

    /// Removes the oldest item from the queue and gives its place: the caller takes the item
    /// out, or reads it where it is (it stays there until the place is written again).
    pub(crate) fn pop_slot(&mut self) -> Option<&mut Option<T>> {
        if self.len == 0 {
            return None;
        }
        let at = self.head;
        self.len -= 1;
        // An empty queue starts again at its first place: a state machine that holds one
        // item at a time keeps using the same (cached) memory.
        self.head = if self.len == 0 { 0 } else { (at + 1) % N };
        self.items.get_mut(at)
    }

    /// Free places.
    pub(crate) const fn free(&self) -> usize {
        N - self.len
    }

    /// Items queued.
    pub(crate) const fn len(&self) -> usize {
        self.len
    }
}

#[cfg(test)]
mod tests {
    use super::Queue;

    #[test]
    fn fifo_order_wraps_and_refuses_when_full() {
        let mut q: Queue<u32, 3> = Queue::new();
        assert_eq!(q.pop(), None);
        for round in 0..5 {
            q.push(round).unwrap();
            q.push(round + 10).unwrap();
            assert_eq!(q.pop(), Some(round));
            q.push(round + 20).unwrap();
            q.push(round + 30).unwrap();
            assert_eq!(q.push(99), Err(99));
            assert_eq!((q.free(), q.len()), (0, 3));
            assert_eq!(q.pop(), Some(round + 10));
            assert_eq!(q.pop(), Some(round + 20));
            assert_eq!(q.pop(), Some(round + 30));
            assert_eq!(q.pop(), None);
        }
    }

    #[test]
    fn an_item_lent_in_place_stays_until_its_place_is_written_again() {
        let mut q: Queue<[u8; 4], 2> = Queue::new();
        assert!(q.push_with(|slot| *slot = Some([1; 4])));
        assert!(!q.push_with(|_| {}), "a place left empty appends nothing");
        assert_eq!(q.len(), 1);
        assert_eq!(q.peek(), Some(&[1; 4]));
        assert_eq!(q.len(), 1, "peeking leaves it");
        assert_eq!(q.pop_slot().map(|s| *s), Some(Some([1; 4])));
        assert_eq!(q.peek(), None);
        assert_eq!(q.len(), 0);
        // The queue starts again at its first place, where the lent item still is.
        assert!(q.push_with(|slot| {
            assert_eq!(*slot, Some([1; 4]), "the room of the item lent");
            if let Some(item) = slot {
                item[0] = 2;
            }
        }));
        assert!(q.push_with(|slot| *slot = Some([3; 4])));
        assert!(!q.push_with(|slot| *slot = Some([4; 4])), "full");
        assert_eq!(q.pop(), Some([2, 1, 1, 1]));
        assert_eq!(q.pop(), Some([3; 4]));
        assert_eq!(q.pop(), None);
        assert!(q.pop_slot().is_none());
    }
}
