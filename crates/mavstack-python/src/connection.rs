//! `mavstack.mavutil.mavlink_connection(path)`: a log read message by message with
//! pymavlink's `recv_match`, `recv_msg`, iteration and `messages`.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use mavstack_core::signing::SecretKey;
use pyo3::exceptions::{
    PyIndexError, PyKeyError, PyNameError, PyOSError, PyTypeError, PyValueError,
    PyZeroDivisionError,
};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PySet, PyString, PyTuple};

use crate::dialect::Dialect;
use crate::log_data::{CHECK_EVERY, Found, LogBytes, Scan, is_tlog};
use crate::message::Message;

/// A key given as 32 bytes or 64 hex digits.
pub(crate) fn parse_key(key: Option<&Bound<'_, PyAny>>) -> PyResult<Option<SecretKey>> {
    let Some(key) = key else { return Ok(None) };
    if key.is_none() {
        return Ok(None);
    }
    if let Ok(b) = key.cast::<PyBytes>() {
        let bytes: [u8; 32] = b.as_bytes().try_into().map_err(|_| {
            PyValueError::new_err(format!(
                "key: {} bytes, a signing key is 32 bytes (or 64 hex digits)",
                b.as_bytes().len()
            ))
        })?;
        return Ok(Some(SecretKey::new(bytes)));
    }
    if let Ok(s) = key.cast::<PyString>() {
        let text = s.to_cow()?;
        return SecretKey::from_hex(text.trim())
            .map(Some)
            .map_err(|e| PyValueError::new_err(format!("key: {e}")));
    }
    Err(PyTypeError::new_err(
        "key: 32 bytes or a string of 64 hex digits",
    ))
}

/// A MAVLink log read message by message, as pymavlink's `mavlogfile`: `.tlog` files by
/// their extension, anything else as raw frames. Bad frames and unknown message ids are
/// counted (`stats()`), never returned.
#[pyclass(module = "mavstack", name = "mavlogfile")]
pub(crate) struct LogConnection {
    path: PathBuf,
    log: Arc<LogBytes>,
    dialect: Arc<Dialect>,
    tlog: bool,
    key: Option<SecretKey>,
    scan: Scan,
    /// The scan position at which the file's length is looked at next.
    next_check: usize,
    /// Latest message per (sysid, message index): pymavlink's `sysid_state[s].messages`.
    by_sysid: HashMap<(u8, usize), Found>,
    /// Latest message per message index: pymavlink's `messages`.
    latest: HashMap<usize, Found>,
    /// Conditions compiled so far and their globals.
    conditions: Conditions,
    /// `recv_match`'s last `type` argument and its mask.
    types: TypeCache,
}

impl LogConnection {
    /// Opens `path` with `dialect`, verifying signatures with `key` when given.
    pub(crate) fn open(path: PathBuf, dialect: &str, key: Option<SecretKey>) -> PyResult<Self> {
        let dialect = Dialect::load(dialect)?;
        let log = LogBytes::open(&path)
            .map_err(|e| PyOSError::new_err(format!("cannot read {}: {e}", path.display())))?;
        let tlog = is_tlog(&path);
        Ok(Self {
            scan: Scan::new(&log, &dialect, tlog, key.clone()),
            next_check: CHECK_EVERY,
            path,
            log,
            dialect,
            tlog,
            key,
            by_sysid: HashMap::new(),
            latest: HashMap::new(),
            conditions: Conditions::default(),
            types: TypeCache::default(),
        })
    }

    fn message(&self, found: &Found) -> Message {
        Message::new(
            Arc::clone(&self.dialect.messages[found.message]),
            Arc::clone(&self.log),
            found.start,
            found.len,
            found.ts_us,
            found.verified,
            self.tlog,
        )
    }

    /// The next good frame, recorded as the latest of its type. `OSError` naming the file
    /// when it was truncated since it was opened (looked at every [`CHECK_EVERY`] bytes and
    /// at the end).
    fn next_found(&mut self) -> PyResult<Option<Found>> {
        let found = self.scan.next(&self.log, &self.dialect);
        if found.is_none() || self.scan.position() >= self.next_check {
            self.next_check = self.scan.position().saturating_add(CHECK_EVERY);
            self.log
                .check_length()
                .map_err(|e| PyOSError::new_err(e.to_string()))?;
        }
        let Some(found) = found else {
            return Ok(None);
        };
        self.by_sysid.insert((found.sysid, found.message), found);
        self.latest.insert(found.message, found);
        Ok(Some(found))
    }

    /// `recv_match`'s loop: the next frame of a type `wanted` marks (any without a mask) for
    /// which `condition` holds.
    fn match_next(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        condition: Option<&str>,
        wanted: Option<&TypeMask>,
    ) -> PyResult<Option<Found>> {
        loop {
            let Some(found) = slf.borrow_mut().next_found()? else {
                return Ok(None);
            };
            if wanted.is_some_and(|w| !w.wants(found.message)) {
                continue;
            }
            if let Some(c) = condition
                && !Self::condition_holds(slf, py, c, found.sysid)?
            {
                continue;
            }
            return Ok(Some(found));
        }
    }

    /// Evaluates `condition` against the latest messages of `sysid`, as pymavlink's
    /// `evaluate_condition`: a NameError, ZeroDivisionError or IndexError is false.
    fn condition_holds(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        condition: &str,
        sysid: u8,
    ) -> PyResult<bool> {
        let (globals, code) = slf.borrow_mut().conditions.prepare(py, condition)?;
        let locals = Bound::new(
            py,
            LatestMessages {
                connection: slf.clone().unbind(),
                sysid: Some(sysid),
            },
        )?;
        eval_condition(py, &globals, &code, locals.as_any())
    }
}

/// `recv_match`'s `type` argument and the message indexes it asks for.
pub(crate) struct TypeMask {
    ty: Py<PyAny>,
    mask: Vec<bool>,
}

impl TypeMask {
    /// Whether the message at `index` of the dialect is one of the types asked for.
    pub(crate) fn wants(&self, index: usize) -> bool {
        self.mask[index]
    }
}

/// The mask of `recv_match`'s last `type` argument, reused while the next call passes the
/// same object or an equal one: a loop calls `recv_match(type="ATTITUDE")` many times with
/// the same string, and building the mask each time would cost a name lookup per call.
#[derive(Default)]
pub(crate) struct TypeCache(Option<TypeMask>);

impl TypeCache {
    /// The mask of `ty`, reused or made; give it back with [`Self::keep`] after the call.
    pub(crate) fn take(&mut self, dialect: &Dialect, ty: &Bound<'_, PyAny>) -> PyResult<TypeMask> {
        if let Some(last) = self.0.take() {
            let same = {
                let was = last.ty.bind(ty.py());
                was.is(ty) || (was.get_type().is(ty.get_type()) && was.eq(ty)?)
            };
            if same {
                return Ok(last);
            }
        }
        Ok(TypeMask {
            ty: ty.clone().unbind(),
            mask: wanted_mask(dialect, ty)?,
        })
    }

    /// Keeps `mask` for the next call.
    pub(crate) fn keep(&mut self, mask: TypeMask) {
        self.0 = Some(mask);
    }
}

/// Which message indexes `type` asks for (a name, or a list, set or tuple of names).
fn wanted_mask(dialect: &Dialect, ty: &Bound<'_, PyAny>) -> PyResult<Vec<bool>> {
    let mut mask = vec![false; dialect.messages.len()];
    let mut add = |name: &Bound<'_, PyAny>| -> PyResult<()> {
        let name: String = name.extract()?;
        if let Some(i) = dialect.index_of_name(&name) {
            mask[i] = true;
        }
        Ok(())
    };
    if ty.is_instance_of::<PyString>() {
        add(ty)?;
    } else if ty.is_instance_of::<PyList>()
        || ty.is_instance_of::<PySet>()
        || ty.is_instance_of::<PyTuple>()
    {
        for name in ty.try_iter()? {
            add(&name?)?;
        }
    } else {
        return Err(PyTypeError::new_err(
            "type: a message name or a list or set of names",
        ));
    }
    Ok(mask)
}

/// The globals conditions are evaluated with (Python's `math`, as pymavlink) and the
/// conditions compiled so far, by their text.
#[derive(Default)]
pub(crate) struct Conditions {
    globals: Option<Py<PyDict>>,
    compiled: HashMap<String, Py<PyAny>>,
}

impl Conditions {
    /// The globals and the compiled code of `condition`.
    pub(crate) fn prepare(
        &mut self,
        py: Python<'_>,
        condition: &str,
    ) -> PyResult<(Py<PyDict>, Py<PyAny>)> {
        let globals = match &self.globals {
            Some(g) => g.clone_ref(py),
            None => {
                let g = PyDict::new(py);
                let math = py.import("math")?;
                for name in math.dir()? {
                    let name: String = name.extract()?;
                    if !name.starts_with('_') {
                        g.set_item(&name, math.getattr(&name)?)?;
                    }
                }
                let g = g.unbind();
                self.globals = Some(g.clone_ref(py));
                g
            }
        };
        let code = match self.compiled.get(condition) {
            Some(c) => c.clone_ref(py),
            None => {
                let c = py
                    .import("builtins")?
                    .getattr("compile")?
                    .call1((condition, "<condition>", "eval"))?
                    .unbind();
                self.compiled.insert(condition.to_owned(), c.clone_ref(py));
                c
            }
        };
        Ok((globals, code))
    }
}

/// Evaluates compiled `code` with `locals` (the latest messages by name), as pymavlink's
/// `evaluate_condition`: a NameError, ZeroDivisionError or IndexError is false.
pub(crate) fn eval_condition(
    py: Python<'_>,
    globals: &Py<PyDict>,
    code: &Py<PyAny>,
    locals: &Bound<'_, PyAny>,
) -> PyResult<bool> {
    let result = py
        .import("builtins")?
        .getattr("eval")?
        .call1((code, globals, locals));
    match result {
        Ok(v) => {
            if v.is_none() {
                Ok(false)
            } else {
                v.is_truthy()
            }
        }
        Err(e)
            if e.is_instance_of::<PyNameError>(py)
                || e.is_instance_of::<PyZeroDivisionError>(py)
                || e.is_instance_of::<PyIndexError>(py) =>
        {
            Ok(false)
        }
        Err(e) => Err(e),
    }
}

#[pymethods]
impl LogConnection {
    /// The next message, or `None` at the end of the log.
    fn recv_msg(&mut self) -> PyResult<Option<Message>> {
        Ok(self.next_found()?.map(|f| self.message(&f)))
    }

    /// The next message of the given type(s) for which `condition` (a Python expression over
    /// the latest messages of the sender's system, as pymavlink: `"ATTITUDE.roll > 0.1"`)
    /// holds; `None` at the end of the log. `blocking` and `timeout` are accepted for
    /// pymavlink's signature: a file has an end, and the end is `None`.
    #[pyo3(signature = (condition=None, r#type=None, blocking=false, timeout=None))]
    fn recv_match(
        slf: &Bound<'_, Self>,
        py: Python<'_>,
        condition: Option<&str>,
        r#type: Option<&Bound<'_, PyAny>>,
        blocking: bool,
        timeout: Option<f64>,
    ) -> PyResult<Option<Message>> {
        let _ = (blocking, timeout);
        let wanted = match r#type {
            Some(t) if !t.is_none() => {
                let mut this = slf.borrow_mut();
                let this = &mut *this;
                Some(this.types.take(&this.dialect, t)?)
            }
            _ => None,
        };
        let found = Self::match_next(slf, py, condition, wanted.as_ref());
        if let Some(w) = wanted {
            slf.borrow_mut().types.keep(w);
        }
        Ok(found?.map(|found| slf.borrow().message(&found)))
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self) -> PyResult<Option<Message>> {
        self.recv_msg()
    }

    /// The latest message of each type (pymavlink's `messages`), read live.
    #[getter]
    fn messages(slf: &Bound<'_, Self>) -> LatestMessages {
        LatestMessages {
            connection: slf.clone().unbind(),
            sysid: None,
        }
    }

    /// How far through the log the reader is, in percent.
    #[getter]
    fn percent(&self) -> f64 {
        if self.log.is_empty() {
            100.0
        } else {
            100.0 * self.scan.position() as f64 / self.log.len() as f64
        }
    }

    /// The dialect's name.
    #[getter]
    fn dialect(&self) -> &str {
        &self.dialect.name
    }

    /// The file's path.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// Counts so far: `frames` (returned or skipped by type), `bad_crc`, `unknown_id`,
    /// `bad_signature`, `signed`, `skipped_bytes`, `bytes` (the file's size).
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.scan.stats;
        let d = PyDict::new(py);
        d.set_item("frames", s.frames)?;
        d.set_item("bad_crc", s.bad_crc)?;
        d.set_item("unknown_id", s.unknown_id)?;
        d.set_item("bad_signature", s.bad_signature)?;
        d.set_item("signed", s.signed)?;
        d.set_item("skipped_bytes", s.skipped_bytes)?;
        d.set_item("bytes", self.log.len())?;
        Ok(d)
    }

    /// Back to the start of the log (counts and latest messages cleared).
    fn rewind(&mut self) {
        self.scan = Scan::new(&self.log, &self.dialect, self.tlog, self.key.clone());
        self.next_check = CHECK_EVERY;
        self.by_sysid.clear();
        self.latest.clear();
    }

    /// Nothing to release early: the log's bytes go with the last message that uses them.
    fn close(&mut self) {}

    fn __enter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(&mut self, _args: &Bound<'_, PyTuple>) -> bool {
        false
    }
}

/// The latest message of each type, by name: a connection's `messages` (all systems), or
/// the locals a condition is evaluated with (one system).
#[pyclass(module = "mavstack", name = "LatestMessages")]
pub(crate) struct LatestMessages {
    connection: Py<LogConnection>,
    sysid: Option<u8>,
}

impl LatestMessages {
    fn lookup(&self, py: Python<'_>, name: &str) -> Option<Message> {
        let c = self.connection.borrow(py);
        let i = c.dialect.index_of_name(name)?;
        let latest = match self.sysid {
            Some(s) => c.by_sysid.get(&(s, i)),
            None => c.latest.get(&i),
        }?;
        Some(c.message(latest))
    }

    fn names(&self, py: Python<'_>) -> Vec<String> {
        let c = self.connection.borrow(py);
        let mut found: Vec<(usize, usize)> = match self.sysid {
            Some(s) => c
                .by_sysid
                .iter()
                .filter(|((sys, _), _)| *sys == s)
                .map(|((_, i), l)| (l.start, *i))
                .collect(),
            None => c.latest.iter().map(|(i, l)| (l.start, *i)).collect(),
        };
        found.sort_unstable();
        found
            .into_iter()
            .map(|(_, i)| c.dialect.messages[i].name.clone())
            .collect()
    }
}

#[pymethods]
impl LatestMessages {
    fn __getitem__(&self, py: Python<'_>, name: &str) -> PyResult<Message> {
        self.lookup(py, name)
            .ok_or_else(|| PyKeyError::new_err(name.to_owned()))
    }

    fn __contains__(&self, py: Python<'_>, name: &str) -> bool {
        self.lookup(py, name).is_some()
    }

    fn __len__(&self, py: Python<'_>) -> usize {
        self.names(py).len()
    }

    fn __iter__<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        PyList::new(py, self.names(py))?
            .try_iter()
            .map(Bound::into_any)
    }

    /// The names, oldest first.
    fn keys(&self, py: Python<'_>) -> Vec<String> {
        self.names(py)
    }

    /// The latest message called `name`, or `default`.
    #[pyo3(signature = (name, default=None))]
    fn get(&self, py: Python<'_>, name: &str, default: Option<Py<PyAny>>) -> Py<PyAny> {
        match self.lookup(py, name) {
            Some(m) => Py::new(py, m).map_or_else(|_| py.None(), Py::into_any),
            None => default.unwrap_or_else(|| py.None()),
        }
    }
}
