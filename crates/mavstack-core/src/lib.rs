//! # mavstack-core
//!
//! The `no_std`, allocation-free foundation of mavstack: what every other layer and every
//! generated dialect stands on.
//!
//! ```text
//!  XML dialects ──(mavstack-codegen)──► generated structs ──implement──► Message / MessageSet
//!                                                                         │
//!  bytes ◄── payload helpers (little-endian, zero-extended) ◄─────────────┘
//!        ◄── crc (CRC-16/MCRF4XX with CRC_EXTRA)
//! ```
//!
//! - [`crc`]: the X.25 / CRC-16/MCRF4XX checksum that guards every frame.
//! - [`message`]: the [`Message`] trait that every generated message implements and the
//!   [`MessageSet`] trait of a dialect's message enum, plus [`MessageInfo`], the per-id facts
//!   (CRC_EXTRA, lengths, target offsets) a parser needs.
//! - [`payload`]: the byte helpers generated code uses to read and write payload fields.
//! - [`text`]: `char[N]` fields as text.
//!
//! ## Guarantees
//! - `#![no_std]`, no allocation, `#![forbid(unsafe_code)]`.
//! - Decoding a payload never fails: short payloads are zero-extended (MAVLink 2 truncation),
//!   longer ones are cut (a newer dialect's extensions), and enums are open.
//!
//! ## Features
//! - `std` (default): links `std`; nothing in the crate needs it.
//! - `serde`: serde support for generated messages, including arrays longer than 32.
//!
//! MSRV: Rust 1.95 (the toolchain CI builds with).
#![no_std]
#![forbid(unsafe_code)]

#[cfg(feature = "std")]
extern crate std;

pub mod crc;
pub mod message;
pub mod parse;
pub mod payload;
#[cfg(feature = "serde")]
pub mod serde_arrays;
pub mod signing;
pub mod text;
pub mod wire;

pub use crc::Crc16;
pub use message::{MAX_PAYLOAD_LEN, Message, MessageInfo, MessageSet, UnknownMessage};
