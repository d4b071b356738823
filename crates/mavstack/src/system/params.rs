//! [`Params`]: a system's parameters — the whole table (PARAM_REQUEST_LIST, or ArduPilot's
//! packed file over MAVFTP), one read, a set confirmed (typed as the system has it), and a
//! file of values loaded with only what differs set.

use core::time::Duration;

use mavstack_dialects::common::{MavParamType, MavProtocolCapability};
use mavstack_services::ftp::param_pck;
use mavstack_services::param::list::ListFetch;
use mavstack_services::param::{
    Name, Param, ParamClient, ParamConfig, ParamEvent, ParamHandle, ParamRef, Value,
};
use mavstack_transport::clock;

use super::{System, SystemError, run};
use crate::modes::Flavour;

/// How long [`ParamsVia::Auto`] waits for AUTOPILOT_VERSION.
pub const CAPABILITIES_WAIT: Duration = Duration::from_secs(2);

/// Retries of the first MAVFTP request (the open) of [`ParamsVia::Auto`], which can still
/// fall back. (Applied to every request, a transfer through 20 % loss each way gave up
/// half-way about every other time, and the fallback cost three times as long.)
pub const AUTO_FTP_RETRIES: u8 = 3;

/// How long a whole table may take.
const LIST_LIMIT: Duration = Duration::from_secs(600);

/// How long one read or set may take.
const ONE_LIMIT: Duration = Duration::from_secs(30);

/// How the parameter table is fetched ([`Params::get_all_via`]) or a file of values set
/// ([`Params::load`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ParamsVia {
    /// Fetching: MAVFTP (`@PARAM/param.pck`) when the system's AUTOPILOT_VERSION advertises
    /// MAV_PROTOCOL_CAPABILITY_FTP (asked for [`CAPABILITIES_WAIT`] at most), the file's
    /// open tried [`AUTO_FTP_RETRIES`] times more and the transfer once it answered with the
    /// usual retries; PARAM_REQUEST_LIST when it does not, or when the download fails.
    /// Loading: one MAVFTP upload to an ArduPilot that advertises MAVFTP, PARAM_SET
    /// otherwise or for what the upload did not set.
    Auto,
    /// MAVFTP only.
    Ftp,
    /// PARAM_REQUEST_LIST to fetch, PARAM_SET to set: one parameter at a time.
    List,
}

/// The parameters of a system (from [`System::params`]).
#[derive(Clone, Debug)]
pub struct Params {
    system: System,
}

/// One value of a loaded file that differed from the system's.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct Change {
    /// The parameter.
    pub name: Name,
    /// The value asked for, in the parameter's type.
    pub value: Value,
    /// The value it had.
    pub was: Value,
    /// The value it has now, read back (`None`: no longer listed).
    pub now: Option<Value>,
}

impl Change {
    /// Whether the system has the value asked for now.
    #[must_use]
    pub fn set(&self) -> bool {
        self.now.is_some_and(|v| v.same_as(self.value))
    }
}

/// What [`Params::load`] did.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct LoadReport {
    /// The values that differed, and what became of them.
    pub changes: Vec<Change>,
    /// How many values were already in force.
    pub unchanged: usize,
    /// Names the system does not have (skipped).
    pub unknown: Vec<Name>,
    /// How they were set: `nothing to set`, `one MAVFTP upload`, `PARAM_SET`, or `MAVFTP
    /// upload, then PARAM_SET for what it did not set`.
    pub how: &'static str,
}

/// `value` in `current`'s type, as PARAM_SET will carry it: integers exactly (from the f64,
/// not through f32), clamped to their type's range; a REAL32 only within f32's range.
///
/// ```
/// use mavstack::services::param::{Name, Value};
/// use mavstack::system::typed_value;
/// let name = Name::new("RTL_ALT").unwrap();
/// assert_eq!(typed_value(name, Value::I32(0), 16_777_217.0).unwrap(), Value::I32(16_777_217));
/// assert_eq!(typed_value(name, Value::U8(0), 300.0).unwrap(), Value::U8(255));
/// assert!(typed_value(name, Value::F32(0.0), 1e39).is_err());
/// ```
///
/// # Errors
/// [`SystemError::Invalid`]: NaN or a value beyond ±3.4e38 for a REAL32, NaN for an
/// integer, or a type PARAM_SET cannot carry.
pub fn typed_value(name: Name, current: Value, value: f64) -> Result<Value, SystemError> {
    // A REAL32 holds what f32 holds: no infinity, no NaN (an integer type clamps instead).
    if current.param_type() == MavParamType::REAL32 && !(value as f32).is_finite() {
        return Err(SystemError::Invalid(format!(
            "{name}: {value} is not a REAL32 value (beyond ±3.4e38, or not a number)"
        )));
    }
    if value.is_nan() {
        return Err(SystemError::Invalid(format!(
            "{name}: NaN is not a value of its type"
        )));
    }
    Value::F32(value as f32)
        .converted_to(current.param_type())
        .map(|v| match v {
            // Integers straight from the f64, not through f32 (exact to 2^53).
            Value::I32(_) if value.fract() == 0.0 => {
                Value::I32(value.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32)
            }
            Value::U32(_) if value.fract() == 0.0 => {
                Value::U32(value.clamp(0.0, f64::from(u32::MAX)) as u32)
            }
            v => v,
        })
        .ok_or_else(|| SystemError::Invalid(format!("{name} has a type PARAM_SET cannot carry")))
}

impl Params {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    fn client(&self) -> ParamClient {
        let config = ParamConfig {
            retries: self.system.retries(),
            ..ParamConfig::default()
        }
        .for_autopilot(self.system.autopilot());
        ParamClient::new(config, self.system.encoding())
    }

    /// The whole parameter table, by index (PARAM_REQUEST_LIST, missing ones asked for
    /// again).
    ///
    /// # Errors
    /// [`SystemError::Param`] (entries still missing after the retries), [`SystemError::Busy`],
    /// [`SystemError::Timeout`] (10 minutes), [`SystemError::Stopped`].
    pub async fn get_all(&self) -> Result<Vec<(Name, Value)>, SystemError> {
        self.get_all_with_progress(|_, _| {}).await
    }

    /// Like [`get_all`](Self::get_all), telling `progress` (values received, count) each
    /// time more have come.
    ///
    /// # Errors
    /// As [`get_all`](Self::get_all).
    pub async fn get_all_with_progress(
        &self,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Vec<(Name, Value)>, SystemError> {
        let _one = self.system.inner.locks.params.lock().await;
        let mut frames = self.system.frames().await;
        let mut client = self.client();
        let target = self.system.target();
        client
            .fetch_all(clock::now(), target)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        let mut told = (0, 0);
        let result = run::drive(
            &self.system.inner,
            &mut frames,
            &mut client,
            LIST_LIMIT,
            |c| {
                if let Some(ListFetch::Collecting(list)) = c.list_state(target) {
                    let now = (list.count() - list.missing(), list.count());
                    if now != told {
                        told = now;
                        progress(now.0, now.1);
                    }
                }
                let result = core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                    ParamEvent::List { result, .. } => Some(result),
                    _ => None,
                });
                if let Some(Ok(table)) = &result
                    && told != (table.len(), table.len())
                {
                    progress(table.len(), table.len());
                }
                result
            },
        )
        .await?;
        result.map_err(|source| SystemError::Param {
            what: "list".to_owned(),
            source,
        })
    }

    /// The whole table in one MAVFTP download of ArduPilot's packed file,
    /// `@PARAM/param.pck` ([`param_pck`]): the order and types of the file, the same table
    /// as [`get_all`](Self::get_all) gives, in a fraction of the time on a long table. Only
    /// systems whose MAVFTP server has that file (ArduPilot, `mavstack vehicle`) can answer.
    /// `progress` hears (bytes so far, size).
    ///
    /// # Errors
    /// Those of [`Ftp::read`](super::Ftp::read) (no such file: [`SystemError::Ftp`]), and
    /// [`SystemError::ParamFile`] for a file that is not a packed table.
    pub async fn get_all_via_ftp(
        &self,
        progress: impl FnMut(u64, u64),
    ) -> Result<Vec<(Name, Value)>, SystemError> {
        self.via_ftp(progress, None).await
    }

    async fn via_ftp(
        &self,
        progress: impl FnMut(u64, u64),
        first_retries: Option<u8>,
    ) -> Result<Vec<(Name, Value)>, SystemError> {
        let bytes = self
            .system
            .ftp()
            .read_probing(param_pck::PATH, progress, first_retries)
            .await?;
        param_pck::decode(&bytes).map_err(|source| SystemError::ParamFile {
            path: param_pck::PATH,
            source,
        })
    }

    /// The whole table as `via` says, and the way it came ([`ParamsVia::Ftp`] or
    /// [`ParamsVia::List`]): the same table either way (names, values, types). `progress`
    /// hears the way, and (done, total) in bytes of the file or in parameters. A fallback
    /// of [`ParamsVia::Auto`] is logged as a warning with the reason.
    ///
    /// # Errors
    /// Those of [`get_all_via_ftp`](Self::get_all_via_ftp) for [`ParamsVia::Ftp`], of
    /// [`get_all`](Self::get_all) otherwise.
    pub async fn get_all_via(
        &self,
        via: ParamsVia,
        mut progress: impl FnMut(ParamsVia, u64, u64),
    ) -> Result<(Vec<(Name, Value)>, ParamsVia), SystemError> {
        let ftp = match via {
            ParamsVia::Ftp => true,
            ParamsVia::List => false,
            ParamsVia::Auto => self.has_ftp().await,
        };
        if ftp {
            let probe = (via == ParamsVia::Auto).then_some(AUTO_FTP_RETRIES);
            let got = self
                .via_ftp(|done, total| progress(ParamsVia::Ftp, done, total), probe)
                .await;
            match got {
                Ok(table) => return Ok((table, ParamsVia::Ftp)),
                Err(e) if via == ParamsVia::Ftp || matches!(e, SystemError::Stopped) => {
                    return Err(e);
                }
                Err(e) => {
                    tracing::warn!(
                        "MAVFTP failed ({}): PARAM_REQUEST_LIST instead",
                        crate::error_chain(&e)
                    );
                }
            }
        }
        let table = self
            .get_all_with_progress(|done, total| {
                progress(ParamsVia::List, done as u64, total as u64);
            })
            .await?;
        Ok((table, ParamsVia::List))
    }

    /// Whether the system advertises a MAVFTP server (AUTOPILOT_VERSION asked for, up to
    /// [`CAPABILITIES_WAIT`]).
    async fn has_ftp(&self) -> bool {
        self.system
            .capabilities(CAPABILITIES_WAIT)
            .await
            .is_some_and(|c| c.contains(MavProtocolCapability::FTP))
    }

    /// One parameter, read by name.
    ///
    /// # Errors
    /// [`SystemError::Param`] (no answer, or no such parameter), [`SystemError::Stopped`].
    pub async fn get(&self, name: Name) -> Result<Param, SystemError> {
        let _one = self.system.inner.locks.params.lock().await;
        let mut frames = self.system.frames().await;
        let mut client = self.client();
        let handle = client.read(clock::now(), self.system.target(), ParamRef::Name(name));
        self.finish(&mut frames, &mut client, handle, name).await
    }

    /// Sets a parameter to `value` (sent in `value`'s type) and waits for the system's
    /// confirmation; returns the value in force (the system may have clamped or refused it).
    ///
    /// # Errors
    /// [`SystemError::Param`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn set(&self, name: Name, value: Value) -> Result<Param, SystemError> {
        let _one = self.system.inner.locks.params.lock().await;
        let mut frames = self.system.frames().await;
        let mut client = self.client();
        let handle = client
            .set(clock::now(), self.system.target(), name, value)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        self.finish(&mut frames, &mut client, handle, name).await
    }

    /// Sets a parameter to `value` in the type the system has it in (read first: see
    /// [`typed_value`]); returns the parameter before and after.
    ///
    /// # Errors
    /// [`SystemError::Invalid`] for a value its type cannot hold (nothing is sent); those
    /// of [`get`](Self::get) and [`set`](Self::set).
    pub async fn set_typed(&self, name: Name, value: f64) -> Result<(Param, Param), SystemError> {
        let before = self.get(name).await?;
        let typed = typed_value(name, before.value, value)?;
        let after = self.set(name, typed).await?;
        Ok((before, after))
    }

    async fn finish(
        &self,
        frames: &mut crate::node::Subscription,
        client: &mut ParamClient,
        handle: ParamHandle,
        name: Name,
    ) -> Result<Param, SystemError> {
        let result = run::drive(&self.system.inner, frames, client, ONE_LIMIT, |c| {
            core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                ParamEvent::Finished { handle: h, result } if h == handle => Some(result),
                _ => None,
            })
        })
        .await?;
        result.map_err(|source| SystemError::Param {
            what: name.to_string(),
            source,
        })
    }

    /// Sets the parameters of `table` with one MAVFTP upload of ArduPilot's packed file
    /// ([`param_pck::encode_upload`]), then reads the file back and returns the table as the
    /// system has it now. The upload itself has no answer per parameter: ArduPilot converts
    /// each value to its parameter's type and skips names it does not have, silently, so
    /// compare what comes back. At most [`param_pck::MAX_UPLOAD`] bytes (about 5,000
    /// changes); `progress` hears (bytes so far, size) of the upload.
    ///
    /// # Errors
    /// [`SystemError::ParamPack`] for a table too large to pack; those of
    /// [`Ftp::write`](super::Ftp::write) and [`get_all_via_ftp`](Self::get_all_via_ftp).
    pub async fn set_via_ftp(
        &self,
        table: &[(Name, Value)],
        progress: impl FnMut(u64, u64),
    ) -> Result<Vec<(Name, Value)>, SystemError> {
        let bytes = param_pck::encode_upload(table).map_err(|source| SystemError::ParamPack {
            path: param_pck::PATH,
            source,
        })?;
        self.system
            .ftp()
            .write(param_pck::PATH, &bytes, progress)
            .await?;
        self.get_all_via_ftp(|_, _| {}).await
    }

    /// Loads a file of values (`wanted`, as [`mavstack_sim::params::load`](crate::sim)
    /// reads one, or any table): the system's table is fetched, each value converted to its
    /// parameter's type, and only those that differ are set — as `via` says — then read
    /// back, since an upload has no answer per parameter. `progress` hears (done, total) of
    /// the current stage. Names the system does not have are skipped (and logged).
    ///
    /// # Errors
    /// [`SystemError::Invalid`] for a value its parameter's type cannot hold (nothing is
    /// sent); those of [`get_all_via`](Self::get_all_via), [`set`](Self::set) and, with
    /// [`ParamsVia::Ftp`], [`set_via_ftp`](Self::set_via_ftp).
    pub async fn load(
        &self,
        wanted: &[(Name, Value)],
        via: ParamsVia,
        mut progress: impl FnMut(u64, u64),
    ) -> Result<LoadReport, SystemError> {
        let (current, _) = self
            .get_all_via(ParamsVia::Auto, |_, d, t| progress(d, t))
            .await?;
        let mut changes = Vec::new();
        let (mut unchanged, mut unknown) = (0usize, Vec::new());
        for &(name, value) in wanted {
            let Some(&(_, was)) = current.iter().find(|(n, _)| *n == name) else {
                unknown.push(name);
                continue;
            };
            let value = typed_value(name, was, value.as_f64())?;
            if value.same_as(was) {
                unchanged += 1;
            } else {
                changes.push(Change {
                    name,
                    value,
                    was,
                    now: None,
                });
            }
        }
        if !unknown.is_empty() {
            let names: Vec<&str> = unknown.iter().map(Name::as_str).collect();
            tracing::warn!("not on the vehicle, skipped: {}", names.join(", "));
        }
        let how = if changes.is_empty() {
            "nothing to set"
        } else {
            self.set_changes(&mut changes, via, &mut progress).await?
        };
        Ok(LoadReport {
            changes,
            unchanged,
            unknown,
            how,
        })
    }

    /// Sets `changes` as `via` says, filling in what each reads back; how it went.
    async fn set_changes(
        &self,
        changes: &mut [Change],
        via: ParamsVia,
        progress: &mut impl FnMut(u64, u64),
    ) -> Result<&'static str, SystemError> {
        let by_ftp = match via {
            ParamsVia::Ftp => true,
            ParamsVia::List => false,
            ParamsVia::Auto => is_ardupilot(self.system.flavour()) && self.has_ftp().await,
        };
        if by_ftp {
            let table: Vec<(Name, Value)> = changes.iter().map(|c| (c.name, c.value)).collect();
            match self.set_via_ftp(&table, &mut *progress).await {
                Ok(now) => {
                    for c in changes.iter_mut() {
                        c.now = now.iter().find(|(n, _)| *n == c.name).map(|&(_, v)| v);
                    }
                    if via == ParamsVia::Ftp || changes.iter().all(Change::set) {
                        return Ok("one MAVFTP upload");
                    }
                    // An upload has no answer per parameter, and a vehicle may skip some
                    // (ArduPilot 4.7 SITL left RTL_ALT alone in a one-entry file, whoever
                    // sent it): what did not take goes by PARAM_SET.
                    let missed = changes.iter().filter(|c| !c.set()).count();
                    tracing::warn!(
                        "the MAVFTP upload did not set {missed} of {} values: PARAM_SET for those",
                        changes.len()
                    );
                    let mut left: Vec<&mut Change> =
                        changes.iter_mut().filter(|c| !c.set()).collect();
                    self.set_each(&mut left, progress).await?;
                    return Ok("MAVFTP upload, then PARAM_SET for what it did not set");
                }
                Err(e) if via == ParamsVia::Ftp => return Err(e),
                Err(e) => tracing::warn!(
                    "MAVFTP upload failed ({}): PARAM_SET instead",
                    crate::error_chain(&e)
                ),
            }
        }
        let mut all: Vec<&mut Change> = changes.iter_mut().collect();
        self.set_each(&mut all, progress).await?;
        Ok("PARAM_SET")
    }

    /// Sets each of `changes` by PARAM_SET, noting the value confirmed.
    async fn set_each(
        &self,
        changes: &mut [&mut Change],
        progress: &mut impl FnMut(u64, u64),
    ) -> Result<(), SystemError> {
        let total = changes.len() as u64;
        for (i, c) in changes.iter_mut().enumerate() {
            progress(i as u64 + 1, total);
            let p = self.set(c.name, c.value).await?;
            c.now = Some(p.value);
        }
        Ok(())
    }
}

/// Whether `flavour` is one of ArduPilot's (which takes `param.pck` uploads).
const fn is_ardupilot(flavour: Option<Flavour>) -> bool {
    matches!(
        flavour,
        Some(
            Flavour::ArduCopter
                | Flavour::ArduPlane
                | Flavour::ArduRover
                | Flavour::ArduSub
                | Flavour::ArduTracker
        )
    )
}
