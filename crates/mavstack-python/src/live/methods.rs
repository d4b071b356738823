//! `LiveLink`'s Python methods and properties: receiving (`recv_msg`, `recv_match`,
//! `messages`), what pymavlink keeps of the target (`target_system`, `flightmode`,
//! `motors_armed`, the mode mapping), sending (`encode`, `send_fields`, `send`, `write`),
//! signing, closing and the connection's facts and counters.

use core::sync::atomic::Ordering;
use core::time::Duration;
use std::time::Instant;

use mavstack::Node;
use mavstack::channel::SigningConfig;
use mavstack::core::wire::{self, FrameHeader, Version};
use mavstack::modes;
use mavstack::router::LinkId;
use mavstack_core::signing::SecretKey;
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use super::fields::encode_payload;
use super::heartbeat::ardupilot_modes;
use super::receive::{Deadline, Posted, Seconds};
use super::{CUSTOM_MODE_ENABLED, LiveLink, lock, runtime, unix_now};
use crate::message::Message;

#[pymethods]
impl LiveLink {
    /// The next message, or `None` when none has arrived (pymavlink's `recv_msg`: it does
    /// not wait).
    fn recv_msg(&self, py: Python<'_>) -> PyResult<Option<Py<Message>>> {
        let mut rx = lock(py, &self.frames);
        let mut found = None;
        while let Some(i) = self.next_frame(py, &mut rx, false, &mut Deadline::after(None))? {
            if let Posted::Message(m, _) = self.post(py, &mut rx, i, |_| true)? {
                found = Some(m);
                break;
            }
        }
        drop(rx);
        self.materialize(py)?;
        Ok(found)
    }

    /// The next message of the given type(s) for which `condition` holds (a Python
    /// expression over the latest messages of the sender's system, as pymavlink's); with
    /// `blocking`, waiting up to `timeout` seconds (forever without one) with the GIL
    /// released. `None` when nothing matched in time.
    #[pyo3(signature = (condition=None, r#type=None, blocking=false, timeout=None))]
    fn recv_match(
        &self,
        py: Python<'_>,
        condition: Option<&str>,
        r#type: Option<&Bound<'_, PyAny>>,
        blocking: bool,
        timeout: Option<Seconds>,
    ) -> PyResult<Option<Py<Message>>> {
        let deadline = Deadline::after(timeout);
        let mut rx = lock(py, &self.frames);
        let wanted = match r#type {
            Some(t) if !t.is_none() => Some(rx.types.take(&self.dialect, t)?),
            _ => None,
        };
        let found = self.match_next(py, &mut rx, condition, wanted.as_ref(), blocking, deadline);
        if let Some(w) = wanted {
            rx.types.keep(w);
        }
        drop(rx);
        self.materialize(py)?;
        found
    }

    /// The latest message of each type from the target system (pymavlink's `messages`, a
    /// dict by name).
    #[getter]
    fn messages(&self, py: Python<'_>) -> PyResult<Py<PyDict>> {
        self.materialize(py)?;
        Ok(lock(py, &self.state).target(py).messages.clone_ref(py))
    }

    /// The latest messages of each system heard: `{sysid: {name: message}}`.
    fn messages_by_system<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.materialize(py)?;
        let all: Vec<(u8, Py<PyDict>)> = lock(py, &self.state)
            .systems
            .iter()
            .map(|(k, s)| (*k, s.messages.clone_ref(py)))
            .collect();
        let d = PyDict::new(py);
        for (sysid, m) in all {
            d.set_item(sysid, m)?;
        }
        Ok(d)
    }

    /// The target system: the first vehicle heard (0 until then), or what was set.
    #[getter]
    fn get_target_system(&self, py: Python<'_>) -> u8 {
        lock(py, &self.state).sysid
    }

    #[setter]
    fn set_target_system(&self, py: Python<'_>, value: u8) {
        let mut st = lock(py, &self.state);
        st.sysid = value;
        let _ = st.target(py);
    }

    /// The target component (0, every component, until set: as pymavlink).
    #[getter]
    fn get_target_component(&self, py: Python<'_>) -> u8 {
        lock(py, &self.state).target_component
    }

    #[setter]
    fn set_target_component(&self, py: Python<'_>, value: u8) {
        lock(py, &self.state).target_component = value;
    }

    /// The target's flight mode, by name (`"GUIDED"`), from its latest HEARTBEAT.
    #[getter]
    fn flightmode(&self, py: Python<'_>) -> String {
        lock(py, &self.state).target(py).flightmode.clone()
    }

    /// Whether the target's latest HEARTBEAT said armed.
    fn motors_armed(&self, py: Python<'_>) -> bool {
        lock(py, &self.state).target(py).armed
    }

    /// The target's HEARTBEAT `type` (None before one came).
    #[getter]
    fn mav_type(&self, py: Python<'_>) -> Option<u8> {
        lock(py, &self.state).target(py).mav_type
    }

    /// The target's HEARTBEAT `autopilot` (None before one came).
    #[getter]
    fn mav_autopilot(&self, py: Python<'_>) -> Option<u8> {
        lock(py, &self.state).target(py).autopilot
    }

    /// The target's HEARTBEAT `base_mode`.
    #[getter]
    fn base_mode(&self, py: Python<'_>) -> u8 {
        lock(py, &self.state).target(py).base_mode
    }

    /// The target's modes, name → `custom_mode`, for its autopilot and vehicle type (ArduPilot's
    /// by pymavlink's names); `None` before its HEARTBEAT or for an autopilot whose modes are
    /// not known.
    fn mode_mapping<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(flavour) = lock(py, &self.state).flavour(py) else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        for (name, number) in ardupilot_modes(flavour) {
            d.set_item(name, number)?;
        }
        Ok(Some(d))
    }

    /// MAV_CMD_DO_SET_MODE's param1-3 for `mode` (a name, or an ArduPilot mode number) on
    /// the target; `None` for a name it does not have.
    fn mode_params(
        &self,
        py: Python<'_>,
        mode: &Bound<'_, PyAny>,
    ) -> PyResult<Option<(f32, f32, f32)>> {
        let flavour = lock(py, &self.state).flavour(py);
        if let Ok(n) = mode.extract::<u32>() {
            return Ok(Some(match flavour {
                Some(f) => f.command_params(n),
                None => (f32::from(CUSTOM_MODE_ENABLED), n as f32, 0.0),
            }));
        }
        let name: String = mode.extract()?;
        Ok(flavour.and_then(|f| {
            let pymavlink = ardupilot_modes(f)
                .into_iter()
                .find(|(n, _)| *n == name)
                .map(|(_, number)| number);
            pymavlink
                .or_else(|| modes::by_name(f, &name).map(|m| m.custom_mode))
                .map(|number| f.command_params(number))
        }))
    }

    /// A message of `name` from its fields' values in XML order, framed (MAVLink 2) as
    /// this connection's system and component would send it: pymavlink's `*_encode`.
    fn encode(&self, name: &str, args: &Bound<'_, PyTuple>) -> PyResult<Message> {
        let ty = self.message_type(name)?;
        let payload = encode_payload(&ty, args)?;
        let info = self.dialect.table.info(ty.id).ok_or_else(|| {
            PyValueError::new_err(format!("no message id {} in the dialect", ty.id))
        })?;
        let (sysid, compid) = self.handle.identity();
        let header = FrameHeader {
            version: Version::V2,
            seq: self.encode_seq.fetch_add(1, Ordering::Relaxed),
            sysid,
            compid,
            signed: false,
        };
        let mut out = [0u8; wire::MAX_FRAME_LEN];
        let len = wire::emit(&header, info, &payload, &mut out)
            .map_err(|e| PyValueError::new_err(format!("{}: {e}", ty.name)))?;
        Ok(Message::live(ty, &out[..len], unix_now(), false))
    }

    /// Sends message `name` from its fields' values in XML order: pymavlink's `*_send`.
    /// The link frames it in its version (and signs it when it signs).
    fn send_fields(&self, py: Python<'_>, name: &str, args: &Bound<'_, PyTuple>) -> PyResult<()> {
        let ty = self.message_type(name)?;
        let payload = encode_payload(&ty, args)?;
        self.send_payload(py, ty.id, &payload)?;
        Ok(())
    }

    /// Sends `message` (one received or encoded) as this connection's own: pymavlink's
    /// `mav.send`.
    fn send(&self, py: Python<'_>, message: PyRef<'_, Message>) -> PyResult<()> {
        let id = message.message_type().id;
        let payload = message.payload().to_vec();
        drop(message);
        self.send_payload(py, id, &payload)?;
        Ok(())
    }

    /// Writes `data` (whole frames) to every peer of the link as they are: pymavlink's
    /// `write`, what a forwarder does with `get_msgbuf()`.
    fn write(&self, py: Python<'_>, data: &[u8]) -> PyResult<()> {
        let handle = self.node_handle()?.clone();
        let rt = runtime()?;
        let stale = lock(py, &self.peers)
            .1
            .is_none_or(|t| t.elapsed() > Duration::from_secs(1));
        if stale {
            let report = py.detach(|| rt.block_on(handle.report()));
            let mut peers = lock(py, &self.peers);
            if let Some(report) = report {
                for link in report.links.iter().filter_map(|l| l.link_id) {
                    if !peers.0.contains(&link) {
                        peers.0.push(link);
                    }
                }
            }
            peers.1 = Some(Instant::now());
        }
        let peers = lock(py, &self.peers).0.clone();
        let kept: Vec<LinkId> = py.detach(|| {
            rt.block_on(async {
                let mut kept = Vec::new();
                for link in peers {
                    if handle.send_bytes(link, data).await {
                        kept.push(link);
                    }
                }
                kept
            })
        });
        lock(py, &self.peers).0.retain(|l| kept.contains(l));
        Ok(())
    }

    /// Signs every frame sent from now on with `key` (32 bytes) and accepts only signed
    /// frames, but the message ids in `allow_unsigned` (at most 8); `link_id` goes into the
    /// signatures, `initial_timestamp` (10 µs units since 2015) is the least one issued.
    #[pyo3(signature = (key, link_id=0, initial_timestamp=0, allow_unsigned=Vec::new()))]
    fn setup_signing(
        &self,
        py: Python<'_>,
        key: &[u8],
        link_id: u8,
        initial_timestamp: u64,
        allow_unsigned: Vec<u32>,
    ) -> PyResult<()> {
        let key: [u8; 32] = key.try_into().map_err(|_| {
            PyValueError::new_err(format!(
                "secret_key: {} bytes, a signing key is 32 bytes",
                key.len()
            ))
        })?;
        let mut config = SigningConfig::new(SecretKey::new(key), link_id);
        config.initial_timestamp = initial_timestamp;
        if !allow_unsigned.is_empty() {
            config.clear_allowed_unsigned();
            for id in allow_unsigned {
                config
                    .allow_unsigned(id)
                    .map_err(|e| PyValueError::new_err(format!("allow_unsigned_callback: {e}")))?;
            }
        }
        self.apply_signing(py, Some(config))
    }

    /// Stops signing (pymavlink's `disable_signing`).
    fn disable_signing(&self, py: Python<'_>) -> PyResult<()> {
        self.apply_signing(py, None)
    }

    /// Closes the link: queued frames go out, the socket or port closes.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        self.closed.store(true, Ordering::Release);
        let Some(node) = lock(py, &self.node).take() else {
            return Ok(());
        };
        let rt = runtime()?;
        let res = py.detach(|| rt.block_on(node.shutdown()));
        match res {
            Ok(_) => Ok(()),
            Err(e) => Err(PyOSError::new_err(format!("{}: {e}", self.device))),
        }
    }

    /// This connection's own system id (pymavlink's `mav.srcSystem`).
    #[getter]
    fn src_system(&self) -> u8 {
        self.handle.identity().0
    }

    /// This connection's own component id (pymavlink's `mav.srcComponent`).
    #[getter]
    fn src_component(&self) -> u8 {
        self.handle.identity().1
    }

    /// The dialect's name.
    #[getter]
    fn dialect(&self) -> &str {
        &self.dialect.name
    }

    /// The connection string (keys redacted).
    #[getter]
    fn address(&self) -> &str {
        &self.device
    }

    /// For each message of the dialect: its name, and its fields in XML order (pymavlink's
    /// arguments), each with its default (`None`: a required argument; else the value of an
    /// optional one -- 0 for an extension, 3 for HEARTBEAT's `mavlink_version` -- and, for an
    /// array extension, its length: pymavlink's default is that many zeros, `b""` for text,
    /// whose length is given as 0).
    #[allow(clippy::type_complexity)]
    fn message_signatures(&self) -> Vec<(String, Vec<(String, Option<u8>, Option<usize>)>)> {
        self.dialect
            .messages
            .iter()
            .map(|m| {
                let fields = m
                    .fields
                    .iter()
                    .map(|f| {
                        let default = if f.mavlink_version {
                            Some(3)
                        } else if f.extension {
                            Some(0)
                        } else {
                            None
                        };
                        // A text extension's array length is reported as 0: its default is b"".
                        let array = f
                            .array_len
                            .filter(|_| f.extension)
                            .map(|n| if f.is_text() { 0 } else { n });
                        (f.name.clone(), default, array)
                    })
                    .collect();
                (m.name.clone(), fields)
            })
            .collect()
    }

    /// The node's report (links, peers, counters), as text: for diagnosing a link.
    fn report(&self, py: Python<'_>) -> PyResult<String> {
        let handle = self.node_handle()?.clone();
        let rt = runtime()?;
        let finished = lock(py, &self.node).as_ref().is_some_and(Node::is_finished);
        let report = py.detach(|| rt.block_on(handle.report()));
        Ok(format!("finished: {finished}; {report:#?}"))
    }

    /// The ids of the dialect's messages.
    fn message_ids(&self) -> Vec<u32> {
        self.dialect.messages.iter().map(|m| m.id).collect()
    }

    /// Counts: `received` (messages returned or recorded), `unknown_id`.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (received, unknown_id) = {
            let st = lock(py, &self.state);
            (st.received, st.unknown_id)
        };
        let d = PyDict::new(py);
        d.set_item("received", received)?;
        d.set_item("unknown_id", unknown_id)?;
        Ok(d)
    }
}
