//! [`Mission`]: a system's mission, geofence and rally plans — upload (confirmed, or read
//! back when the final MISSION_ACK was lost), download, clear, set the current item — and
//! plans as ground stations write them (QGC WPL: item 0 is home), put in and taken out of
//! each autopilot's convention.

use core::time::Duration;

use mavstack_dialects::common::{MavCmd, MavFrame, MavMissionType, MissionItemInt};
use mavstack_services::mission::transfer::{Download, Upload};
use mavstack_services::mission::{
    BUSY_WAIT, MissionClient, MissionConfig, MissionError, MissionEvent,
};
use mavstack_services::plan::{self, Convention};
use mavstack_transport::clock;

use super::{System, SystemError, run};
use mavstack_core::Message as _;
use mavstack_dialects::common::HomePosition;

/// How long a plan transfer may take.
const TRANSFER_LIMIT: Duration = Duration::from_secs(3600);

/// How long a plan download waits for the system's home (PX4's plans have none).
const HOME_WAIT: Duration = Duration::from_secs(3);

/// The plans of a system (from [`System::mission`]).
#[derive(Clone, Debug)]
pub struct Mission {
    system: System,
}

impl Mission {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    fn config(&self) -> MissionConfig {
        MissionConfig {
            retries: self.system.retries(),
            ..MissionConfig::default()
        }
        .for_autopilot(self.system.autopilot())
    }

    fn client(&self) -> MissionClient {
        MissionClient::new(self.system.own(), self.config())
    }

    /// The convention between a plan and this system: a plan (`as_plan`: item 0 is home,
    /// as QGC WPL files have it) of the MISSION type follows the autopilot's; other plans
    /// (JSON, fences, rally points) go as they are.
    #[must_use]
    pub fn convention(&self, kind: MavMissionType, as_plan: bool) -> Convention {
        if as_plan && kind == MavMissionType::MISSION {
            Convention::of(self.system.autopilot())
        } else {
            Convention::Plain
        }
    }

    /// Uploads `items` as the system's plan of `kind` (mission, fence or rally), as they
    /// are.
    ///
    /// # Errors
    /// [`SystemError::Mission`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn upload(
        &self,
        kind: MavMissionType,
        items: Vec<MissionItemInt>,
    ) -> Result<(), SystemError> {
        self.upload_with_progress(kind, items, |_, _| {}).await
    }

    /// Uploads a plan (item 0: home) of `kind` in the autopilot's convention (see
    /// [`convention`](Self::convention)), telling `progress` (items sent, count).
    ///
    /// # Errors
    /// As [`upload`](Self::upload).
    pub async fn upload_plan(
        &self,
        kind: MavMissionType,
        plan: &[MissionItemInt],
        progress: impl FnMut(usize, usize),
    ) -> Result<usize, SystemError> {
        let items = plan::to_vehicle(self.convention(kind, true), plan);
        let count = items.len();
        self.upload_with_progress(kind, items, progress).await?;
        Ok(count)
    }

    /// Like [`upload`](Self::upload), telling `progress` (items sent, count) each time the
    /// system has asked for more, and (count, count) once it has taken the plan.
    ///
    /// # Errors
    /// As [`upload`](Self::upload).
    pub async fn upload_with_progress(
        &self,
        kind: MavMissionType,
        items: Vec<MissionItemInt>,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<(), SystemError> {
        let count = items.len();
        let mut told = (0, 0);
        let event = {
            let _one = self.system.inner.locks.mission.lock().await;
            let mut frames = self.system.frames().await;
            let mut client = self.client();
            client
                .upload(clock::now(), self.system.target(), kind, items.clone())
                .map_err(|e| SystemError::Busy(e.to_string()))?;
            let mut warned_busy = false;
            run::drive(
                &self.system.inner,
                &mut frames,
                &mut client,
                TRANSFER_LIMIT,
                |c| {
                    let now = match c.upload_state() {
                        Some(Upload::AwaitingRequest(u)) => {
                            if u.refused_as_busy() && !warned_busy {
                                warned_busy = true;
                                tracing::warn!(
                                    "mission upload: the vehicle refused to start it as busy \
                                     (another transfer open); asking again for up to {} s",
                                    BUSY_WAIT.as_secs()
                                );
                            }
                            (u.sent(), u.count())
                        }
                        Some(Upload::AwaitingAck(u)) => (u.count(), u.count()),
                        None => told,
                    };
                    if now != told {
                        told = now;
                        progress(now.0, now.1);
                    }
                    c.poll_event()
                },
            )
            .await?
        };
        let result = match event {
            MissionEvent::Uploaded {
                result: Err(MissionError::Unconfirmed { result }),
                ..
            } => {
                // The final ACK was lost; what the vehicle holds tells whether it took the
                // plan: all of it, or only its end where the vehicle stored the rest as it
                // asked for it.
                let first = self.config().readback_from(kind, items.len());
                tracing::info!(
                    "mission upload: the final MISSION_ACK was lost ({result:?} to the last \
                     item sent again): reading the plan back from item {first}"
                );
                let back = self.download_items(kind, first, |_, _| {}).await?;
                if plan::same_from(&items, usize::from(first), &back) {
                    Ok(())
                } else {
                    Err(MissionError::Rejected { result })
                }
            }
            MissionEvent::Uploaded { result, .. } => result,
            _ => return Err(unexpected("upload")),
        };
        // The last request and the ACK may come in one turn, the states between them never
        // seen: a finished upload always ends its progress at the count.
        if result.is_ok() && told != (count, count) {
            progress(count, count);
        }
        result.map_err(|source| SystemError::Mission {
            what: "upload",
            source,
        })
    }

    /// Downloads the system's plan of `kind`, as it is.
    ///
    /// # Errors
    /// [`SystemError::Mission`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn download(&self, kind: MavMissionType) -> Result<Vec<MissionItemInt>, SystemError> {
        self.download_with_progress(kind, |_, _| {}).await
    }

    /// Downloads the system's plan of `kind` as a plan (item 0: home; see
    /// [`convention`](Self::convention)): PX4's home, which is not in its plan, is asked for.
    ///
    /// # Errors
    /// As [`download`](Self::download).
    pub async fn download_plan(
        &self,
        kind: MavMissionType,
        progress: impl FnMut(usize, usize),
    ) -> Result<Vec<MissionItemInt>, SystemError> {
        let items = self.download_with_progress(kind, progress).await?;
        let convention = self.convention(kind, true);
        let home = if convention == Convention::Px4 {
            self.home_item(HOME_WAIT).await
        } else {
            None
        };
        Ok(plan::from_vehicle(convention, &items, home))
    }

    /// Like [`download`](Self::download), telling `progress` (items received, count) as
    /// they come.
    ///
    /// # Errors
    /// As [`download`](Self::download).
    pub async fn download_with_progress(
        &self,
        kind: MavMissionType,
        progress: impl FnMut(usize, usize),
    ) -> Result<Vec<MissionItemInt>, SystemError> {
        self.download_items(kind, 0, progress).await
    }

    /// Downloads the items of the plan of `kind` from `first` on, telling `progress`.
    async fn download_items(
        &self,
        kind: MavMissionType,
        first: u16,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Vec<MissionItemInt>, SystemError> {
        let _one = self.system.inner.locks.mission.lock().await;
        let mut frames = self.system.frames().await;
        let mut client = self.client();
        client
            .download_from(clock::now(), self.system.target(), kind, first)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        let mut told = (0, 0);
        let event = run::drive(
            &self.system.inner,
            &mut frames,
            &mut client,
            TRANSFER_LIMIT,
            |c| {
                if let Some(Download::AwaitingItem(d)) = c.download_state() {
                    let now = (usize::from(d.seq), usize::from(d.count()));
                    if now != told {
                        told = now;
                        progress(now.0, now.1);
                    }
                }
                c.poll_event()
            },
        )
        .await?;
        match event {
            MissionEvent::Downloaded { result, .. } => {
                if let Ok(items) = &result
                    && told != (items.len(), items.len())
                {
                    progress(items.len(), items.len());
                }
                result.map_err(|source| SystemError::Mission {
                    what: "download",
                    source,
                })
            }
            _ => Err(unexpected("download")),
        }
    }

    /// Clears the system's plan of `kind`.
    ///
    /// # Errors
    /// [`SystemError::Mission`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn clear(&self, kind: MavMissionType) -> Result<(), SystemError> {
        self.simple(
            "clear",
            |c, s| c.clear(clock::now(), s.target(), kind),
            |e| match e {
                MissionEvent::Cleared { result, .. } => Some(result),
                _ => None,
            },
        )
        .await
    }

    /// Makes mission item `seq` the current one.
    ///
    /// # Errors
    /// [`SystemError::Mission`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn set_current(&self, seq: u16) -> Result<(), SystemError> {
        self.simple(
            "set current",
            |c, s| c.set_current(clock::now(), s.target(), seq),
            |e| match e {
                MissionEvent::CurrentSet { result, .. } => Some(result),
                _ => None,
            },
        )
        .await
    }

    /// Runs the operation `what`, started by `start`, to its event; `pick` takes its result.
    async fn simple<E: core::fmt::Display>(
        &self,
        what: &'static str,
        start: impl FnOnce(&mut MissionClient, &System) -> Result<(), E>,
        pick: impl FnOnce(MissionEvent) -> Option<Result<(), MissionError>>,
    ) -> Result<(), SystemError> {
        let _one = self.system.inner.locks.mission.lock().await;
        let mut frames = self.system.frames().await;
        let mut client = self.client();
        start(&mut client, &self.system).map_err(|e| SystemError::Busy(e.to_string()))?;
        let event = run::drive(
            &self.system.inner,
            &mut frames,
            &mut client,
            TRANSFER_LIMIT,
            MissionClient::poll_event,
        )
        .await?;
        pick(event)
            .ok_or_else(|| unexpected(what))?
            .map_err(|source| SystemError::Mission { what, source })
    }

    /// Its home as a plan's item 0 (a NAV_WAYPOINT in MAV_FRAME_GLOBAL at home's latitude,
    /// longitude and altitude above mean sea level): HOME_POSITION asked for when not seen
    /// yet, awaited up to `wait`; `None` when it never came.
    pub async fn home_item(&self, wait: Duration) -> Option<MissionItemInt> {
        if self.system.state().home.is_none() {
            self.system.request_once(HomePosition::ID).await;
            self.system.wait_state(wait, |s| s.home.is_some()).await;
        }
        let home = self.system.state().home?;
        Some(MissionItemInt {
            frame: MavFrame::GLOBAL,
            command: MavCmd::NAV_WAYPOINT,
            autocontinue: 1,
            x: home.latitude,
            y: home.longitude,
            z: home.altitude as f32 / 1000.0,
            ..MissionItemInt::default()
        })
    }
}

fn unexpected(what: &'static str) -> SystemError {
    SystemError::Busy(format!(
        "{what}: the mission client reported another operation"
    ))
}
