//! `mavstack router` with an MQTT 5 fleet link (`mqtt://HOST:PORT?fleet=F&vid=V`), against
//! mosquitto (Debian's broker, started by the script on a free port) with paho-mqtt as the
//! independent MQTT peer and pymavlink 2.4.50 packing and reading every frame
//! (`tests-interop/bridge_interop.py`; `docs/contracts/fleet-keys.md`):
//!
//! - `telemetry`: every frame from the vehicle's network (MAVLink 1, MAVLink 2, signed, an id
//!   no dialect knows) reaches a paho subscriber on `mav/F/V/{sysid}/{compid}/{NAME}` byte for
//!   byte; telemetry at QoS 0, control at QoS 1;
//! - `inbound`: frames published on `mav/F/V/in` reach the vehicles byte for byte (a signed
//!   one through a `key=` link), and none is published back;
//! - `command`: an MQTT 5 request to `@cmd` gets `mavstack vehicle`'s COMMAND_ACK with the
//!   request's correlation data; no answer gives `timeout` after the resends; a key that does
//!   not match the target is refused at once;
//! - `ground`: a ground router on `vid=*` shows two vehicles that are both system 1 as
//!   systems 1 and 2, and a command to 2 reaches the second as a command to its own 1;
//! - `alive`: `@alive` retained `online`, `offline` on SIGTERM, and by the last will on
//!   SIGKILL;
//! - `corrupt`: pymavlink-packed frames with a byte flipped, on `in` and as a request on
//!   `@cmd`, never reach the vehicle (nor a resend of the request); the request gets
//!   `error=bad_crc`; both counted (`bad_crc`);
//! - `vehicles`: a ground router on `vid=*&max_vehicles=3` keeps at most 3 vehicle links
//!   while a client announces 20 more vehicles (refusals counted), the real vehicle heard
//!   first still works both ways, and a vehicle going offline frees a place.
//!
//! The same over Zenoh (`zenoh://HOST:PORT?fleet=F&vid=V`, `tests-interop/bridge_zenoh.py`)
//! with eclipse-zenoh (PyPI) as the independent peer, its session the Zenoh router the link
//! connects to: frames on their keys byte for byte, frames on `in` into the network, a query
//! on `@cmd` answered with the vehicle's COMMAND_ACK (or the error `timeout`), the liveliness
//! token gone on SIGTERM and on SIGKILL, the ground side's remapping, reconnection after the
//! Zenoh router restarts, and the link as an in-process peer (`zenoh:`). And `mqtts://`
//! against mosquitto's TLS listener with client certificates (`tls`).
//!
//! Never skipped: without mosquitto, paho-mqtt, eclipse-zenoh or pymavlink they fail.

use crate::pymavlink_dialect;
use crate::support;

fn scenario(name: &str) {
    pymavlink_dialect::dialect_ready();
    support::scenario("bridge_interop.py", name, env!("CARGO_BIN_EXE_mavstack"));
}

fn zenoh(name: &str) {
    pymavlink_dialect::dialect_ready();
    support::scenario("bridge_zenoh.py", name, env!("CARGO_BIN_EXE_mavstack"));
}

#[test]
fn bridge_publishes_every_frame_on_its_key_byte_for_byte() {
    scenario("telemetry");
}

#[test]
fn bridge_lets_frames_from_the_broker_into_the_network() {
    scenario("inbound");
}

#[test]
fn bridge_answers_mqtt5_command_requests_with_the_vehicles_ack() {
    scenario("command");
}

#[test]
fn bridge_says_offline_on_exit_and_by_last_will() {
    scenario("alive");
}

/// The ground side: a ground router subscribed to the whole fleet (`vid=*`) presents two
/// vehicles that are both system 1 as systems 1 and 2, both ways (pymavlink's packing).
#[test]
fn ground_router_remaps_vehicles_that_share_a_sysid() {
    scenario("ground");
}

#[test]
fn zenoh_bridge_puts_every_frame_on_its_key_byte_for_byte() {
    zenoh("telemetry");
}

#[test]
fn zenoh_bridge_lets_frames_from_zenoh_into_the_network() {
    zenoh("inbound");
}

#[test]
fn zenoh_bridge_answers_queries_on_cmd_with_the_vehicles_ack() {
    zenoh("command");
}

#[test]
fn zenoh_bridge_liveliness_token_goes_on_exit_and_on_crash() {
    zenoh("alive");
}

#[test]
fn zenoh_bridge_runs_as_an_in_process_peer() {
    zenoh("peer");
}

/// Corrupt frames from the broker are dropped and counted, never given a fresh checksum.
#[test]
fn bridge_drops_corrupt_frames_on_in_and_cmd() {
    scenario("corrupt");
}

/// The ground side takes at most `max_vehicles` vehicles as links.
#[test]
fn ground_router_bounds_its_vehicle_links() {
    scenario("vehicles");
}

/// The ground side over Zenoh: liveliness with history and the fleet's frames, remapped.
#[test]
fn zenoh_ground_router_remaps_vehicles_that_share_a_sysid() {
    zenoh("ground");
}

/// `mqtts://` against mosquitto's TLS listener that asks for client certificates: frames
/// both ways with `ca=`, `client_cert=`, `client_key=`; without the CA, no connection.
#[test]
fn mqtts_bridge_with_client_certificate_and_a_refused_server() {
    scenario("tls");
}

/// The Zenoh router gone for 2 s and back on its port: the link's session reconnects.
#[test]
fn zenoh_bridge_reconnects_after_the_zenoh_router_restarts() {
    zenoh("restart");
}
