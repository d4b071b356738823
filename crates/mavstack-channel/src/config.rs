//! How a link is set up: who we are, which role we play, the version policy, signing.

use mavstack_dialects::common::{MavResult, ProtocolVersion};

use crate::handshake::HandshakeConfig;
use crate::signing::SigningConfig;

/// Which versions a vehicle's link speaks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum VehicleVersion {
    /// MAVLink 2 disabled: the link sends MAVLink 1 only and refuses the handshake. (It
    /// still parses MAVLink 2 frames, as every MAVLink 2 library does, so that it can refuse
    /// a request sent in MAVLink 2.)
    Mavlink1Only,
    /// Start in MAVLink 1 and switch the link to MAVLink 2 when the first MAVLink 2 frame is
    /// accepted on it (ArduPilot with `SERIALn_PROTOCOL` = 2).
    #[default]
    StartMavlink1,
    /// MAVLink 2 from the first frame.
    Mavlink2,
}

/// A vehicle's version policy.
///
/// The vehicle answers a request for PROTOCOL_VERSION (MAV_CMD_REQUEST_PROTOCOL_VERSION, or
/// MAV_CMD_REQUEST_MESSAGE with param1 = 300, as COMMAND_LONG or COMMAND_INT) whose target
/// system is 0 or its own and whose target component is 0 or its own. (PX4 answers whatever
/// the component; we follow the routing rules.)
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct VehiclePolicy {
    /// Which versions the link speaks.
    pub version: VehicleVersion,
    /// The PROTOCOL_VERSION sent in answer to a handshake request; `None` for a vehicle
    /// without protocol-version support, which stays silent (neither ACK nor answer) and
    /// leaves the request to the caller's own command handling.
    pub protocol_version: Option<ProtocolVersion>,
    /// The COMMAND_ACK result that refuses a handshake when MAVLink 2 is disabled
    /// (default MAV_RESULT_UNSUPPORTED; the devguide also names DENIED).
    pub nack_result: MavResult,
    /// For a vehicle without protocol-version support (`protocol_version` `None`): refuse
    /// the request as ArduPilot does — COMMAND_ACK FAILED for REQUEST_MESSAGE(300),
    /// UNSUPPORTED for MAV_CMD_REQUEST_PROTOCOL_VERSION — instead of staying silent.
    pub refuse_unsupported: bool,
}

impl Default for VehiclePolicy {
    fn default() -> Self {
        Self {
            version: VehicleVersion::default(),
            protocol_version: Some(default_protocol_version()),
            nack_result: MavResult::UNSUPPORTED,
            refuse_unsupported: false,
        }
    }
}

/// The PROTOCOL_VERSION a vehicle answers by default: version 200, min 100, max 200, both
/// hashes zero (set them to the first 8 bytes of the definitions' and the library's git
/// SHAs when known).
#[must_use]
pub fn default_protocol_version() -> ProtocolVersion {
    ProtocolVersion {
        version: 200,
        min_version: 100,
        max_version: 200,
        spec_version_hash: [0; 8],
        library_version_hash: [0; 8],
    }
}

/// A ground station's version policy.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum GroundPolicy {
    /// Start in MAVLink 1; switch to MAVLink 2 on the first MAVLink 2 frame accepted, on
    /// AUTOPILOT_VERSION with MAV_PROTOCOL_CAPABILITY_MAVLINK2, or on a successful handshake.
    #[default]
    Automatic,
    /// MAVLink 2 from the start (a configuration switch).
    Mavlink2,
}

/// Which end of the link we are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Role {
    /// A vehicle (or any component that answers the handshake).
    Vehicle(VehiclePolicy),
    /// A ground station (or any component that runs the handshake).
    GroundStation(GroundPolicy),
    /// A router's link: it forwards what others send and speaks for nobody. It never answers
    /// or starts a handshake, and delivers SETUP_SIGNING as an ordinary frame (the router
    /// decides where it may go). The version policy is a vehicle's: MAVLink 1 only
    /// ([`VehicleVersion::Mavlink1Only`]), MAVLink 1 until the peer's first MAVLink 2 frame
    /// ([`VehicleVersion::StartMavlink1`]), or MAVLink 2 from the start.
    Relay(VehicleVersion),
}

/// The setup of one link.
///
/// ```
/// use mavstack_channel::{Config, VehicleVersion};
/// let mut config = Config::vehicle(1, 1);
/// config.vehicle_policy_mut().unwrap().version = VehicleVersion::Mavlink2;
/// config.secure = true; // e.g. a USB link: SETUP_SIGNING is accepted here
/// assert!(config.validate().is_ok());
/// ```
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct Config {
    /// Our system id (1..=255), the source of every frame we send.
    pub system_id: u8,
    /// Our component id (1..=255).
    pub component_id: u8,
    /// Vehicle or ground station, with its version policy.
    pub role: Role,
    /// Signing: `Some` makes the link signed MAVLink 2 from the first frame.
    pub signing: Option<SigningConfig>,
    /// The link is trusted (USB, a wire): SETUP_SIGNING is accepted only on such links.
    pub secure: bool,
    /// Retries of the ground-station handshake.
    pub handshake: HandshakeConfig,
}

impl Config {
    /// A vehicle `(system_id, component_id)` that starts in MAVLink 1, switches on the first
    /// MAVLink 2 frame and answers the handshake; no signing; not secure.
    #[must_use]
    pub fn vehicle(system_id: u8, component_id: u8) -> Self {
        Self {
            system_id,
            component_id,
            role: Role::Vehicle(VehiclePolicy::default()),
            signing: None,
            secure: false,
            handshake: HandshakeConfig::default(),
        }
    }

    /// A ground station `(system_id, component_id)` with the automatic version policy; no
    /// signing; not secure.
    #[must_use]
    pub fn ground_station(system_id: u8, component_id: u8) -> Self {
        Self {
            system_id,
            component_id,
            role: Role::GroundStation(GroundPolicy::Automatic),
            signing: None,
            secure: false,
            handshake: HandshakeConfig::default(),
        }
    }

    /// A router's link `(system_id, component_id)` with version policy `version`; no
    /// signing; not secure. The ids are the router's own, used for frames it sends itself.
    ///
    /// ```
    /// use mavstack_channel::{Channel, Config, LinkVersion, VehicleVersion};
    /// let link = Channel::new(Config::relay(1, 191, VehicleVersion::Mavlink2)).unwrap();
    /// assert_eq!(link.version(), LinkVersion::Mavlink2);
    /// ```
    #[must_use]
    pub fn relay(system_id: u8, component_id: u8, version: VehicleVersion) -> Self {
        Self {
            system_id,
            component_id,
            role: Role::Relay(version),
            signing: None,
            secure: false,
            handshake: HandshakeConfig::default(),
        }
    }

    /// The vehicle policy, to adjust it (`None` for a ground station).
    ///
    /// ```
    /// use mavstack_channel::{Config, VehicleVersion};
    /// let mut config = Config::vehicle(1, 1);
    /// let policy = config.vehicle_policy_mut().unwrap();
    /// policy.version = VehicleVersion::Mavlink1Only;
    /// policy.protocol_version = None; // no PROTOCOL_VERSION support: stay silent
    /// ```
    pub const fn vehicle_policy_mut(&mut self) -> Option<&mut VehiclePolicy> {
        match &mut self.role {
            Role::Vehicle(policy) => Some(policy),
            Role::GroundStation(_) | Role::Relay(_) => None,
        }
    }

    /// Whether the link accepts MAVLink 2 (every role but a vehicle or relay with MAVLink 2
    /// disabled).
    #[must_use]
    pub const fn accepts_mavlink2(&self) -> bool {
        !matches!(
            self.role,
            Role::Vehicle(VehiclePolicy {
                version: VehicleVersion::Mavlink1Only,
                ..
            }) | Role::Relay(VehicleVersion::Mavlink1Only)
        )
    }

    /// Checks the setup.
    ///
    /// # Errors
    /// [`ConfigError`] naming the first problem.
    pub const fn validate(&self) -> Result<(), ConfigError> {
        if self.system_id == 0 {
            return Err(ConfigError::ZeroSystemId);
        }
        if self.component_id == 0 {
            return Err(ConfigError::ZeroComponentId);
        }
        if self.signing.is_some() && !self.accepts_mavlink2() {
            return Err(ConfigError::SigningNeedsMavlink2);
        }
        Ok(())
    }
}

/// A link setup that cannot work.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// System id 0 is the broadcast address, never a source.
    #[error("system id 0 is the broadcast address, not a valid source")]
    ZeroSystemId,
    /// Component id 0 is MAV_COMP_ID_ALL, never a source.
    #[error("component id 0 is MAV_COMP_ID_ALL, not a valid source")]
    ZeroComponentId,
    /// Signing on a vehicle with MAVLink 2 disabled: MAVLink 1 frames cannot be signed.
    #[error("signing needs MAVLink 2, which this vehicle has disabled")]
    SigningNeedsMavlink2,
}
