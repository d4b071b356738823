//! Conformance: grade a remote vehicle or ground station against the rules of the MAVLink
//! versions documents (what `mavstack conform` runs; feature `sim`).
//!
//! - [`grade_vehicle`]: this node plays a ground station towards a vehicle — discovers it,
//!   watches the version it starts in, sends a MAVLink 2 frame and watches the switch, runs
//!   the handshake in each form, asks for AUTOPILOT_VERSION — and grades every frame's
//!   checksum, truncation, sequence, framing and signing, and a semi-transparent radio in the
//!   path by its RADIO_STATUS.
//! - [`grade_ground_station`]: a simulated vehicle answers (or NACKs, or ignores) the
//!   handshake, and the ground station's requests, switch, fallback and mixing are graded.
//!
//! Both read the wire through the node's tap ([`NodeHandle::tap`](crate::NodeHandle::tap)),
//! before any parsing, and send their own frames exactly as crafted
//! ([`NodeHandle::send_bytes`](crate::NodeHandle::send_bytes)): the link layer hides or
//! repairs nothing. The [`Report`] has one [`Verdict`] per [`Rule`] of the role, each with
//! evidence a person can act on ("HEARTBEAT 4 of 9 in MAVLink 1 after the switch at
//! 2.31 s").
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::conform::{VehicleOptions, grade_vehicle};
//! use mavstack::{LinkSpec, Node};
//! let node = Node::builder()
//!     .identity(255, 190)
//!     .link(LinkSpec::parse("udpin:0.0.0.0:14550", &|_| None)?)
//!     .start()
//!     .await?;
//! let report = grade_vehicle(&node.handle(), &VehicleOptions::default()).await;
//! for v in &report.verdicts {
//!     println!("{} {} {}", v.rule.id(), v.status.as_str(), v.evidence);
//! }
//! std::process::exit(i32::from(!report.conforms()));
//! # }
//! ```

mod gcs;
mod vehicle;
mod wire;

use core::fmt;

pub use gcs::{GcsOptions, VehicleMode, grade_ground_station};
pub use vehicle::{VehicleOptions, grade_vehicle};

/// How much a rule matters: failing a `must` or `should` rule fails the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Level {
    /// Required by the documents.
    Must,
    /// Recommended.
    Should,
    /// Reported only.
    Info,
}

impl Level {
    /// `"must"`, `"should"` or `"info"`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Must => "must",
            Self::Should => "should",
            Self::Info => "info",
        }
    }
}

/// A verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Status {
    /// The rule holds.
    Pass,
    /// It does not.
    Fail,
    /// Its precondition does not hold (the evidence says which).
    NotApplicable,
}

impl Status {
    /// `"pass"`, `"fail"` or `"n/a"`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Pass => "pass",
            Self::Fail => "fail",
            Self::NotApplicable => "n/a",
        }
    }
}

/// The rules, with their stable ids (`docs/contracts/conformance.md`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Rule {
    /// HEARTBEATs arrive at about 1 Hz with `mavlink_version` 3.
    Heartbeat,
    /// Every frame passes its checksum with the dialect's CRC_EXTRA.
    Crc,
    /// Each component's `seq` rises by one (mod 256) on a loss-free link.
    Sequence,
    /// MAVLink 2 payloads carry no trailing zero bytes (but keep at least one byte).
    Truncation,
    /// AUTOPILOT_VERSION is sent on request and its MAVLINK2 flag agrees with behaviour.
    CapabilityFlag,
    /// A vehicle that starts in MAVLink 1 with MAVLink 2 enabled switches on the first
    /// MAVLink 2 frame.
    SwitchOnV2,
    /// A REQUEST_MESSAGE sent in MAVLink 2 is answered in MAVLink 2 framing: PROTOCOL_VERSION,
    /// or, where the system refuses 300, another message it emits (AUTOPILOT_VERSION), the
    /// versions documents' fallback.
    HandshakeAnswer,
    /// PROTOCOL_VERSION is answered at all (deprecated by the MAVLink guide in 2025-12;
    /// ArduPilot never had it): reported only.
    ProtocolVersionSupported,
    /// PROTOCOL_VERSION arrives in MAVLink 2 framing.
    HandshakeV2Framing,
    /// MAV_CMD_REQUEST_PROTOCOL_VERSION is answered the same way.
    Handshake519,
    /// The request sent as COMMAND_INT is answered the same way.
    HandshakeCommandInt,
    /// A system without MAVLink 2 NACKs the request instead of staying silent.
    NackWithoutV2,
    /// `min_version` ≤ `version` ≤ `max_version`, and `max_version` ≥ 200.
    ProtocolVersionValues,
    /// Once the link is MAVLink 2 no MAVLink 1 frame follows; on a signed link no unsigned
    /// frame.
    NoMixing,
    /// A system that signs, signs from its first frame.
    SignedFromStart,
    /// A RADIO_STATUS source switches to MAVLink 2 after the first MAVLink 2 frame passed it.
    RadioV2AfterFirstV2,
    /// The ground station's handshake request is a MAVLink 2 frame.
    GcsHandshakeV2Framing,
    /// It sends MAVLink 2 after the vehicle's first MAVLink 2 frame or MAVLINK2 capability.
    GcsSwitch,
    /// After a NACK or silence it goes on working in MAVLink 1.
    GcsFallback,
    /// After switching it sends no MAVLink 1 frame.
    GcsNoMixing,
}

impl Rule {
    /// The stable id (`"handshake_v2_framing"`).
    #[must_use]
    pub const fn id(self) -> &'static str {
        match self {
            Self::Heartbeat => "heartbeat",
            Self::Crc => "crc",
            Self::Sequence => "sequence",
            Self::Truncation => "truncation",
            Self::CapabilityFlag => "capability_flag",
            Self::SwitchOnV2 => "switch_on_v2",
            Self::HandshakeAnswer => "handshake_answer",
            Self::ProtocolVersionSupported => "protocol_version_supported",
            Self::HandshakeV2Framing => "handshake_v2_framing",
            Self::Handshake519 => "handshake_519",
            Self::HandshakeCommandInt => "handshake_command_int",
            Self::NackWithoutV2 => "nack_without_v2",
            Self::ProtocolVersionValues => "protocol_version_values",
            Self::NoMixing => "no_mixing",
            Self::SignedFromStart => "signed_from_start",
            Self::RadioV2AfterFirstV2 => "radio_v2_after_first_v2",
            Self::GcsHandshakeV2Framing => "gcs_handshake_v2_framing",
            Self::GcsSwitch => "gcs_switch",
            Self::GcsFallback => "gcs_fallback",
            Self::GcsNoMixing => "gcs_no_mixing",
        }
    }

    /// How much it matters.
    #[must_use]
    pub const fn level(self) -> Level {
        match self {
            Self::ProtocolVersionSupported | Self::Handshake519 => Level::Info,
            Self::Sequence
            | Self::SwitchOnV2
            | Self::HandshakeCommandInt
            | Self::NackWithoutV2
            | Self::ProtocolVersionValues
            | Self::RadioV2AfterFirstV2
            | Self::GcsSwitch
            | Self::GcsFallback => Level::Should,
            _ => Level::Must,
        }
    }
}

impl fmt::Display for Rule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.id())
    }
}

/// One rule's verdict and the evidence for it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Verdict {
    /// The rule.
    pub rule: Rule,
    /// Pass, fail or n/a.
    pub status: Status,
    /// What was seen, in words, with times in seconds since the run started.
    pub evidence: String,
}

impl Verdict {
    fn new(rule: Rule, status: Status, evidence: impl Into<String>) -> Self {
        Self {
            rule,
            status,
            evidence: evidence.into(),
        }
    }

    fn pass(rule: Rule, evidence: impl Into<String>) -> Self {
        Self::new(rule, Status::Pass, evidence)
    }

    fn fail(rule: Rule, evidence: impl Into<String>) -> Self {
        Self::new(rule, Status::Fail, evidence)
    }

    fn na(rule: Rule, evidence: impl Into<String>) -> Self {
        Self::new(rule, Status::NotApplicable, evidence)
    }

    fn check(rule: Rule, ok: bool, evidence: impl Into<String>) -> Self {
        Self::new(rule, if ok { Status::Pass } else { Status::Fail }, evidence)
    }
}

/// Which side was graded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Role {
    /// A vehicle (conform played the ground station).
    Vehicle,
    /// A ground station (conform played the vehicle).
    GroundStation,
}

impl Role {
    /// `"vehicle"` or `"gcs"`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Vehicle => "vehicle",
            Self::GroundStation => "gcs",
        }
    }
}

/// A report card.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// The side graded.
    pub role: Role,
    /// The graded system's (sysid, compid), if one was heard.
    pub target: Option<(u8, u8)>,
    /// One verdict per rule of the role, in the table's order.
    pub verdicts: Vec<Verdict>,
    /// Seconds the run took.
    pub seconds: f64,
}

impl Report {
    /// Whether no `must` or `should` rule failed.
    #[must_use]
    pub fn conforms(&self) -> bool {
        !self
            .verdicts
            .iter()
            .any(|v| v.status == Status::Fail && v.rule.level() != Level::Info)
    }

    /// How many verdicts have `status`.
    #[must_use]
    pub fn count(&self, status: Status) -> usize {
        self.verdicts.iter().filter(|v| v.status == status).count()
    }

    /// The verdict on `rule`, if the role has it.
    #[must_use]
    pub fn verdict(&self, rule: Rule) -> Option<&Verdict> {
        self.verdicts.iter().find(|v| v.rule == rule)
    }
}

/// Fuzzing entry: `data` as the wire of a vehicle-role run, read and graded; never panics,
/// and every rule gets a verdict with evidence.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_wire(data: &[u8]) {
    let verdicts = vehicle::fuzz_grade(data);
    assert_eq!(verdicts.len(), vehicle::VEHICLE_RULES.len());
    assert!(verdicts.iter().all(|v| !v.evidence.is_empty()));
}

/// The verdicts [`fuzz_wire`] checks, for tests of the graders on crafted input.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
#[must_use]
pub fn fuzz_grade_for_tests(data: &[u8]) -> Vec<Verdict> {
    vehicle::fuzz_grade(data)
}

/// Times, for evidence.
fn secs(t: f64) -> String {
    format!("{t:.2} s")
}

/// "MAVLink 1" / "MAVLink 2".
fn version_name(v: mavstack_core::wire::Version) -> &'static str {
    match v {
        mavstack_core::wire::Version::V1 => "MAVLink 1",
        mavstack_core::wire::Version::V2 => "MAVLink 2",
    }
}
