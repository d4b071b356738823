//! Design rationale: why the channel negotiates versions and checks signatures the way it
//! does. Documentation only; no code.
//!
//! # Version negotiation
//!
//! ## One version per link, decided per link
//! MAVLink 1 and 2 differ in framing, not in messages, and a MAVLink 2 parser reads both. What
//! has to be decided is what a link *sends*. The C library keeps that per channel
//! (`MAVLINK_STATUS_FLAG_OUT_MAVLINK1`), and so do we: [`crate::Channel`] is one link and
//! [`crate::LinkVersion`] is its state. A component with a USB link and a radio link can
//! send MAVLink 2 on one and MAVLink 1 on the other.
//!
//! A link never mixes framings on output, with two deliberate exceptions that the protocol
//! itself requires: the ground station's handshake request, and the vehicle's
//! PROTOCOL_VERSION answer, both go out in MAVLink 2 framing while the link may still send
//! MAVLink 1. Their whole point is to test whether MAVLink 2 gets through. The vehicle's
//! COMMAND_ACK uses the link's framing, so a MAVLink 1 peer can read the refusal or the
//! acceptance whatever happens to the MAVLink 2 answer.
//!
//! ## Who switches, and when
//! The devguide leaves the "who switches first" question open (mavlink/mavlink#630). We
//! implement its best practice and make the choices explicit:
//!
//! - A vehicle switches on the first *accepted* MAVLink 2 frame: one whose checksum was
//!   checked (or whose signature was verified). A stray `0xFD` in noise, a frame of an
//!   unknown id (checksum unchecked), or a frame rejected by signing never switches a link.
//! - A vehicle with MAVLink 2 disabled still parses MAVLink 2: otherwise it could not refuse
//!   the handshake, which arrives in MAVLink 2. It never sends MAVLink 2 and refuses the
//!   handshake with a failure ACK (UNSUPPORTED by default) in MAVLink 1.
//! - A vehicle configured without protocol-version support stays silent, as some real
//!   targets do; the ground station must then time out.
//! - An automatic ground station switches on the first accepted MAVLink 2 frame, on
//!   AUTOPILOT_VERSION with MAV_PROTOCOL_CAPABILITY_MAVLINK2 (8192; not 32768, which is
//!   MISSION_RALLY), or on handshake success. On a NACK it goes back to MAVLink 1. On a
//!   timeout it goes back to MAVLink 1 unless MAVLink 2 frames have been accepted on the
//!   link: a peer whose MAVLink 2 frames arrive is reachable in MAVLink 2, and flipping back
//!   would only make the link oscillate between the first-frame rule and the fallback.
//! - A configured (MAVLink 2 from the start) or signing link never changes version on its
//!   own: configuration wins over negotiation, and signing needs MAVLink 2.
//!
//! ## Why the handshake is a typestate
//! The ground-station side awaits two different things: first any sign of an answer (an ACK
//! or the message), then, once accepted, only the message. Modelling these as types consumed
//! by value ([`crate::handshake::AwaitingAnswer`], [`crate::handshake::AwaitingMessage`])
//! makes "an ACK after acceptance" or "a retry after the end" unrepresentable rather than
//! something each handler must remember to check. An ACK ACCEPTED whose message never
//! arrives is reported as `Timeout { acked: true }`: the target speaks MAVLink 2 but the path
//! mangles it (a non-transparent radio), which is exactly what the handshake exists to find.
//!
//! Retries follow the command protocol: the same command every interval, COMMAND_LONG's
//! `confirmation` counting 0, 1, 2, ... (COMMAND_INT has no such field). Defaults are
//! MAVSDK's 500 ms and QGC's three retries.
//!
//! # Signing threat model
//!
//! ## What signing protects against
//! An attacker who can inject and capture frames on the link but does not hold a key must
//! not be able to (a) make a frame accepted that no key holder produced, (b) make a captured
//! frame accepted a second time, or (c) stop genuine frames from being accepted by sending
//! frames of their own. Confidentiality is not a goal: MAVLink signing authenticates, it
//! does not encrypt.
//!
//! ## Order of the checks
//! 1. An unsigned frame (and every MAVLink 1 frame, which cannot carry a signature) is let in
//!    only if its message id is on the allow-list, and then marked
//!    [`crate::Authentication::AllowedUnsigned`], never authenticated. RADIO_STATUS is on the
//!    list by default because SiK radios inject it unsigned; every id on the list is one an
//!    attacker can inject, so keep it short (PX4 allowing HEARTBEAT lets anyone spawn
//!    phantom vehicles). A *signed* frame with a bad signature is rejected even if its id is
//!    on the list.
//! 2. The signature is checked against every key of the link, in constant time per key. On a
//!    mismatch the frame is rejected with nothing else touched.
//! 3. Only then the replay table: a known stream needs a timestamp strictly greater than its
//!    last (equal is a replay); a new stream needs a timestamp no more than one minute
//!    behind the link's current timestamp; a full table rejects new streams.
//! 4. Only an accepted frame updates the stream and raises the link's own timestamp.
//!
//! Checking the signature before the table is what defeats (c): pymavlink 2.4.50 recorded
//! the stream's timestamp before verifying, so one forged frame with a huge timestamp locked
//! the genuine stream out. Here a forged frame cannot move any state. Raising our timestamp
//! only from verified frames also means a forger cannot push our outgoing timestamps into the
//! future.
//!
//! ## The one-minute rule, one-sided
//! A new stream is refused only when it is more than a minute *behind* (the C library's
//! rule). A stream far *ahead* is accepted, because only a key holder can produce it, and a
//! receiver without a clock (whose timestamp is stale) must still accept a sender that has
//! one; refusing it would reject genuine frames. The window bounds how old a capture an
//! attacker can replay into a stream the receiver has not seen yet (after a restart, or
//! into a fresh channel): at most a minute.
//!
//! ## Streams are per channel
//! The C library shares one stream table between all channels so that a frame captured on
//! one link cannot be replayed on another. A [`crate::Channel`] is one link and owns its
//! table, so cross-link replay is limited only by the one-minute window of a new stream and
//! by the link id in the stream key. A component with several signed links that cares
//! about cross-link replay should give each peer a distinct link id per link and keep the
//! links' clocks close; a shared table is a router concern (a later layer).
//!
//! ## Outgoing timestamps never go backwards
//! Each frame gets `max(clock-derived, last + 1)`, and "last" also rises to every verified
//! incoming timestamp (QGC#14375 was a ground station rejected for a stale timestamp). A
//! clock that steps back therefore only slows the timestamps down to one unit per frame. A
//! restart must not reuse timestamps either: the channel reserves ahead and asks the caller
//! to persist the reservation ([`crate::Event::PersistTimestamp`]) *before* using a
//! timestamp at or beyond the last one stored, so a restarted link that loads the stored
//! value starts above anything it sent, even with no clock at all. Because this is an event
//! rather than a callback, the channel stays free of I/O; the adapter writes the value
//! wherever it likes (a file, flash, a parameter).
//!
//! ## SETUP_SIGNING
//! The message carries a secret key in the clear, so it is accepted only on a link the
//! configuration marks secure (USB, a wire) and only when addressed to this system (and
//! this component or all of its components). On a signing link it must itself pass the
//! signing checks. It is never delivered as an ordinary frame: the key goes to the caller
//! once, in [`crate::Event::SigningSetup`], for storage. An all-zero key with timestamp 0
//! turns signing off, as ArduPilot and PX4 do.
//!
//! ## Signed frames on a link without keys
//! They are delivered (a router or logger must see them) but marked
//! [`crate::Authentication::NotChecked`]: parsed is not authenticated.
