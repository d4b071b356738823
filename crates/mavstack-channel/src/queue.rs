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

    /// Removes the oldest item.
    pub(crate) fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        let item = self.items[self.head].take();
        self.len -= 1;
        // An empty queue starts again at its first place: a state machine that holds one
        // item at a time keeps using the same (cached) memory.
        self.head = if self.len == 0 {
            0
        } else {
            (self.head + 1) % N
        };
        item
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
}
