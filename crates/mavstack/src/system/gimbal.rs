//! [`Gimbals`]: a system's gimbals (the gimbal protocol v2) — found by their managers'
//! GIMBAL_MANAGER_INFORMATION, each a [`Gimbal`] to take control of, point by angles, rates
//! or at a location, and read the attitude of. The protocol is `mavstack_services::gimbal`'s;
//! every request is checked against the manager's limits before it is sent.

use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::MessageSet as _;
use mavstack_dialects::common::{GimbalDeviceAttitudeStatus, GimbalManagerStatus, MavMessage};
use mavstack_services::Address;
use mavstack_services::gimbal::{
    Attitude, Control, DiscoveryConfig, GimbalDiscovery, GimbalInfo, YawFrame,
};
use mavstack_transport::clock;

use super::{System, SystemError, run};

/// How long a discovery may take at most (its own limit is shorter).
const DISCOVERY_LIMIT: Duration = Duration::from_secs(10);

/// After how long without a GIMBAL_DEVICE_ATTITUDE_STATUS (or GIMBAL_MANAGER_STATUS) it is
/// asked for once.
const ASK_AFTER: Duration = Duration::from_secs(1);

/// The gimbals of a system (from [`System::gimbals`]).
#[derive(Clone, Debug)]
pub struct Gimbals {
    system: System,
}

/// Who controls a gimbal (GIMBAL_MANAGER_STATUS).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct GimbalControl {
    /// The component in primary control.
    pub primary: Option<Address>,
    /// The component in secondary control.
    pub secondary: Option<Address>,
    /// The manager's flags (GIMBAL_MANAGER_FLAGS).
    pub flags: u32,
}

impl Gimbals {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// The system's gimbals: its gimbal managers, found by asking the whole system and each
    /// component heard for GIMBAL_MANAGER_INFORMATION (and each manager's device for
    /// GIMBAL_DEVICE_INFORMATION), in the order they answered. Empty when none answered
    /// within 3 s.
    ///
    /// # Errors
    /// [`SystemError::Stopped`].
    pub async fn list(&self) -> Result<Vec<Gimbal>, SystemError> {
        let inner = &self.system.inner;
        let components = self.system.component_ids();
        let mut frames = self.system.frames().await;
        let mut discovery = GimbalDiscovery::new(
            clock::now(),
            inner.target.system,
            &components,
            DiscoveryConfig::default(),
        );
        let found = run::drive(
            inner,
            &mut frames,
            &mut discovery,
            DISCOVERY_LIMIT,
            GimbalDiscovery::poll_result,
        )
        .await?;
        let mut gimbals = Vec::with_capacity(found.len());
        for info in found {
            let manager = self.system.at(info.manager).await;
            gimbals.push(Gimbal {
                root: self.system.clone(),
                manager,
                info,
            });
        }
        Ok(gimbals)
    }
}

/// One gimbal of a system: its manager and device (from [`Gimbals::list`]).
#[derive(Clone, Debug)]
pub struct Gimbal {
    root: System,
    manager: System,
    info: GimbalInfo,
}

impl Gimbal {
    /// What its manager says about it: manager and device, capabilities, limits, and the
    /// device's vendor and model when it told them.
    #[must_use]
    pub const fn info(&self) -> &GimbalInfo {
        &self.info
    }

    /// Takes control of it (MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE): primary control leaves
    /// the secondary controller as it is, and the other way round.
    ///
    /// # Errors
    /// [`SystemError::Command`] (refused or unanswered), [`SystemError::Busy`],
    /// [`SystemError::Stopped`].
    pub async fn take_control(&self, secondary: bool) -> Result<(), SystemError> {
        let control = if secondary {
            Control::Secondary
        } else {
            Control::Primary
        };
        let command = self.info.configure(self.manager.own(), control);
        self.manager.commands().send(command).await.map(drop)
    }

    /// Gives up whatever control we have of it.
    ///
    /// # Errors
    /// As [`take_control`](Self::take_control).
    pub async fn release_control(&self) -> Result<(), SystemError> {
        let command = self.info.configure(self.manager.own(), Control::Release);
        self.manager.commands().send(command).await.map(drop)
    }

    /// Points it at `pitch_deg` (positive up) and `yaw_deg` (positive right) in `frame`
    /// (MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW), once the manager accepts.
    ///
    /// # Errors
    /// [`SystemError::Gimbal`] for an angle outside its limits or NaN (nothing is sent);
    /// as [`take_control`](Self::take_control).
    pub async fn set_angles(
        &self,
        pitch_deg: f32,
        yaw_deg: f32,
        frame: YawFrame,
    ) -> Result<(), SystemError> {
        let command = self.info.set_angles(pitch_deg, yaw_deg, frame)?;
        self.manager.commands().send(command).await.map(drop)
    }

    /// Turns it at `pitch_dps` and `yaw_dps` degrees per second.
    ///
    /// # Errors
    /// [`SystemError::Gimbal`] for NaN (nothing is sent); as
    /// [`take_control`](Self::take_control).
    pub async fn set_rates(
        &self,
        pitch_dps: f32,
        yaw_dps: f32,
        frame: YawFrame,
    ) -> Result<(), SystemError> {
        let command = self.info.set_rates(pitch_dps, yaw_dps, frame)?;
        self.manager.commands().send(command).await.map(drop)
    }

    /// Sends one GIMBAL_MANAGER_SET_PITCHYAW (unconfirmed: for setpoints streamed at a
    /// rate): angles in degrees, rates in degrees per second, `None` for "not set".
    ///
    /// # Errors
    /// [`SystemError::Gimbal`] (nothing is sent), [`SystemError::Stopped`].
    pub async fn stream(
        &self,
        angles: (Option<f32>, Option<f32>),
        rates: (Option<f32>, Option<f32>),
        frame: YawFrame,
    ) -> Result<(), SystemError> {
        let m = self.info.pitch_yaw_message(angles, rates, frame)?;
        self.manager
            .send(&MavMessage::GimbalManagerSetPitchyaw(m))
            .await
    }

    /// Keeps it on a location (MAV_CMD_DO_SET_ROI_LOCATION): latitude and longitude in
    /// degrees, altitude in metres above mean sea level.
    ///
    /// # Errors
    /// [`SystemError::Gimbal`] for a location that is not one (nothing is sent); as
    /// [`take_control`](Self::take_control).
    pub async fn point_at(&self, lat: f64, lon: f64, alt_amsl: f32) -> Result<(), SystemError> {
        let command = self.info.point_at(lat, lon, alt_amsl)?;
        self.manager.commands().send(command).await.map(drop)
    }

    /// Stops keeping it on a location (MAV_CMD_DO_SET_ROI_NONE).
    ///
    /// # Errors
    /// As [`take_control`](Self::take_control).
    pub async fn clear_roi(&self) -> Result<(), SystemError> {
        let command = self.info.clear_roi();
        self.manager.commands().send(command).await.map(drop)
    }

    /// Where it looks: its next GIMBAL_DEVICE_ATTITUDE_STATUS (asked for once with
    /// REQUEST_MESSAGE when none came within a second), as degrees in the frame its flags
    /// say (and the yaw in the other frame where its `delta_yaw` gives it).
    ///
    /// # Errors
    /// [`SystemError::Timeout`] when none came within `wait`, [`SystemError::Stopped`].
    pub async fn attitude(&self, wait: Duration) -> Result<Attitude, SystemError> {
        let info = self.info.clone();
        let asked = self.info.manager.component;
        self.next(
            GimbalDeviceAttitudeStatus::ID,
            asked,
            wait,
            move |from, m| match m {
                MavMessage::GimbalDeviceAttitudeStatus(s) if info.owns_status(from, s) => {
                    Attitude::from_status(s)
                }
                _ => None,
            },
        )
        .await
    }

    /// Who controls it: the manager's next GIMBAL_MANAGER_STATUS for its device.
    ///
    /// # Errors
    /// As [`attitude`](Self::attitude).
    pub async fn control(&self, wait: Duration) -> Result<GimbalControl, SystemError> {
        let manager = self.info.manager;
        let device = self.info.device_id;
        let addr = |s: u8, c: u8| (s != 0).then_some(Address::new(s, c));
        self.next(
            GimbalManagerStatus::ID,
            manager.component,
            wait,
            move |from, m| match m {
                MavMessage::GimbalManagerStatus(s)
                    if from == manager
                        && (s.gimbal_device_id == device || s.gimbal_device_id == 0) =>
                {
                    Some(GimbalControl {
                        primary: addr(s.primary_control_sysid, s.primary_control_compid),
                        secondary: addr(s.secondary_control_sysid, s.secondary_control_compid),
                        flags: s.flags.0,
                    })
                }
                _ => None,
            },
        )
        .await
    }

    /// The next message from the system that `pick` takes, asking component `asked` for
    /// message `id` once after [`ASK_AFTER`].
    async fn next<T>(
        &self,
        id: u32,
        asked: u8,
        wait: Duration,
        mut pick: impl FnMut(Address, &MavMessage) -> Option<T>,
    ) -> Result<T, SystemError> {
        let system = self.root.target().system;
        let mut frames = self.root.frames().await;
        let deadline = tokio::time::Instant::now() + wait;
        let mut ask_at = Some(tokio::time::Instant::now() + ASK_AFTER);
        loop {
            let wake = ask_at.map_or(deadline, |a| a.min(deadline));
            tokio::select! {
                () = tokio::time::sleep_until(wake) => {
                    if tokio::time::Instant::now() >= deadline {
                        return Err(SystemError::Timeout { seconds: wait.as_secs_f64() });
                    }
                    if ask_at.take().is_some() {
                        let manager = if asked == self.manager.target().component {
                            &self.manager
                        } else {
                            &self.root
                        };
                        manager.request_once(id).await;
                    }
                }
                incoming = frames.recv() => {
                    let incoming = incoming.ok_or(SystemError::Stopped)?;
                    let f = incoming.frame.frame.view();
                    if f.sysid() != system || f.msg_id() != id {
                        continue;
                    }
                    if let Ok(m) = MavMessage::decode(f.msg_id(), f.payload())
                        && let Some(v) = pick(Address::new(f.sysid(), f.compid()), &m)
                    {
                        return Ok(v);
                    }
                }
            }
        }
    }
}
