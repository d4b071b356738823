//! `listen --rate NAME:HZ`: listening while asking the first autopilot heard for telemetry
//! rates. Asking means speaking, so the link is a ground station's `mavstack::Node` (our
//! HEARTBEAT every second) that hands every frame it accepts to the printer, and the rates
//! are asked with `System::telemetry().request_rate` — SET_MESSAGE_INTERVAL, the
//! REQUEST_DATA_STREAM fallback, and asking again after the vehicle restarts are the
//! library's.

use mavstack::core::signing::SecretKey;
use mavstack::router::{LocalDelivery, RouterConfig};
use mavstack::system::{System, Wanted};
use mavstack::{LinkSpec, Node};
use mavstack_transport::ConnSpec;
use mavstack_xml::Dialect;
use tokio::time::Instant;

use crate::link_cmd::{ListenArgs, Printer, interrupted, runtime};
use crate::{Failure, fail};

/// How long the search for the autopilot to ask goes on (for the whole listen, in effect).
const FIND_FOREVER: core::time::Duration = core::time::Duration::from_secs(86_400 * 365);

pub(crate) fn listen(
    args: &ListenArgs,
    dialect: &Dialect,
    spec: LinkSpec,
    key: Option<SecretKey>,
    rates: &[(u32, f32)],
    until: Option<Instant>,
) -> Result<(), Failure> {
    if matches!(spec.conn, ConnSpec::File { .. }) {
        return Err(Failure::Input(anyhow::anyhow!(
            "--rate: a file cannot be asked for rates"
        )));
    }
    runtime()?.block_on(async {
        let mut router = RouterConfig::default();
        router.local = LocalDelivery::All;
        router.forward = false;
        let node = Node::ground_station(255, 190)
            .router(router)
            .dialect(dialect.message_table())
            .link(spec)
            .start()
            .await
            .map_err(fail)?;
        let handle = node.handle();
        let mut frames = handle.subscribe().await;
        let wanted = rates.to_vec();
        let asker = tokio::spawn(async move {
            let Ok(system) = System::wait(&handle, Wanted::AnyAutopilot, FIND_FOREVER).await else {
                return;
            };
            for (id, hz) in wanted {
                match system.telemetry().request_rate(id, hz).await {
                    Ok(r) if r.arrived => {
                        tracing::info!("{} at {hz} Hz ({:?})", mavstack::message_name(id), r.how);
                    }
                    Ok(_) => tracing::warn!(
                        "{} asked for at {hz} Hz: it does not come",
                        mavstack::message_name(id)
                    ),
                    Err(e) => tracing::warn!("asking for rates: {e}"),
                }
            }
            // The system's handle keeps asking again after a restart for as long as it lives.
            core::future::pending::<()>().await;
        });
        let mut printer = Printer::new(args, dialect, key)?;
        let mut redraw = tokio::time::interval(core::time::Duration::from_secs(1));
        let stop = interrupted();
        tokio::pin!(stop);
        let until = async {
            match until {
                Some(at) => tokio::time::sleep_until(at).await,
                None => core::future::pending().await,
            }
        };
        tokio::pin!(until);
        loop {
            tokio::select! {
                incoming = frames.recv() => {
                    let Some(incoming) = incoming else { break };
                    let received = &incoming.frame;
                    if !args.keep_unknown && !received.crc_checked {
                        continue;
                    }
                    let frame = received.frame.view();
                    if printer.frame(&frame, received.crc_checked, None)? {
                        break;
                    }
                    if frames.is_empty() {
                        printer.flush(false)?;
                    }
                }
                _ = redraw.tick() => printer.flush(true)?,
                () = &mut stop => break,
                () = &mut until => break,
            }
        }
        printer.finish()?;
        asker.abort();
        node.shutdown().await.map_err(fail)?;
        Ok(())
    })
}
