//! # The routing rules, and why (documentation only)
//!
//! ## Routes
//! Every accepted frame teaches the router that its source `(sysid, compid)` is reachable
//! through the link it arrived on; sources with id 0 teach nothing. A frame is forwarded:
//!
//! - **broadcast** (no target field, a target truncated away, or `target_system` 0): to every
//!   link but the one it came from;
//! - **targeted**: to the links where the target `(system, component)` was heard within the
//!   route TTL; with `target_component` 0, or a component not heard yet, to the links of
//!   any component of the system (a camera behind an autopilot is reached through the
//!   autopilot's link before it has spoken); a target never heard is dropped and counted
//!   (`unknown_target`, on the link the frame came from);
//! - never back to the link it came from.
//!
//! One exception to "no target, broadcast": LOG_DATA, the bulk of a log download, goes to
//! the link that asked for the log (learned from the targeted LOG_REQUEST_DATA, kept while
//! the transfer flows; see [`crate::log_readers`]). Flooding it, as mavlink-router does,
//! copies a whole flight log onto every radio.
//!
//! Targets are read through the dialect's target offsets, extension fields included
//! (COMMAND_ACK's `target_system` is one), bounds-checked against the payload as
//! transmitted: a field that MAVLink 2 truncation removed reads as 0. A frame whose message
//! the dialect does not know (its checksum could not be checked) is a broadcast, as in
//! mavlink-router.
//!
//! ## Moving, redundancy and echoes
//! A source heard on a second link replaces its first link only when it has been quiet
//! there for `route_move_after` (1 s by default); while both are fresh, targeted frames go
//! to both. This is what a vehicle with two radios needs, and it is why an echo cannot cut a
//! system off: mavlink-router stops sending a vehicle's traffic to a link for good once one
//! frame with the vehicle's sysid comes back from it (its issue #452). Here the echo's link
//! is merely added, and forgotten after the TTL if the echo is not repeated.
//!
//! ## Framing
//! A link carries one framing (the versions documents: "all connections to other
//! components over a particular channel must share the same MAVLink version"). A frame
//! whose framing the out-link carries goes byte for byte (seq, CRC and signature kept,
//! unknown ids included). Otherwise it is written again with the source's sysid, compid and
//! seq: to MAVLink 1 with the base fields (ids above 255 cannot go), to MAVLink 2 truncated,
//! without its signature for a link that has no key, and signed with the out-link's key for
//! a signed link. That departs from the routing guide's "never modify a forwarded frame"
//! exactly where the channel rule asks it to: a `version=1` link, a signed link, and
//! signatures on a link without a key. Between two option-less links of MAVLink 2 peers the
//! router forwards byte for byte, as mavlink-router does.
//!
//! Re-framing needs the message's CRC_EXTRA: a frame of an unknown id that would need it is
//! dropped (`cannot_convert`) rather than sent with a checksum nobody can verify.
//!
//! ## Signing boundaries
//! A frame goes onto a signed link byte for byte only when its signature verifies with that
//! link's key (end-to-end signing through the router). Otherwise the router signs it, but
//! only when it came from a link marked `trusted` or was verified by a signed link: this is
//! what MAVProxy gets wrong (its issue #1683: any peer that reaches one of its outputs gets
//! its commands signed). Frames arriving on a signed link must verify and be fresh for
//! their stream, or they are dropped there. SETUP_SIGNING is forwarded only from a `secure`
//! link and never as a broadcast.
//!
//! ## Priorities and limits
//! Commands, parameters, missions, HEARTBEAT, signing setup and the handshake are control
//! traffic ([`crate::is_control`]): a queue of their own drained first on every link, and
//! exempt from rate limits (a byte budget goes into debt for them rather than refuse them).
//! Telemetry beyond a limit or a full queue is dropped and counted on the link it would have
//! gone to, so a flooding or slow link affects only itself.
