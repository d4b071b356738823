//! How frames reach a [`LiveLink`]: in batches from the node ([`BatchSubscription`]), each
//! frame recorded as pymavlink's `post_message` records it before any Python object exists.
//!
//! pymavlink builds a message object for every frame and keeps the latest of each type in
//! `messages`. Here a frame that `recv_match` filters out is only copied into its type's
//! slot of the sender's state ([`RawFrame`], reused) and marked; the marked slots become
//! message objects in the `messages` dicts ([`LiveLink::materialize`]) before Python can
//! look at them: before `recv_match` or `recv_msg` returns, before a condition is evaluated,
//! before the GIL is released to wait, and when `messages` is read. So the dicts hold exactly
//! what pymavlink's would whenever Python code runs, and a stream `recv_match` does not want
//! costs no Python object per frame.

use core::sync::atomic::Ordering;
use core::time::Duration;
use std::time::Instant;

use mavstack::channel::Authentication;
use mavstack::core::wire::MAX_FRAME_LEN;
use mavstack::router::LinkId;
use mavstack::{BatchFrame, BatchSubscription, BatchWait, FrameBatch};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyInt;

use super::heartbeat::{heartbeat_fields, mode_string, probably_vehicle};
use super::{LiveLink, SAFETY_ARMED, SIGNAL_CHECK, State, SystemState, lock, unix_now};
use crate::connection::{TypeCache, TypeMask, eval_condition};
use crate::message::Message;

/// HEARTBEAT's message id, the same in every dialect.
const HEARTBEAT_ID: u32 = 0;

/// The receiving side of a connection: the node's batches and the one being read.
pub(super) struct Receiver {
    frames: BatchSubscription,
    batch: FrameBatch,
    /// The next frame of `batch` to read.
    next: usize,
    /// `time.time()` when `batch` was taken from the node: its messages' `_timestamp`.
    taken_at: f64,
    /// The router link of the last frame (the peers list is looked at when it changes).
    last_link: Option<LinkId>,
    /// The node has stopped.
    closed: bool,
    /// `recv_match`'s last `type` argument and its mask.
    pub(super) types: TypeCache,
}

impl Receiver {
    pub(super) fn new(frames: BatchSubscription) -> Self {
        Self {
            frames,
            batch: FrameBatch::new(),
            next: 0,
            taken_at: 0.0,
            last_link: None,
            closed: false,
            types: TypeCache::default(),
        }
    }
}

/// The latest frame of one type from one system that no message object was made for yet.
pub(super) struct RawFrame {
    bytes: [u8; MAX_FRAME_LEN],
    len: usize,
    timestamp: f64,
    verified: bool,
    /// Newer than what `messages` holds.
    marked: bool,
}

/// A timeout argument in seconds: a float, or an int read without the float object that
/// Python's own conversion would make for it (`timeout=1` is the common spelling).
pub(super) struct Seconds(f64);

impl<'py> FromPyObject<'_, 'py> for Seconds {
    type Error = PyErr;

    fn extract(obj: Borrowed<'_, 'py, PyAny>) -> PyResult<Self> {
        if let Ok(int) = obj.cast::<PyInt>()
            && let Ok(n) = int.extract::<i64>()
        {
            // Seconds as a count: exact far beyond any timeout anyone waits.
            #[allow(clippy::cast_precision_loss)]
            return Ok(Self(n as f64));
        }
        obj.extract::<f64>().map(Self)
    }
}

/// A receive call's timeout. Its deadline is read from the clock only when first needed, at
/// the first wait or the first new batch: most calls find their message waiting and never
/// look. The timeout then runs from that moment, at most one batch's frames after the call.
pub(super) struct Deadline {
    /// Seconds, as given (none: wait forever; negative: no wait).
    timeout: Option<f64>,
    at: Option<Instant>,
}

impl Deadline {
    /// `timeout` seconds (none: wait forever; negative: no wait).
    pub(super) fn after(timeout: Option<Seconds>) -> Self {
        Self {
            timeout: timeout.map(|s| s.0),
            at: None,
        }
    }

    /// The deadline, read from the clock the first time; none for a timeout too long for a
    /// `Duration` (infinity included) or NaN.
    fn get(&mut self) -> Option<Instant> {
        if self.at.is_none() {
            let timeout = self.timeout.filter(|t| !t.is_nan())?;
            let timeout = Duration::try_from_secs_f64(timeout.max(0.0)).ok()?;
            self.at = Instant::now().checked_add(timeout);
        }
        self.at
    }
}

/// What [`LiveLink::post`] made of a frame.
pub(super) enum Posted {
    /// A message id the dialect does not define (counted).
    Unknown,
    /// Recorded, but not wanted: no object was made.
    Recorded,
    /// Wanted: the message (now also the latest of its type) and its sender.
    Message(Py<Message>, u8),
}

impl LiveLink {
    /// The index of the next frame in `rx`'s batch: at once, or (when `blocking`) waiting
    /// until `deadline` with the GIL released. `None` when nothing came in time or the node
    /// has stopped.
    pub(super) fn next_frame(
        &self,
        py: Python<'_>,
        rx: &mut Receiver,
        blocking: bool,
        deadline: &mut Deadline,
    ) -> PyResult<Option<usize>> {
        loop {
            if rx.next < rx.batch.len() {
                rx.next += 1;
                return Ok(Some(rx.next - 1));
            }
            if rx.closed {
                return Ok(None);
            }
            let mut got = rx.frames.wait(&mut rx.batch, Duration::ZERO);
            if got == BatchWait::TimedOut {
                if !blocking {
                    return Ok(None);
                }
                let wait = match deadline.get() {
                    Some(d) => {
                        let now = Instant::now();
                        if d <= now {
                            return Ok(None);
                        }
                        (d - now).min(SIGNAL_CHECK)
                    }
                    None => SIGNAL_CHECK,
                };
                // Other threads may read `messages` while this one waits.
                self.materialize(py)?;
                let (frames, batch) = (&mut rx.frames, &mut rx.batch);
                got = py.detach(|| frames.wait(batch, wait));
            }
            match got {
                BatchWait::Frames => {
                    rx.next = 0;
                    rx.taken_at = unix_now();
                    // A stream of frames the call does not want may never leave a wait to
                    // time out: Ctrl-C is looked at with each batch too (the batch stays for
                    // the next call).
                    py.check_signals()?;
                }
                BatchWait::Closed => rx.closed = true,
                _ => py.check_signals()?,
            }
        }
    }

    /// `recv_match`'s loop: the next message of a type `wanted` marks (any without a mask)
    /// for which `condition` holds.
    pub(super) fn match_next(
        &self,
        py: Python<'_>,
        rx: &mut Receiver,
        condition: Option<&str>,
        wanted: Option<&TypeMask>,
        blocking: bool,
        mut deadline: Deadline,
    ) -> PyResult<Option<Py<Message>>> {
        loop {
            let Some(i) = self.next_frame(py, rx, blocking, &mut deadline)? else {
                return Ok(None);
            };
            // Waiting looks at the deadline; a stream that never lets it wait, at each batch.
            if i == 0 && deadline.get().is_some_and(|d| Instant::now() >= d) {
                rx.next = 0;
                return Ok(None);
            }
            let posted = self.post(py, rx, i, |index| wanted.is_none_or(|w| w.wants(index)))?;
            let Posted::Message(message, sysid) = posted else {
                continue;
            };
            if let Some(c) = condition {
                self.materialize(py)?;
                let (globals, code, locals) = {
                    let mut st = lock(py, &self.state);
                    let (globals, code) = st.conditions.prepare(py, c)?;
                    (globals, code, st.messages_of(py, sysid)?)
                };
                if !eval_condition(py, &globals, &code, locals.bind(py).as_any())? {
                    continue;
                }
            }
            return Ok(Some(message));
        }
    }

    /// Records frame `i` of `rx`'s batch as pymavlink's `post_message` does; when `wanted`
    /// says so for its type index, makes its message (the latest of its type from then on).
    pub(super) fn post(
        &self,
        py: Python<'_>,
        rx: &mut Receiver,
        i: usize,
        wanted: impl Fn(usize) -> bool,
    ) -> PyResult<Posted> {
        let Some(f) = rx.batch.get(i) else {
            return Ok(Posted::Unknown);
        };
        let frame = f.view();
        let Some(index) = self.dialect.index_of_id(frame.msg_id()) else {
            lock(py, &self.state).unknown_id += 1;
            return Ok(Posted::Unknown);
        };
        if rx.last_link != Some(f.link) {
            rx.last_link = Some(f.link);
            let mut peers = lock(py, &self.peers);
            if !peers.0.contains(&f.link) {
                peers.0.push(f.link);
            }
        }
        let verified = matches!(f.auth, Authentication::Verified { .. });
        let (sysid, compid) = (frame.sysid(), frame.compid());
        let ty = &self.dialect.messages[index];
        let heartbeat =
            (frame.msg_id() == HEARTBEAT_ID).then(|| heartbeat_fields(ty, frame.payload()));
        let mut st = lock(py, &self.state);
        st.received += 1;
        let target_unset = st.sysid == 0;
        let types = self.dialect.messages.len();
        let system = st.system(py, sysid);
        if let Some(hb) = heartbeat
            && probably_vehicle(compid, &hb)
        {
            system.flightmode = mode_string(&hb);
            system.armed = hb.base_mode & SAFETY_ARMED != 0;
            system.mav_type = Some(hb.mav_type);
            system.autopilot = Some(hb.autopilot);
            system.base_mode = hb.base_mode;
            if target_unset {
                st.sysid = sysid;
            }
        }
        let system = st.system(py, sysid);
        if !wanted(index) {
            system.mark(types, index, &f, rx.taken_at, verified);
            self.marked.store(true, Ordering::Release);
            return Ok(Posted::Recorded);
        }
        if let Some(Some(raw)) = system.latest.get_mut(index) {
            raw.marked = false;
        }
        let message = Py::new(
            py,
            Message::live(std::sync::Arc::clone(ty), f.bytes, rx.taken_at, verified),
        )?;
        system
            .messages
            .bind(py)
            .set_item(self.names[index].bind(py), &message)?;
        Ok(Posted::Message(message, sysid))
    }

    /// Makes the message objects of the frames recorded without one and puts them in the
    /// `messages` dicts (see the module docs).
    pub(super) fn materialize(&self, py: Python<'_>) -> PyResult<()> {
        if !self.marked.load(Ordering::Acquire) {
            return Ok(());
        }
        let mut st = lock(py, &self.state);
        // Set only with `state` held: nothing is marked between this and the loop's end.
        self.marked.store(false, Ordering::Relaxed);
        for system in st.systems.values_mut() {
            let mut marked = core::mem::take(&mut system.marked);
            for &index in &marked {
                let Some(Some(raw)) = system.latest.get_mut(index) else {
                    continue;
                };
                if !core::mem::take(&mut raw.marked) {
                    continue;
                }
                let message = Message::live(
                    std::sync::Arc::clone(&self.dialect.messages[index]),
                    &raw.bytes[..raw.len],
                    raw.timestamp,
                    raw.verified,
                );
                system
                    .messages
                    .bind(py)
                    .set_item(self.names[index].bind(py), Py::new(py, message)?)?;
            }
            marked.clear();
            system.marked = marked;
        }
        Ok(())
    }
}

impl State {
    /// The state of system `sysid`, made when first needed.
    pub(super) fn system(&mut self, py: Python<'_>, sysid: u8) -> &mut SystemState {
        self.systems
            .entry(sysid)
            .or_insert_with(|| SystemState::new(py))
    }

    /// The latest messages of `sysid` (pymavlink's `sysid_state[sysid].messages`).
    pub(super) fn messages_of(
        &self,
        py: Python<'_>,
        sysid: u8,
    ) -> PyResult<Py<pyo3::types::PyDict>> {
        self.systems
            .get(&sysid)
            .map(|s| s.messages.clone_ref(py))
            .ok_or_else(|| PyRuntimeError::new_err("no state for the sender"))
    }
}

impl SystemState {
    /// Keeps `f` as the latest of type `index` (of `types`) without making its message.
    fn mark(&mut self, types: usize, index: usize, f: &BatchFrame<'_>, at: f64, verified: bool) {
        if self.latest.len() < types {
            self.latest.resize_with(types, || None);
        }
        let raw = self.latest[index].get_or_insert_with(|| {
            Box::new(RawFrame {
                bytes: [0; MAX_FRAME_LEN],
                len: 0,
                timestamp: 0.0,
                verified: false,
                marked: false,
            })
        });
        let len = f.bytes.len().min(MAX_FRAME_LEN);
        raw.bytes[..len].copy_from_slice(&f.bytes[..len]);
        raw.len = len;
        raw.timestamp = at;
        raw.verified = verified;
        if !raw.marked {
            raw.marked = true;
            self.marked.push(index);
        }
    }
}
