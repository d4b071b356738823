//! # mavstack-dialects
//!
//! Every official MAVLink dialect as typed Rust, generated at build time by
//! `mavstack-codegen` from the XML vendored in `definitions/` (see its `PROVENANCE.md`).
//! `no_std`, no allocation.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! Each definition file is a module behind a cargo feature of the same name, in lower case
//! (`common`, `ardupilotmega`, `uavionix`, ...); a feature enables the files its XML includes,
//! and `all` enables every one. The default is `ardupilotmega`.
//!
//! A module holds the messages and enums its file defines, re-exports those of the files it
//! includes, and has `MavMessage`, the enum of every message of the dialect. Types are shared,
//! never duplicated: `ardupilotmega::Heartbeat` *is* `minimal::Heartbeat`, and the `MAV_CMD`
//! entries that `ardupilotmega.xml` adds are constants of `common::MavCmd` when the
//! `ardupilotmega` feature is on.
//!
//! A dialect chosen by name at run time (a command-line argument, a configuration file)
//! still runs through the typed code: [`with_dialect`] calls a [`DialectVisitor`] with the
//! `MavMessage` of the dialect of that name among those compiled in, so a program needs no
//! list of its own.
//!
//! ```
//! use mavstack_core::{MessageSet, MessageTable};
//! use mavstack_dialects::{DialectVisitor, with_dialect};
//!
//! struct Table;
//! impl DialectVisitor for Table {
//!     type Output = MessageTable;
//!     fn visit<M: MessageSet>(self) -> MessageTable {
//!         MessageTable::of::<M>()
//!     }
//! }
//! // Names are matched without regard to case; `minimal` comes with every dialect feature.
//! let table = with_dialect("Minimal", Table).expect("compiled in");
//! assert!(table.info(0).is_some());
//! assert!(with_dialect("no_such_dialect", Table).is_none());
//! ```
//!
//! Enums are open: `MavType(pub u8)` with a constant per entry, so unknown values survive a
//! round trip; bitmasks keep unknown bits.
//!
//! ```
//! use mavstack_core::{Message, MessageSet};
//! use mavstack_dialects::common::{Heartbeat, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType};
//!
//! let hb = Heartbeat {
//!     r#type: MavType::QUADROTOR,
//!     autopilot: MavAutopilot::PX4,
//!     base_mode: MavModeFlag::CUSTOM_MODE_ENABLED | MavModeFlag::STABILIZE_ENABLED | MavModeFlag::MANUAL_INPUT_ENABLED,
//!     system_status: MavState::ACTIVE,
//!     ..Heartbeat::default()
//! };
//! let mut payload = [0u8; mavstack_core::MAX_PAYLOAD_LEN];
//! let len = hb.encode(&mut payload);
//! assert_eq!(&payload[..len], &[0, 0, 0, 0, 2, 12, 0x51, 4, 3]);
//! assert_eq!(MavMessage::decode(Heartbeat::ID, &payload[..len]), Ok(MavMessage::Heartbeat(hb)));
//! ```
//!
//! ## Features
//! - one per dialect (see above), `all`;
//! - `serde`: `Serialize`/`Deserialize` for every message and enum.
//!
//! MSRV: Rust 1.95.
#![no_std]
#![forbid(unsafe_code)]

include!(concat!(env!("OUT_DIR"), "/mod.rs"));
