//! Records a connection into a tlog until interrupted: `record CONN FILE.tlog`.
//!
//! ```text
//! cargo run -p mavstack-transport --example record -- udpin:0.0.0.0:14550 flight.tlog
//! ```
//!
//! Each frame is stamped with its receive time (microseconds since the Unix epoch). The log
//! is written out at least once a second, so a crash loses at most the last second; Ctrl-C
//! writes out the rest and stops.

use mavstack_dialects::ardupilotmega::MavMessage;
use mavstack_transport::frame::{FrameEvent, FrameProtocol, MessageTable};
use mavstack_transport::tlog;
use mavstack_transport::{ConnSpec, Connection};

#[tokio::main]
async fn main() -> Result<(), Box<dyn core::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [conn_arg, path] = &args[..] else {
        eprintln!("usage: record CONN FILE.tlog   (e.g. udpin:0.0.0.0:14550 flight.tlog)");
        std::process::exit(2);
    };
    let spec: ConnSpec = conn_arg.parse()?;
    // Unknown message ids are recorded too: a log keeps everything that was on the wire.
    let protocol = FrameProtocol::new(MessageTable::of::<MavMessage>()).keep_unknown(true);
    let mut conn = Connection::open(&spec, protocol).await?;
    let mut log = tlog::Writer::new(std::fs::File::create(path)?);
    eprintln!("recording {spec} into {path}; Ctrl-C stops");
    let stop = tokio::signal::ctrl_c();
    tokio::pin!(stop);
    loop {
        // Wake up for the log's flush deadline too, so an idle link's last frames reach the file.
        let flush_at = log.flush_deadline().map(tokio::time::Instant::from_std);
        tokio::select! {
            _ = &mut stop => break,
            () = async { if let Some(t) = flush_at { tokio::time::sleep_until(t).await } else { core::future::pending().await } } => {
                log.flush_if_due()?;
            }
            event = conn.recv() => match event {
                Some(FrameEvent::Frame(f) | FrameEvent::Unknown(f)) => {
                    log.write_record(f.time.as_micros(), f.frame.as_bytes())?;
                }
                Some(_) => {}
                None => break,
            },
        }
    }
    log.flush()?;
    eprintln!("{} frames recorded", log.records());
    conn.close().await?;
    Ok(())
}
