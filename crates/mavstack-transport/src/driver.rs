//! The driver: one task owns one link and one protocol, and is thin.
//!
//! It loops: wait for whichever comes first of link input, a user command, the protocol's
//! deadline, link housekeeping, or room in the event channel; hand it to the protocol; then
//! drain `poll_transmit` into the link and `poll_event` into the event channel. When the
//! event channel is full it stops reading the link (back-pressure: a file is read no faster
//! than the user takes its frames; a UDP socket's kernel buffer absorbs bursts) but still
//! takes commands and handles timeouts.

use std::sync::{Arc, Mutex, PoisonError};

use tokio::sync::mpsc;

use crate::clock;
use crate::error::LinkError;
use crate::link::{Link, LinkStats, MAX_DATAGRAM, sleep_until};
use crate::protocol::Protocol;

/// Commands handled per wake-up before the driver looks at its other work.
const COMMAND_BATCH: usize = 256;

/// What the driver publishes for the user's handle after every step.
#[derive(Debug, Default)]
pub(crate) struct Published<S> {
    pub(crate) link: LinkStats,
    pub(crate) protocol: S,
}

pub(crate) type Shared<S> = Arc<Mutex<Published<S>>>;

enum Step<C> {
    Input,
    Command(C),
    Stop,
    Timeout,
    Housekeeping,
    Forwarded,
    UserGone,
}

/// Runs `proto` over `link` until the user closes the connection or the link ends.
pub(crate) async fn run<P: Protocol>(
    mut link: Link,
    mut proto: P,
    mut commands: mpsc::Receiver<P::Command>,
    events: mpsc::Sender<P::Event>,
    shared: Shared<P::Stats>,
) -> Result<(), LinkError> {
    let mut tx_buf = vec![0u8; MAX_DATAGRAM];
    let mut pending: Option<P::Event> = None;
    link.start(&mut proto);
    loop {
        flush_transmits(&mut link, &mut proto, &mut tx_buf).await;
        if forward(&mut proto, &events, &mut pending).is_err() {
            break;
        }
        publish(&shared, &link, &proto);
        if link.finished().is_some() && pending.is_none() {
            break;
        }
        let timeout = proto.poll_timeout().map(clock::to_tokio);
        let housekeeping = link.next_housekeeping().map(clock::to_tokio);
        let reading = pending.is_none() && link.finished().is_none();
        let step = tokio::select! {
            () = link.wait(), if reading => Step::Input,
            cmd = commands.recv() => cmd.map_or(Step::Stop, Step::Command),
            permit = events.reserve(), if pending.is_some() => match (permit, pending.take()) {
                (Ok(permit), Some(event)) => {
                    permit.send(event);
                    Step::Forwarded
                }
                (Ok(_), None) => Step::Forwarded,
                (Err(_), _) => Step::UserGone,
            },
            () = sleep_until(timeout), if timeout.is_some() => Step::Timeout,
            () = sleep_until(housekeeping), if housekeeping.is_some() => Step::Housekeeping,
        };
        match step {
            Step::Input => {
                link.dispatch(&mut proto);
            }
            Step::Command(cmd) => {
                proto.handle_command(clock::now(), cmd);
                for _ in 1..COMMAND_BATCH {
                    match commands.try_recv() {
                        Ok(cmd) => proto.handle_command(clock::now(), cmd),
                        Err(_) => break,
                    }
                }
            }
            Step::Stop | Step::UserGone => break,
            Step::Timeout => proto.handle_timeout(clock::now()),
            Step::Housekeeping => link.housekeeping(&mut proto),
            Step::Forwarded => {}
        }
    }
    // Commands already sent are handled, and whatever the protocol has to send goes out,
    // before the link closes.
    while let Ok(cmd) = commands.try_recv() {
        proto.handle_command(clock::now(), cmd);
    }
    flush_transmits(&mut link, &mut proto, &mut tx_buf).await;
    let closed = link.shutdown().await;
    publish(&shared, &link, &proto);
    link.take_result().and(closed)
}

async fn flush_transmits<P: Protocol>(link: &mut Link, proto: &mut P, buf: &mut [u8]) {
    while let Some(t) = proto.poll_transmit(clock::now(), buf) {
        let len = t.len.min(buf.len());
        link.transmit(t.dest, &buf[..len]).await;
    }
}

/// Moves events from the protocol into the channel until either runs dry; an event that does
/// not fit waits in `pending`. `Err` when the user's handle is gone.
fn forward<P: Protocol>(
    proto: &mut P,
    events: &mpsc::Sender<P::Event>,
    pending: &mut Option<P::Event>,
) -> Result<(), ()> {
    loop {
        let Some(event) = pending.take().or_else(|| proto.poll_event()) else {
            return Ok(());
        };
        match events.try_send(event) {
            Ok(()) => {}
            Err(mpsc::error::TrySendError::Full(event)) => {
                *pending = Some(event);
                return Ok(());
            }
            Err(mpsc::error::TrySendError::Closed(_)) => return Err(()),
        }
    }
}

fn publish<P: Protocol>(shared: &Shared<P::Stats>, link: &Link, proto: &P) {
    let mut published = shared.lock().unwrap_or_else(PoisonError::into_inner);
    published.link = link.stats();
    published.protocol = proto.stats();
}
