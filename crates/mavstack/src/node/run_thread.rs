//! The driver on a thread of its own (`NodeBuilder::own_thread`): its UDP sockets on that
//! thread's level-triggered `epoll`.

use mavstack_transport::clock;

use super::driver::{Driver, Turn};
use super::moderation::{InputModeration, Moderation};
use super::{NodeError, NodeReport};

impl Driver {
    /// The node on a thread of its own (see [`NodeBuilder::own_thread`]): its UDP sockets
    /// move to an `epoll` this thread waits on; the other links' tasks, the handles' commands
    /// and the subscribers stay on `runtime`, and wake the poll through its waker.
    #[cfg(target_os = "linux")]
    pub(super) fn run_on_thread(
        mut self,
        runtime: &tokio::runtime::Handle,
    ) -> Result<NodeReport, NodeError> {
        let result = self.run_polled();
        runtime.block_on(self.finish(result))
    }

    #[cfg(target_os = "linux")]
    pub(super) fn run_polled(&mut self) -> Result<(), NodeError> {
        let polling = |source: std::io::Error| NodeError::Poll { source };
        let mut waiter = crate::own_thread::Waiter::new().map_err(polling)?;
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if let Some(fd) = slot.io.watch_externally().map_err(polling)? {
                waiter.watch(fd, i).map_err(polling)?;
                slot.polled = true;
            }
        }
        self.reader_poll = Some(waiter.beside().map_err(polling)?);
        let waker = waiter.waker().clone();
        let mut cx = core::task::Context::from_waker(&waker);
        self.start_links();
        let mut ready = vec![false; self.slots.len()];
        let mut bulk = false;
        // Poll the runtime's side (commands, helper-task links) on the next look: at the
        // start, after the waker was woken, and after that side had something (it may have
        // more, and a poll that found something registered no waker).
        let mut runtime = true;
        loop {
            // Batch readers may wait beside this thread while its input is sparse.
            waiter.set_sparse(self.moderation.sparse);
            let mut command = None;
            let mut waited = false;
            // Waiting changes none of the node's deadlines: worked out once per turn.
            let mut deadline = None;
            let (timer, now) = loop {
                let polled = core::mem::take(&mut runtime) | waiter.take_woken();
                let (any, from_runtime) =
                    self.poll_inputs(&mut cx, &mut ready, &mut command, polled);
                runtime = from_runtime;
                let deadline = *deadline.get_or_insert_with(|| self.next_deadline());
                let slots = &mut self.slots;
                let mut mark = |i: usize| {
                    if let Some(slot) = slots.get_mut(i) {
                        slot.io.set_readable();
                    }
                };
                if !any && deadline == waiter.armed() {
                    // Nothing to do, and the timer is set for the deadline (it wakes the
                    // poll once due): wait without reading the clock.
                    waited = true;
                    waiter.wait_armed(mark).map_err(polling)?;
                    continue;
                }
                let now = clock::now();
                let due = deadline.is_some_and(|d| now >= d);
                if any || due {
                    if !waited {
                        // Input left from the last turn: the other sockets' readiness is
                        // looked at too, so that a link that always has more cannot starve
                        // them (one `epoll_wait` more per turn, only while input is left).
                        waiter.look(&mut mark).map_err(polling)?;
                        let polled = core::mem::take(&mut runtime) | waiter.take_woken();
                        let (_, from_runtime) =
                            self.poll_inputs(&mut cx, &mut ready, &mut command, polled);
                        runtime = from_runtime;
                    }
                    break (due, now);
                }
                waited = true;
                waiter.wait(deadline, now, mark).map_err(polling)?;
            };
            let input = ready.iter().any(|&r| r);
            let busy = input && self.moderation.busy(now);
            // Under a steady stream the sockets are read in batches (one datagram per read
            // otherwise: the cheapest read, and the frame goes on at once).
            if self.moderation.busy != bulk {
                bulk = self.moderation.busy;
                for slot in &mut self.slots {
                    slot.io.set_bulk_reads(bulk);
                }
            }
            let inputs_before = self.moderation.inputs;
            // Under a steady stream the thread reads in bursts: nothing else runs on it, so
            // both kinds of moderation sleep it (no wake-ups while datagrams pile up).
            let now = if busy && waited && self.moderation.mode == InputModeration::Timer {
                std::thread::sleep(Moderation::PAUSE);
                clock::now()
            } else {
                now
            };
            let Turn::Go { worked } = self.turn(now, &mut ready, command, timer)? else {
                return Ok(());
            };
            if self.moderation.pause_after(busy, worked, inputs_before) {
                std::thread::sleep(Moderation::PAUSE);
            }
            if let Some(e) = self.failed() {
                return Err(e);
            }
        }
    }
}
