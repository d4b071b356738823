//! `mavstack.read_tlog(path)`: one Arrow table per message type, through the Arrow C stream
//! interface (`__arrow_c_stream__`), so pyarrow, polars and pandas take the columns without
//! a copy.
//!
//! One pass over the log (checksums, signatures) notes where each good frame of each type is:
//! 8 bytes a frame. Each table then decodes its frames in batches straight from the mapped
//! file when it is consumed, so memory holds that index and one batch, not the log.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use arrow_array::builder::{BooleanBufferBuilder, StringBuilder};
use arrow_array::ffi_stream::FFI_ArrowArrayStream;
use arrow_array::types::{
    ArrowPrimitiveType, Float32Type, Float64Type, Int8Type, Int16Type, Int32Type, Int64Type,
    UInt8Type, UInt16Type, UInt32Type, UInt64Type,
};
use arrow_array::{
    ArrayRef, BooleanArray, FixedSizeListArray, PrimitiveArray, RecordBatch, RecordBatchReader,
};
use arrow_schema::{ArrowError, DataType, Field, Schema, SchemaRef};
use mavstack_core::text::until_nul;
use mavstack_core::tlog::TIMESTAMP_LEN;
use mavstack_core::wire::Frame;
use mavstack_xml::PrimitiveType;
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyCapsule, PyDict};

use crate::connection::parse_key;
use crate::dialect::{Dialect, FieldLayout, MessageType};
use crate::log_data::{LogBytes, Scan, is_tlog};
use crate::message::bytes_at;

/// Rows per record batch.
const BATCH_ROWS: usize = 65_536;

/// The Arrow type of one element of a field.
const fn element_type(p: PrimitiveType) -> DataType {
    match p {
        PrimitiveType::U8 => DataType::UInt8,
        PrimitiveType::I8 => DataType::Int8,
        PrimitiveType::U16 => DataType::UInt16,
        PrimitiveType::I16 => DataType::Int16,
        PrimitiveType::U32 => DataType::UInt32,
        PrimitiveType::I32 => DataType::Int32,
        PrimitiveType::U64 => DataType::UInt64,
        PrimitiveType::I64 => DataType::Int64,
        PrimitiveType::F32 => DataType::Float32,
        PrimitiveType::F64 => DataType::Float64,
        PrimitiveType::Char => DataType::Utf8,
    }
}

/// The schema of a message's table (`docs/contracts/python-api.md`): `timestamp_us`, `sysid`,
/// `compid`, `seq`, `signed`, then the fields in wire order, each with its XML `units` as
/// field metadata.
fn schema(ty: &MessageType) -> Schema {
    let mut fields = vec![
        Field::new("timestamp_us", DataType::Int64, false),
        Field::new("sysid", DataType::UInt8, false),
        Field::new("compid", DataType::UInt8, false),
        Field::new("seq", DataType::UInt8, false),
        Field::new("signed", DataType::Boolean, false),
    ];
    for &i in &ty.wire_order {
        let f = &ty.fields[i];
        let element = element_type(f.primitive);
        let data_type = match f.array_len {
            Some(n) if !f.is_text() => DataType::FixedSizeList(
                Arc::new(Field::new("item", element, false)),
                i32::try_from(n).unwrap_or(i32::MAX),
            ),
            _ => element,
        };
        let mut field = Field::new(&f.name, data_type, false);
        if let Some(units) = &f.units {
            field = field.with_metadata(HashMap::from([("units".to_owned(), units.clone())]));
        }
        fields.push(field);
    }
    Schema::new(fields)
}

/// Rows copied into the row buffer at a time: a few tens of kilobytes, so the columns are
/// filled from cache rather than from frames scattered over the log.
const CHUNK_ROWS: usize = 512;

/// A wire type read from little-endian bytes.
trait WireValue: Copy {
    /// Its size on the wire.
    const SIZE: usize;
    /// Reads it from the start of `b` (which holds at least `SIZE` bytes).
    fn read(b: &[u8]) -> Self;
}

macro_rules! wire_value {
    ($($t:ty),*) => {$(
        impl WireValue for $t {
            const SIZE: usize = size_of::<$t>();
            #[inline(always)]
            fn read(b: &[u8]) -> Self {
                let mut raw = [0u8; size_of::<$t>()];
                raw.copy_from_slice(&b[..size_of::<$t>()]);
                <$t>::from_le_bytes(raw)
            }
        }
    )*};
}
wire_value!(u8, i8, u16, i16, u32, i32, u64, i64, f32, f64);

/// One field's column while a batch is built.
trait ColumnBuilder {
    /// Appends the field of each row of `rows` (rows of `stride` bytes, zero-padded).
    fn extend(&mut self, rows: &[u8], stride: usize);
    /// The finished column.
    fn finish(self: Box<Self>) -> ArrayRef;
}

/// A numeric field (a fixed-size list for an array).
struct NumericColumn<T: ArrowPrimitiveType> {
    offset: usize,
    count: usize,
    list: bool,
    values: Vec<T::Native>,
}

impl<T: ArrowPrimitiveType> ColumnBuilder for NumericColumn<T>
where
    T::Native: WireValue,
{
    fn extend(&mut self, rows: &[u8], stride: usize) {
        let size = <T::Native as WireValue>::SIZE;
        let span = self.count * size;
        for row in rows.chunks_exact(stride) {
            let field = &row[self.offset..self.offset + span];
            self.values
                .extend(field.chunks_exact(size).map(<T::Native as WireValue>::read));
        }
    }

    fn finish(self: Box<Self>) -> ArrayRef {
        let values = PrimitiveArray::<T>::new(self.values.into(), None);
        if self.list {
            Arc::new(FixedSizeListArray::new(
                Arc::new(Field::new("item", T::DATA_TYPE, false)),
                i32::try_from(self.count).unwrap_or(i32::MAX),
                Arc::new(values),
                None,
            ))
        } else {
            Arc::new(values)
        }
    }
}

/// A `char[N]` field: text up to its first NUL, bytes that are not ASCII as U+0080–U+00FF
/// (as in the JSON lines contract).
struct TextColumn {
    offset: usize,
    count: usize,
    builder: StringBuilder,
}

impl ColumnBuilder for TextColumn {
    fn extend(&mut self, rows: &[u8], stride: usize) {
        for row in rows.chunks_exact(stride) {
            let raw = until_nul(&row[self.offset..self.offset + self.count]);
            match core::str::from_utf8(raw) {
                Ok(text) if raw.is_ascii() => self.builder.append_value(text),
                _ => self
                    .builder
                    .append_value(raw.iter().map(|&c| char::from(c)).collect::<String>()),
            }
        }
    }

    fn finish(mut self: Box<Self>) -> ArrayRef {
        Arc::new(self.builder.finish())
    }
}

/// The builder of field `f`'s column, for `rows` rows.
fn column_builder(f: &FieldLayout, rows: usize) -> Box<dyn ColumnBuilder> {
    fn numeric<T: ArrowPrimitiveType>(f: &FieldLayout, rows: usize) -> Box<dyn ColumnBuilder>
    where
        T::Native: WireValue,
    {
        Box::new(NumericColumn::<T> {
            offset: f.offset,
            count: f.count(),
            list: f.array_len.is_some(),
            values: Vec::with_capacity(rows * f.count()),
        })
    }
    match f.primitive {
        PrimitiveType::Char => Box::new(TextColumn {
            offset: f.offset,
            count: f.count(),
            builder: StringBuilder::with_capacity(rows, rows * f.count()),
        }),
        PrimitiveType::U8 => numeric::<UInt8Type>(f, rows),
        PrimitiveType::I8 => numeric::<Int8Type>(f, rows),
        PrimitiveType::U16 => numeric::<UInt16Type>(f, rows),
        PrimitiveType::I16 => numeric::<Int16Type>(f, rows),
        PrimitiveType::U32 => numeric::<UInt32Type>(f, rows),
        PrimitiveType::I32 => numeric::<Int32Type>(f, rows),
        PrimitiveType::U64 => numeric::<UInt64Type>(f, rows),
        PrimitiveType::I64 => numeric::<Int64Type>(f, rows),
        PrimitiveType::F32 => numeric::<Float32Type>(f, rows),
        PrimitiveType::F64 => numeric::<Float64Type>(f, rows),
    }
}

/// Decodes one table's frames batch by batch.
struct TableReader {
    schema: SchemaRef,
    ty: Arc<MessageType>,
    log: Arc<LogBytes>,
    tlog: bool,
    /// Frame starts, in file order.
    index: Vec<u64>,
    /// The timestamps of the frames whose timestamp is not the 8 bytes before them (read
    /// past damage as pymavlink reads it), by frame start.
    moved_ts: Arc<HashMap<u64, u64>>,
    next: usize,
}

impl TableReader {
    /// The batch of the frames that start at `entries`: each chunk of frames is copied into
    /// a row buffer (one full, zero-padded payload a row), then each column takes its field
    /// from every row of the chunk.
    fn batch(&self, entries: &[u64]) -> Result<RecordBatch, ArrowError> {
        let n = entries.len();
        // The full payload (every field lies inside it: the end of the last one, to be sure).
        let stride = self
            .ty
            .fields
            .iter()
            .map(|f| f.offset + f.count() * f.primitive.size())
            .fold(self.ty.max_len, usize::max)
            .max(1);
        let mut rows = vec![0u8; CHUNK_ROWS * stride];
        let mut ts = Vec::with_capacity(n);
        let mut sysid = Vec::with_capacity(n);
        let mut compid = Vec::with_capacity(n);
        let mut seq = Vec::with_capacity(n);
        let mut signed = BooleanBufferBuilder::new(n);
        let mut columns: Vec<Box<dyn ColumnBuilder>> = self
            .ty
            .wire_order
            .iter()
            .map(|&i| column_builder(&self.ty.fields[i], n))
            .collect();
        for chunk in entries.chunks(CHUNK_ROWS) {
            for (&e, row) in chunk.iter().zip(rows.chunks_exact_mut(stride)) {
                let start = usize::try_from(e).unwrap_or(usize::MAX);
                let bytes = self.log.get(start..).unwrap_or_default();
                let frame = Frame::new_checked(bytes).map_err(|e| {
                    ArrowError::ExternalError(Box::new(std::io::Error::other(e.to_string())))
                })?;
                let moved = (!self.moved_ts.is_empty())
                    .then(|| self.moved_ts.get(&e).copied())
                    .flatten();
                let t = match (self.tlog, moved, start.checked_sub(TIMESTAMP_LEN)) {
                    (false, _, _) => 0,
                    (true, Some(t), _) => t,
                    (true, None, Some(at)) => u64::from_be_bytes(bytes_at::<8>(&self.log[at..], 0)),
                    (true, None, None) => 0,
                };
                ts.push(i64::try_from(t).unwrap_or(i64::MAX));
                sysid.push(frame.sysid());
                compid.push(frame.compid());
                seq.push(frame.seq());
                signed.append(frame.is_signed());
                let payload = frame.payload();
                let kept = payload.len().min(stride);
                row[..kept].copy_from_slice(&payload[..kept]);
                row[kept..].fill(0);
            }
            let filled = &rows[..chunk.len() * stride];
            for c in &mut columns {
                c.extend(filled, stride);
            }
        }
        let mut out: Vec<ArrayRef> = vec![
            Arc::new(PrimitiveArray::<Int64Type>::new(ts.into(), None)),
            Arc::new(PrimitiveArray::<UInt8Type>::new(sysid.into(), None)),
            Arc::new(PrimitiveArray::<UInt8Type>::new(compid.into(), None)),
            Arc::new(PrimitiveArray::<UInt8Type>::new(seq.into(), None)),
            Arc::new(BooleanArray::new(signed.finish(), None)),
        ];
        out.extend(columns.into_iter().map(ColumnBuilder::finish));
        RecordBatch::try_new(Arc::clone(&self.schema), out)
    }
}

impl Iterator for TableReader {
    type Item = Result<RecordBatch, ArrowError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.next >= self.index.len() {
            return None;
        }
        let end = (self.next + BATCH_ROWS).min(self.index.len());
        let batch = self.batch(&self.index[self.next..end]);
        self.next = end;
        Some(batch)
    }
}

impl RecordBatchReader for TableReader {
    fn schema(&self) -> SchemaRef {
        Arc::clone(&self.schema)
    }
}

/// The frames of one message type of a log, as an Arrow stream: hand it to
/// `pyarrow.table()`, `polars.from_arrow()` or `pyarrow.RecordBatchReader.from_stream()`.
/// It can be consumed once.
#[pyclass(module = "mavstack", name = "Table")]
pub(crate) struct Table {
    name: String,
    rows: usize,
    reader: Option<TableReader>,
}

#[pymethods]
impl Table {
    /// The Arrow C stream interface: a capsule holding an `ArrowArrayStream`.
    #[pyo3(signature = (requested_schema=None))]
    fn __arrow_c_stream__<'py>(
        &mut self,
        py: Python<'py>,
        requested_schema: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyCapsule>> {
        let _ = requested_schema;
        let reader = self.reader.take().ok_or_else(|| {
            PyValueError::new_err(format!(
                "the {} table was consumed already (each table is one Arrow stream: read it again with read_tlog)",
                self.name
            ))
        })?;
        let stream = FFI_ArrowArrayStream::new(Box::new(reader));
        PyCapsule::new_with_value(py, stream, c"arrow_array_stream")
    }

    /// The message type's name.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// Rows (frames of this type in the log).
    #[getter]
    fn num_rows(&self) -> usize {
        self.rows
    }

    fn __len__(&self) -> usize {
        self.rows
    }

    fn __repr__(&self) -> String {
        format!(
            "<mavstack.Table {}: {} rows{}>",
            self.name,
            self.rows,
            if self.reader.is_none() {
                ", consumed"
            } else {
                ""
            }
        )
    }
}

/// Reads a log (`.tlog` by its extension, raw frames otherwise) into one Arrow table per
/// message type present: `{name: Table}` in order of first appearance. `types` limits it to
/// some names; `key` (32 bytes or 64 hex digits) drops and counts frames whose signature
/// fails; `progress` shows a bar on stderr while the log is scanned.
#[pyfunction]
#[pyo3(signature = (path, types=None, dialect="ardupilotmega", key=None, progress=false))]
pub(crate) fn read_tlog<'py>(
    py: Python<'py>,
    path: PathBuf,
    types: Option<Vec<String>>,
    dialect: &str,
    key: Option<&Bound<'py, PyAny>>,
    progress: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let key = parse_key(key)?;
    let dialect = Dialect::load(dialect)?;
    let log = LogBytes::open(&path)
        .map_err(|e| PyOSError::new_err(format!("cannot read {}: {e}", path.display())))?;
    let tlog = is_tlog(&path);
    let wanted: Option<Vec<bool>> = types.map(|names| {
        let mut mask = vec![false; dialect.messages.len()];
        for n in names {
            if let Some(i) = dialect.index_of_name(&n) {
                mask[i] = true;
            }
        }
        mask
    });
    let (order, mut index, moved_ts, length) = py.detach(|| {
        let bar = progress.then(|| crate::progress::bar(log.len() as u64, &path));
        let mut scan = Scan::new(&log, &dialect, tlog, key);
        let mut order = Vec::new();
        let mut index: HashMap<usize, Vec<u64>> = HashMap::new();
        let mut moved_ts: HashMap<u64, u64> = HashMap::new();
        let mut n = 0u64;
        while let Some(found) = scan.next(&log, &dialect) {
            n += 1;
            if let Some(bar) = &bar
                && n.is_multiple_of(65_536)
            {
                bar.set_position(scan.position() as u64);
            }
            if wanted.as_ref().is_some_and(|w| !w[found.message]) {
                continue;
            }
            let entry = found.start as u64;
            let before = found
                .start
                .checked_sub(TIMESTAMP_LEN)
                .map(|at| &log[at..found.start]);
            if tlog && before != Some(&found.ts_us.to_be_bytes()[..]) {
                moved_ts.insert(entry, found.ts_us);
            }
            index
                .entry(found.message)
                .or_insert_with(|| {
                    order.push(found.message);
                    Vec::new()
                })
                .push(entry);
        }
        if let Some(bar) = bar {
            bar.finish_and_clear();
        }
        (order, index, Arc::new(moved_ts), log.check_length())
    });
    length.map_err(|e| PyOSError::new_err(e.to_string()))?;
    let out = PyDict::new(py);
    for m in order {
        let entries = index.remove(&m).unwrap_or_default();
        let ty = Arc::clone(&dialect.messages[m]);
        let table = Table {
            name: ty.name.clone(),
            rows: entries.len(),
            reader: Some(TableReader {
                schema: Arc::new(schema(&ty)),
                ty: Arc::clone(&ty),
                log: Arc::clone(&log),
                tlog,
                index: entries,
                moved_ts: Arc::clone(&moved_ts),
                next: 0,
            }),
        };
        out.set_item(&ty.name, Py::new(py, table)?)?;
    }
    Ok(out)
}
