//! Sends a HEARTBEAT once a second, as a ground station would: `heartbeat CONN`.
//!
//! ```text
//! cargo run -p mavstack-transport --example heartbeat -- udpout:127.0.0.1:14550
//! cargo run -p mavstack-transport --example heartbeat -- tcp:127.0.0.1:5760
//! ```
//!
//! Frames from the other side are counted, and what the vehicle is (from its heartbeats)
//! is printed.

use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::wire::{FrameHeader, Version};
use mavstack_dialects::ardupilotmega::{
    Heartbeat, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType,
};
use mavstack_transport::frame::{FrameBuf, FrameCommand, FrameEvent, FrameProtocol, MessageTable};
use mavstack_transport::{ConnSpec, Connection};

#[tokio::main]
async fn main() -> Result<(), Box<dyn core::error::Error>> {
    let Some(arg) = std::env::args().nth(1) else {
        eprintln!("usage: heartbeat CONN   (e.g. udpout:127.0.0.1:14550)");
        std::process::exit(2);
    };
    let spec: ConnSpec = arg.parse()?;
    let mut conn =
        Connection::open(&spec, FrameProtocol::new(MessageTable::of::<MavMessage>())).await?;
    let heartbeat = Heartbeat {
        r#type: MavType::GCS,
        autopilot: MavAutopilot::INVALID,
        base_mode: MavModeFlag::default(),
        system_status: MavState::ACTIVE,
        ..Heartbeat::default()
    };
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    let mut seq = 0u8;
    let mut received = 0u64;
    loop {
        tokio::select! {
            _ = tick.tick() => {
                // A ground station's ids: system 255, component 190 (MAV_COMP_ID_MISSIONPLANNER).
                let header = FrameHeader { version: Version::V2, seq, sysid: 255, compid: 190, signed: false };
                seq = seq.wrapping_add(1);
                conn.send(FrameCommand::to_all(FrameBuf::from_message(&header, &heartbeat)?)).await?;
                let link = conn.stats().link;
                eprintln!("sent {seq} heartbeats; received {received} frames; dropped {}", link.tx_dropped);
            }
            event = conn.recv() => match event {
                Some(FrameEvent::Frame(f)) => {
                    received += 1;
                    let frame = f.frame.frame();
                    if frame.msg_id() == Heartbeat::ID {
                        let hb = Heartbeat::decode(frame.payload());
                        println!("system {} component {}: {:?} {:?} {:?}",
                            frame.sysid(), frame.compid(), hb.r#type, hb.autopilot, hb.system_status);
                    }
                }
                Some(_) => {}
                None => break,
            },
        }
    }
    conn.close().await?;
    Ok(())
}
