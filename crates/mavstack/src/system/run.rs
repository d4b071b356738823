//! Driving one `mavstack-services` state machine over the link to a system until it gives
//! a result: what every operation of every handle runs.

use core::time::Duration;

use mavstack_core::MessageSet as _;
use mavstack_dialects::common::MavMessage;
use mavstack_services::{Address, Service};
use mavstack_transport::clock;

use super::{Inner, SystemError};
use crate::node::Subscription;

/// Drives `service` over the system's link until `done` returns a result, or fails after
/// `limit`. `frames` must have been subscribed before the service's first request went out
/// (so that no answer is missed); only frames of the target system reach the service.
pub(super) async fn drive<S: Service, R>(
    inner: &Inner,
    frames: &mut Subscription,
    service: &mut S,
    limit: Duration,
    done: impl FnMut(&mut S) -> Option<R>,
) -> Result<R, SystemError> {
    drive_with(inner, frames, service, limit, done, |_, _, _, _| {}).await
}

/// [`drive`], with `other` given the frames of the target system that the common dialect
/// cannot decode (an autopilot's own messages): the service, the sender, the message id and
/// the payload.
pub(super) async fn drive_with<S: Service, R>(
    inner: &Inner,
    frames: &mut Subscription,
    service: &mut S,
    limit: Duration,
    mut done: impl FnMut(&mut S) -> Option<R>,
    mut other: impl FnMut(&mut S, Address, u32, &[u8]),
) -> Result<R, SystemError> {
    let deadline = tokio::time::Instant::now() + limit;
    loop {
        flush(inner, service).await?;
        if let Some(result) = done(service) {
            return Ok(result);
        }
        let now = tokio::time::Instant::now();
        if now >= deadline {
            return Err(SystemError::Timeout {
                seconds: limit.as_secs_f64(),
            });
        }
        let wake = service
            .poll_timeout()
            .map_or(deadline, |t| clock::to_tokio(t).min(deadline));
        tokio::select! {
            () = tokio::time::sleep_until(wake) => service.handle_timeout(clock::now()),
            incoming = frames.recv() => {
                let incoming = incoming.ok_or(SystemError::Stopped)?;
                let f = incoming.frame.frame.view();
                if f.sysid() != inner.target.system {
                    continue;
                }
                let from = Address::new(f.sysid(), f.compid());
                match MavMessage::decode(f.msg_id(), f.payload()) {
                    Ok(msg) => {
                        service.handle_message(clock::now(), from, &msg);
                    }
                    Err(_) => other(service, from, f.msg_id(), f.payload()),
                }
            }
        }
    }
}

/// Sends what `service` has to send.
pub(super) async fn flush<S: Service>(inner: &Inner, service: &mut S) -> Result<(), SystemError> {
    while let Some(out) = service.poll_transmit() {
        if inner.node.send_on(inner.link(), &out.message).await == 0
            && inner.node.report().await.is_none()
        {
            return Err(SystemError::Stopped);
        }
    }
    Ok(())
}
