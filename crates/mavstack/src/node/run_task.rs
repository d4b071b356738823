//! The driver as a task of the runtime: the runtime's reactor watches the sockets.

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_transport::clock;

use super::driver::{Driver, Turn};
use super::moderation::{InputModeration, Moderation};
use super::{NodeError, NodeReport};

impl Driver {
    /// The node as a task of the runtime: the runtime's reactor watches the sockets.
    pub(super) async fn run(mut self) -> Result<NodeReport, NodeError> {
        self.start_links();
        let mut ready = vec![false; self.slots.len()];
        let sleep = tokio::time::sleep(Duration::from_secs(3600));
        tokio::pin!(sleep);
        let mut armed: Option<Instant> = None;
        let mut timer_fired = false;
        let result = loop {
            let deadline = self.next_deadline();
            // Re-arming the timer costs a trip through the runtime's timer wheel: only when the
            // deadline moved (or after it fired).
            if let Some(d) = deadline
                && (armed != Some(d) || timer_fired)
            {
                sleep.as_mut().reset(clock::to_tokio(d));
                armed = Some(d);
            }
            let mut command = None;
            let mut timer = false;
            let mut waited = false;
            core::future::poll_fn(|cx| {
                let (mut any, _) = self.poll_inputs(cx, &mut ready, &mut command, true);
                if deadline.is_some() && sleep.as_mut().poll(cx).is_ready() {
                    timer = true;
                    any = true;
                }
                if any {
                    core::task::Poll::Ready(())
                } else {
                    waited = true;
                    core::task::Poll::Pending
                }
            })
            .await;
            // Woken from idle under a steady stream: let the next datagrams arrive first.
            let mut now = clock::now();
            let input = ready.iter().any(|&r| r);
            let busy = input && self.moderation.busy(now);
            let inputs_before = self.moderation.inputs;
            if busy && waited && self.moderation.mode == InputModeration::Timer {
                tokio::time::sleep(Moderation::PAUSE).await;
                now = clock::now();
            }
            timer_fired = timer;
            let worked = match self.turn(now, &mut ready, command, timer) {
                Ok(Turn::Go { worked }) => worked,
                Ok(Turn::Stop) => break Ok(()),
                Err(e) => break Err(e),
            };
            if self.moderation.pause_after(busy, worked, inputs_before) {
                // Sleep through the next millisecond of the stream, then let the runtime
                // look at the sockets (the yield below) and read it all in one turn.
                std::thread::sleep(Moderation::PAUSE);
                tokio::task::yield_now().await;
            } else if !waited && worked {
                // Busy (a link always has input): let the runtime poll its I/O driver, so
                // the other sockets' readiness is seen, and run its other tasks (signals,
                // statistics). One flooding link cannot starve the rest. (A turn that found
                // nothing, a drained socket's last look, goes straight back to waiting.)
                tokio::task::yield_now().await;
            }
            if let Some(e) = self.failed() {
                break Err(e);
            }
        };
        self.finish(result).await
    }
}
