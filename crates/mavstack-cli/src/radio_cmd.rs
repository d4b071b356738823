//! `mavstack radio`: a semi-transparent radio forwarding frames between a ground station (A)
//! and a vehicle (B) and injecting RADIO_STATUS, MAVLink 1 until it has seen MAVLink 2
//! ([`mavstack::radio::RadioBridge`]).

use clap::Args;
use mavstack::radio::{RadioBridge, RadioNotice};
use mavstack_channel::RadioConfig;

use crate::link_cmd::{interrupted, runtime, seconds};
use crate::vehicle_cmd::{say, stderr_log};
use crate::{Failure, fail};

#[derive(Debug, Args)]
pub(crate) struct RadioArgs {
    /// The ground station's side.
    conn_a: String,
    /// The vehicle's side.
    conn_b: String,
    /// Seconds between RADIO_STATUS frames (from 0.01 to 86400).
    #[arg(long, default_value_t = 1.0, value_parser = crate::link_cmd::period_arg)]
    interval: f64,
    /// Print the radio's events to stderr.
    #[arg(long, short)]
    verbose: bool,
}

pub(crate) fn radio(args: &RadioArgs) -> Result<(), Failure> {
    // The link grammar of every command; a radio carries frames as they are, so only the
    // connection of each link string is used.
    let parse = |text: &str| {
        mavstack::LinkSpec::parse(text, &|_| None).map_err(|e| Failure::Input(e.into()))
    };
    let a = parse(&args.conn_a)?.conn;
    let b = parse(&args.conn_b)?.conn;
    let mut config = RadioConfig::default();
    config.interval = seconds(args.interval, "--interval")?;
    runtime()?.block_on(async {
        let log = stderr_log(args.verbose);
        let notify = move |n: &RadioNotice| say(&log, || n.to_string());
        let radio = RadioBridge::start(&a, &b, config, notify)
            .await
            .map_err(fail)?;
        radio.run_until(interrupted()).await.map_err(fail)?;
        Ok(())
    })
}
