//! One message of a log as Python sees it: pymavlink's `MAVLink_message` methods and
//! attributes over the frame's bytes, each field decoded when it is read.

use std::sync::Arc;

use mavstack_core::wire::{Frame, MAX_FRAME_LEN, Version};
use mavstack_xml::PrimitiveType;
use pyo3::exceptions::PyAttributeError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyByteArray, PyDict, PyList, PyString};

use crate::dialect::{FieldLayout, MessageType};
use crate::log_data::LogBytes;

/// `N` bytes of `payload` from `at`, zero where the payload is shorter (MAVLink 2 truncation,
/// or extensions a MAVLink 1 frame does not carry).
#[inline]
pub(crate) fn bytes_at<const N: usize>(payload: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    if let Some(s) = payload.get(at..) {
        let n = s.len().min(N);
        out[..n].copy_from_slice(&s[..n]);
    }
    out
}

/// The bytes of a `char[N]` field up to its first NUL (zero-extended past the payload).
fn text_bytes<'a>(f: &FieldLayout, payload: &'a [u8]) -> &'a [u8] {
    let end = payload.len().min(f.offset + f.count());
    let raw = payload.get(f.offset..end).unwrap_or_default();
    mavstack_core::text::until_nul(raw)
}

/// One element of a field as a Python int or float.
fn scalar<'py>(
    py: Python<'py>,
    primitive: PrimitiveType,
    payload: &[u8],
    at: usize,
) -> PyResult<Bound<'py, PyAny>> {
    Ok(match primitive {
        PrimitiveType::U8 | PrimitiveType::Char => {
            bytes_at::<1>(payload, at)[0].into_pyobject(py)?.into_any()
        }
        PrimitiveType::I8 => i8::from_le_bytes(bytes_at(payload, at))
            .into_pyobject(py)?
            .into_any(),
        PrimitiveType::U16 => u16::from_le_bytes(bytes_at(payload, at))
            .into_pyobject(py)?
            .into_any(),
        PrimitiveType::I16 => i16::from_le_bytes(bytes_at(payload, at))
            .into_pyobject(py)?
            .into_any(),
        PrimitiveType::U32 => u32::from_le_bytes(bytes_at(payload, at))
            .into_pyobject(py)?
            .into_any(),
        PrimitiveType::I32 => i32::from_le_bytes(bytes_at(payload, at))
            .into_pyobject(py)?
            .into_any(),
        PrimitiveType::U64 => u64::from_le_bytes(bytes_at(payload, at))
            .into_pyobject(py)?
            .into_any(),
        PrimitiveType::I64 => i64::from_le_bytes(bytes_at(payload, at))
            .into_pyobject(py)?
            .into_any(),
        PrimitiveType::F32 => f64::from(f32::from_le_bytes(bytes_at(payload, at)))
            .into_pyobject(py)?
            .into_any(),
        PrimitiveType::F64 => f64::from_le_bytes(bytes_at(payload, at))
            .into_pyobject(py)?
            .into_any(),
    })
}

/// A field's value as pymavlink gives it: `char[N]` as `str` (cut at the first NUL, bytes
/// that are not ASCII as U+FFFD, pymavlink's `decode("ascii", errors="replace")`), other
/// arrays as lists, scalars as int or float.
pub(crate) fn field_value<'py>(
    py: Python<'py>,
    f: &FieldLayout,
    payload: &[u8],
) -> PyResult<Bound<'py, PyAny>> {
    if f.is_text() {
        let text: String = text_bytes(f, payload)
            .iter()
            .map(|&b| {
                if b.is_ascii() {
                    char::from(b)
                } else {
                    '\u{fffd}'
                }
            })
            .collect();
        return Ok(PyString::new(py, &text).into_any());
    }
    match f.array_len {
        None => scalar(py, f.primitive, payload, f.offset),
        Some(n) => {
            let size = f.primitive.size();
            let items = (0..n)
                .map(|i| scalar(py, f.primitive, payload, f.offset + i * size))
                .collect::<PyResult<Vec<_>>>()?;
            Ok(PyList::new(py, items)?.into_any())
        }
    }
}

/// pymavlink's `MAVLink_header`: the frame's header fields.
#[pyclass(module = "mavstack", name = "MAVLinkHeader", frozen, get_all)]
pub(crate) struct Header {
    #[pyo3(name = "msgId")]
    msg_id: u32,
    incompat_flags: u8,
    compat_flags: u8,
    mlen: u8,
    seq: u8,
    #[pyo3(name = "srcSystem")]
    src_system: u8,
    #[pyo3(name = "srcComponent")]
    src_component: u8,
}

#[pymethods]
impl Header {
    fn __repr__(&self) -> String {
        format!(
            "MAVLinkHeader(msgId={}, incompat_flags={}, compat_flags={}, mlen={}, seq={}, srcSystem={}, srcComponent={})",
            self.msg_id,
            self.incompat_flags,
            self.compat_flags,
            self.mlen,
            self.seq,
            self.src_system,
            self.src_component
        )
    }
}

/// The longest frame a live message keeps inside itself: most telemetry (ATTITUDE and
/// GLOBAL_POSITION_INT are 40 bytes in MAVLink 2) fits, so the object stays small; a longer
/// frame is boxed.
const INLINE_FRAME: usize = 80;

/// Where a [`Message`]'s frame is: in the log it was read from (shared, not copied), in the
/// message itself (a live link's frame of up to [`INLINE_FRAME`] bytes: no allocation of its
/// own), or boxed (a longer one).
enum FrameBytes {
    Log {
        log: Arc<LogBytes>,
        start: usize,
        len: usize,
    },
    Inline {
        buf: [u8; INLINE_FRAME],
        len: u8,
    },
    Boxed(Box<[u8]>),
}

impl FrameBytes {
    /// A copy of `frame` (at most a MAVLink frame's length of it).
    fn copy_of(frame: &[u8]) -> Self {
        let frame = &frame[..frame.len().min(MAX_FRAME_LEN)];
        match u8::try_from(frame.len()) {
            Ok(len) if frame.len() <= INLINE_FRAME => {
                let mut buf = [0; INLINE_FRAME];
                buf[..frame.len()].copy_from_slice(frame);
                Self::Inline { buf, len }
            }
            _ => Self::Boxed(frame.into()),
        }
    }

    /// The frame's bytes.
    fn get(&self) -> &[u8] {
        match self {
            Self::Log { log, start, len } => &log[*start..*start + *len],
            Self::Inline { buf, len } => &buf[..usize::from(*len)],
            Self::Boxed(b) => b,
        }
    }
}

/// One MAVLink message read from a log, with pymavlink's methods and attributes: fields as
/// attributes (`m.roll`), `get_type()`, `get_srcSystem()`, `get_seq()`, `_timestamp`,
/// `to_dict()` and the rest. Fields are decoded from the frame's bytes when read.
#[pyclass(module = "mavstack", name = "MAVLinkMessage")]
pub(crate) struct Message {
    ty: Arc<MessageType>,
    bytes: FrameBytes,
    verified: bool,
    /// The tlog timestamp in seconds since the Unix epoch (0.0 in a raw log).
    #[pyo3(get, set, name = "_timestamp")]
    timestamp: f64,
    /// The link number MAVProxy keeps in a tlog timestamp's low two bits.
    #[pyo3(get, name = "_link")]
    link: u8,
}

impl Message {
    /// The message of the frame at `start..start + len` of `log`.
    pub(crate) fn new(
        ty: Arc<MessageType>,
        log: Arc<LogBytes>,
        start: usize,
        len: usize,
        ts_us: u64,
        verified: bool,
        tlog: bool,
    ) -> Self {
        Self {
            ty,
            bytes: FrameBytes::Log { log, start, len },
            verified,
            // pymavlink: `tusec * 1.0e-6`, the same floating-point operation.
            timestamp: if tlog { ts_us as f64 * 1.0e-6 } else { 0.0 },
            link: (ts_us & 3) as u8,
        }
    }

    /// A message received on a live link (or encoded to be sent): the whole frame in
    /// `frame`, `timestamp` its arrival in seconds since the Unix epoch (pymavlink's
    /// `time.time()` at receipt), `verified` whether its signature was checked with a key.
    pub(crate) fn live(ty: Arc<MessageType>, frame: &[u8], timestamp: f64, verified: bool) -> Self {
        Self {
            ty,
            bytes: FrameBytes::copy_of(frame),
            verified,
            timestamp,
            link: 0,
        }
    }

    /// The message's type.
    pub(crate) fn message_type(&self) -> &Arc<MessageType> {
        &self.ty
    }

    /// The payload as received (MAVLink 2: possibly truncated).
    pub(crate) fn payload(&self) -> &[u8] {
        let f = self.frame();
        let header = match f.version() {
            Version::V1 => mavstack_core::wire::HEADER_LEN_V1,
            Version::V2 => mavstack_core::wire::HEADER_LEN_V2,
        };
        &self.bytes.get()[header..header + f.payload_len()]
    }

    fn frame(&self) -> Frame<&[u8]> {
        Frame::new_unchecked(self.bytes.get())
    }

    fn value<'py>(&self, py: Python<'py>, f: &FieldLayout) -> PyResult<Bound<'py, PyAny>> {
        field_value(py, f, self.frame().payload())
    }

    fn formatted(&self, py: Python<'_>) -> String {
        let frame = self.frame();
        let payload = frame.payload();
        let mut out = format!("{} {{", self.ty.name);
        for (i, f) in self.ty.fields.iter().enumerate() {
            if i > 0 {
                out.push_str(", ");
            }
            out.push_str(&f.name);
            out.push_str(" : ");
            let v = field_value(py, f, payload).and_then(|v| v.str().map(|s| s.to_string()));
            out.push_str(&v.unwrap_or_default());
        }
        out.push('}');
        out
    }
}

#[pymethods]
impl Message {
    /// The message's name, e.g. `"ATTITUDE"`.
    fn get_type(&self) -> &str {
        &self.ty.name
    }

    /// The message id.
    #[allow(non_snake_case)]
    fn get_msgId(&self) -> u32 {
        self.ty.id
    }

    /// The sender's system id.
    #[allow(non_snake_case)]
    fn get_srcSystem(&self) -> u8 {
        self.frame().sysid()
    }

    /// The sender's component id.
    #[allow(non_snake_case)]
    fn get_srcComponent(&self) -> u8 {
        self.frame().compid()
    }

    /// The frame's sequence number.
    fn get_seq(&self) -> u8 {
        self.frame().seq()
    }

    /// Whether the frame's signature was verified with the key given to the reader (as
    /// pymavlink: without a key, `False` even for signed frames).
    fn get_signed(&self) -> bool {
        self.verified
    }

    /// The signature's link id of a verified frame, else `None`.
    fn get_link_id(&self) -> Option<u8> {
        if self.verified {
            self.frame().signature().map(|s| s.link_id)
        } else {
            None
        }
    }

    /// The whole frame, as received.
    fn get_msgbuf<'py>(&self, py: Python<'py>) -> Bound<'py, PyByteArray> {
        PyByteArray::new(py, self.frame().as_bytes())
    }

    /// The payload as received (MAVLink 2: possibly truncated).
    fn get_payload<'py>(&self, py: Python<'py>) -> Bound<'py, PyByteArray> {
        PyByteArray::new(py, self.frame().payload())
    }

    /// The frame's checksum.
    fn get_crc(&self) -> u16 {
        self.frame().checksum()
    }

    /// The header fields.
    fn get_header(&self) -> Header {
        let f = self.frame();
        let v2 = f.version() == Version::V2;
        Header {
            msg_id: f.msg_id(),
            incompat_flags: if v2 { f.incompat_flags() } else { 0 },
            compat_flags: if v2 { f.compat_flags() } else { 0 },
            mlen: f.payload_len() as u8,
            seq: f.seq(),
            src_system: f.sysid(),
            src_component: f.compid(),
        }
    }

    /// The field names in XML order.
    fn get_fieldnames(&self) -> Vec<&str> {
        self.ty.fields.iter().map(|f| f.name.as_str()).collect()
    }

    /// The field names in XML order (pymavlink's attribute).
    #[getter(_fieldnames)]
    fn fieldnames_attr(&self) -> Vec<&str> {
        self.get_fieldnames()
    }

    /// The field names in XML order (pymavlink's class attribute).
    #[getter(fieldnames)]
    fn class_fieldnames(&self) -> Vec<&str> {
        self.get_fieldnames()
    }

    /// The field names in wire order.
    #[getter]
    fn ordered_fieldnames(&self) -> Vec<&str> {
        self.ty
            .wire_order
            .iter()
            .map(|&i| self.ty.fields[i].name.as_str())
            .collect()
    }

    /// The message's name (pymavlink's `_type`).
    #[getter(_type)]
    fn type_attr(&self) -> &str {
        &self.ty.name
    }

    /// The message's name (pymavlink's class attribute `msgname`).
    #[getter]
    fn msgname(&self) -> &str {
        &self.ty.name
    }

    /// The message id (pymavlink's class attribute `id`), or, as in pymavlink, the field
    /// called `id` of a message that has one (LOG_DATA, ...).
    #[getter]
    fn id<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match self.ty.field("id") {
            Some(f) => self.value(py, f),
            None => Ok(self.ty.id.into_pyobject(py)?.into_any()),
        }
    }

    /// The MAVLink version of the frame: 1 or 2.
    #[getter(_version)]
    fn version(&self) -> u8 {
        match self.frame().version() {
            Version::V1 => 1,
            Version::V2 => 2,
        }
    }

    /// A field's value as `to_dict` gives it.
    fn format_attr<'py>(&self, py: Python<'py>, field: &str) -> PyResult<Bound<'py, PyAny>> {
        self.__getattr__(py, field)
    }

    /// `{"mavpackettype": name, field: value, ...}`, fields in XML order, as pymavlink.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("mavpackettype", &self.ty.name)?;
        let frame = self.frame();
        let payload = frame.payload();
        for f in &self.ty.fields {
            d.set_item(&f.name, field_value(py, f, payload)?)?;
        }
        Ok(d)
    }

    /// `to_dict()` as JSON.
    fn to_json(&self, py: Python<'_>) -> PyResult<String> {
        let d = self.to_dict(py)?;
        py.import("json")?
            .call_method1("dumps", (d,))?
            .extract::<String>()
    }

    /// Fields first (as pymavlink's instance attributes shadow its class's), without the
    /// failed generic lookup and its exception that `__getattr__` alone would cost; every
    /// other name through `object.__getattribute__`.
    fn __getattribute__<'py>(
        slf: &Bound<'py, Self>,
        name: &Bound<'py, PyString>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let py = slf.py();
        {
            let me = slf.borrow();
            if let Some(f) = me.ty.field_named(name) {
                return me.value(py, f);
            }
        }
        static GENERIC: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
        let generic = GENERIC.get_or_try_init(py, || {
            py.import("builtins")?
                .getattr("object")?
                .getattr("__getattribute__")
                .map(Bound::unbind)
        })?;
        generic.bind(py).call1((slf, name))
    }

    fn __getattr__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        match self.ty.field(name) {
            Some(f) => self.value(py, f),
            None => Err(PyAttributeError::new_err(format!(
                "{} message has no field {name:?}",
                self.ty.name
            ))),
        }
    }

    fn __dir__(&self) -> Vec<String> {
        let mut names: Vec<String> = self.ty.fields.iter().map(|f| f.name.clone()).collect();
        for m in [
            "get_type",
            "get_msgId",
            "get_srcSystem",
            "get_srcComponent",
            "get_seq",
            "get_signed",
            "get_link_id",
            "get_msgbuf",
            "get_payload",
            "get_crc",
            "get_header",
            "get_fieldnames",
            "format_attr",
            "to_dict",
            "to_json",
            "fieldnames",
            "ordered_fieldnames",
            "msgname",
            "id",
            "_timestamp",
            "_link",
            "_type",
            "_fieldnames",
            "_version",
        ] {
            names.push(m.to_owned());
        }
        names
    }

    fn __str__(&self, py: Python<'_>) -> String {
        self.formatted(py)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        self.formatted(py)
    }

    /// As pymavlink: the same type, checksum, sequence, sender and field values.
    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        let Ok(other) = other.cast::<Self>() else {
            return false;
        };
        let other = other.borrow();
        let (a, b) = (self.frame(), other.frame());
        self.ty.id == other.ty.id
            && self.ty.name == other.ty.name
            && a.checksum() == b.checksum()
            && a.seq() == b.seq()
            && a.sysid() == b.sysid()
            && a.compid() == b.compid()
            && payload_equal(a.payload(), b.payload())
    }
}

/// Whether two payloads decode to the same fields (trailing zeros do not count).
fn payload_equal(a: &[u8], b: &[u8]) -> bool {
    let n = a.len().max(b.len());
    (0..n).all(|i| a.get(i).copied().unwrap_or(0) == b.get(i).copied().unwrap_or(0))
}
