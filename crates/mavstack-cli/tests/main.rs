//! The `mavstack` command's tests, one binary: the command line (`cli_*`: arguments, exit
//! codes, output) and the interoperability scenarios against independent peers (`interop_*`:
//! pymavlink, MAVProxy, MAVSDK, mavlink-router's configuration, tshark, chromium). One
//! binary instead of one per file: the shared helpers and the dependencies' code are
//! compiled and linked once.

mod ends;
#[path = "support/pymavlink_dialect.rs"]
mod pymavlink_dialect;
mod router;
mod support;
mod vehicle;

mod cli_conform;
mod cli_demo;
mod cli_dialect;
mod cli_gcs;
mod cli_input;
mod cli_logging;
mod cli_logs;
mod cli_payload;
mod cli_probe;
mod cli_router;
mod cli_router_conf;
mod cli_router_dialect;
mod cli_router_exit;
mod cli_secrets;
mod cli_shell_rtk;
mod cli_web;
mod interop_bridge;
mod interop_codec;
mod interop_conform;
mod interop_ftp;
mod interop_gcs;
mod interop_links;
mod interop_log;
mod interop_logs;
mod interop_param_pck;
mod interop_payload;
mod interop_router;
mod interop_router_peers;
mod interop_rtk;
mod interop_services;
mod interop_tlog;
mod interop_versions;
