//! `mavstack radio`: a semi-transparent radio forwarding frames between a ground station (A)
//! and a vehicle (B) and injecting RADIO_STATUS, MAVLink 1 until it has seen MAVLink 2.

use core::time::Duration;

use clap::Args;
use mavstack_channel::{Radio, RadioConfig, Side};
use mavstack_core::wire::MAX_FRAME_LEN;
use mavstack_dialects::common::MavMessage;
use mavstack_transport::{
    ConnSpec, Connection, FrameBuf, FrameCommand, FrameEvent, FrameProtocol, clock,
};

use crate::link_cmd::{interrupted, parse_spec, runtime, seconds};
use crate::vehicle_cmd::{Log, say, stderr_log, version_name};
use crate::{Failure, other};

#[derive(Debug, Args)]
pub(crate) struct RadioArgs {
    /// The ground station's side.
    conn_a: String,
    /// The vehicle's side.
    conn_b: String,
    /// Seconds between RADIO_STATUS frames.
    #[arg(long, default_value_t = 1.0)]
    interval: f64,
    /// Print the radio's events to stderr.
    #[arg(long, short)]
    verbose: bool,
}

/// A radio side: frames of any id, forwarded as they are.
pub(crate) type RadioLink = Connection<FrameProtocol<fn(u32) -> Option<u8>>>;

pub(crate) async fn open_radio_side(spec: &ConnSpec) -> Result<RadioLink, Failure> {
    let lookup: fn(u32) -> Option<u8> = mavstack_transport::frame::crc_extra_of::<MavMessage>;
    Connection::open(
        spec,
        FrameProtocol::new(lookup)
            .keep_unknown(true)
            .peer_events(false),
    )
    .await
    .map_err(other)
}

/// Runs a semi-transparent radio between `side_a` (ground) and `side_b` (vehicle) until
/// `stop`.
pub(crate) async fn run_radio(
    mut side_a: RadioLink,
    mut side_b: RadioLink,
    interval: Duration,
    log: Log,
    stop: impl Future<Output = ()>,
) -> Result<(), Failure> {
    let mut config = RadioConfig::default();
    config.interval = interval;
    let mut radio = Radio::new(config);
    tokio::pin!(stop);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut last_injected = None;
    loop {
        let wake = radio
            .poll_timeout()
            .map(|t| t.as_micros().saturating_sub(clock::now().as_micros()))
            .map_or(Duration::from_secs(1), Duration::from_micros);
        let (side, event) = tokio::select! {
            () = &mut stop => break,
            () = tokio::time::sleep(wake) => {
                radio.handle_timeout(clock::now());
                (None, None)
            }
            e = side_a.recv() => (Some(Side::A), e),
            e = side_b.recv() => (Some(Side::B), e),
        };
        if let Some(side) = side {
            let Some(event) = event else { break };
            if let FrameEvent::Frame(f) | FrameEvent::Unknown(f) = event {
                let mut rest = f.frame.as_bytes();
                while !rest.is_empty() {
                    let taken = radio.handle_input(clock::now(), side, rest);
                    rest = &rest[taken..];
                    if taken == 0 {
                        break;
                    }
                }
            }
        }
        while let Some(mavstack_channel::RadioEvent::FirstMavlink2 { from }) = radio.poll_event() {
            say(&log, || {
                format!(
                    "radio: first MAVLink 2 frame (from side {from:?}); RADIO_STATUS in MAVLink 2 from now on"
                )
            });
        }
        while let Some(t) = radio.poll_transmit(clock::now(), &mut buf) {
            let Ok(frame) = FrameBuf::new(&buf[..t.len]) else {
                continue;
            };
            if t.injected && last_injected != Some(t.version) {
                last_injected = Some(t.version);
                say(&log, || {
                    format!(
                        "radio → RADIO_STATUS ({}), every {interval:?}",
                        version_name(t.version)
                    )
                });
            }
            let conn = if t.to == Side::A { &side_a } else { &side_b };
            conn.send(FrameCommand::to_all(frame))
                .await
                .map_err(other)?;
        }
    }
    side_a.close().await.map_err(other)?;
    side_b.close().await.map_err(other)?;
    Ok(())
}

pub(crate) fn radio(args: &RadioArgs) -> Result<(), Failure> {
    let a = parse_spec(&args.conn_a)?;
    let b = parse_spec(&args.conn_b)?;
    let interval = seconds(args.interval, "--interval")?;
    runtime()?.block_on(async {
        let log = stderr_log(args.verbose);
        let side_a = open_radio_side(&a).await?;
        let side_b = open_radio_side(&b).await?;
        run_radio(side_a, side_b, interval, log, interrupted()).await
    })
}
