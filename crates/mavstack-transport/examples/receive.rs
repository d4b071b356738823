//! Prints every frame a connection receives: `receive CONN`.
//!
//! ```text
//! cargo run -p mavstack-transport --example receive -- udpin:0.0.0.0:14550
//! cargo run -p mavstack-transport --example receive -- serial:/dev/ttyUSB0:57600
//! cargo run -p mavstack-transport --example receive -- file:flight.tlog
//! ```

use mavstack_core::MessageSet as _;
use mavstack_dialects::ardupilotmega::MavMessage;
use mavstack_transport::frame::{FrameEvent, FrameProtocol, MessageTable};
use mavstack_transport::{ConnSpec, Connection};

#[tokio::main]
async fn main() -> Result<(), Box<dyn core::error::Error>> {
    let Some(arg) = std::env::args().nth(1) else {
        eprintln!("usage: receive CONN   (e.g. udpin:0.0.0.0:14550)");
        std::process::exit(2);
    };
    let spec: ConnSpec = arg.parse()?;
    let protocol = FrameProtocol::new(MessageTable::of::<MavMessage>()).keep_unknown(true);
    let mut conn = Connection::open(&spec, protocol).await?;
    eprintln!("receiving on {spec}");
    while let Some(event) = conn.recv().await {
        match event {
            FrameEvent::Frame(f) | FrameEvent::Unknown(f) => {
                let frame = f.frame.frame();
                let name = MavMessage::info(frame.msg_id()).map_or("?", |i| i.name);
                println!(
                    "{} v{} sys {} comp {} msg {} {name} ({} bytes)",
                    f.peer,
                    frame.version().number(),
                    frame.sysid(),
                    frame.compid(),
                    frame.msg_id(),
                    frame.frame_len(),
                );
            }
            FrameEvent::PeerAdded(p) => eprintln!("{} is {}", p.id, p.addr),
            FrameEvent::PeerRemoved(id) => eprintln!("{id} went away"),
            _ => {}
        }
    }
    let stats = conn.stats();
    conn.close().await?;
    eprintln!("{:?}", stats.protocol);
    Ok(())
}
