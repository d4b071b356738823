//! Python values into payload bytes: a field as pymavlink's argument of that name gives it,
//! and a message's whole payload from its fields' values in XML order.

use mavstack_xml::PrimitiveType;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyString, PyTuple};

use crate::dialect::{FieldLayout, MessageType};

/// Writes `value` into `payload` as field `f` (pymavlink's argument of that name).
pub(crate) fn put_field(
    f: &FieldLayout,
    value: &Bound<'_, PyAny>,
    payload: &mut [u8],
) -> PyResult<()> {
    if f.is_text() && f.array_len.is_some() {
        let bytes: Vec<u8> = if let Ok(s) = value.cast::<PyString>() {
            s.to_cow()?.as_bytes().to_vec()
        } else if let Ok(b) = value.extract::<Vec<u8>>() {
            b
        } else {
            return Err(PyTypeError::new_err(format!(
                "{}: a str or bytes for char[{}]",
                f.name,
                f.count()
            )));
        };
        let n = bytes.len().min(f.count());
        payload[f.offset..f.offset + n].copy_from_slice(&bytes[..n]);
        return Ok(());
    }
    let size = f.primitive.size();
    match f.array_len {
        None => put_scalar(f, value, &mut payload[f.offset..f.offset + size]),
        Some(n) => {
            let items: Vec<Bound<'_, PyAny>> = if let Ok(b) = value.cast::<PyBytes>() {
                let py = value.py();
                b.as_bytes()
                    .iter()
                    .map(|&x| pyo3::types::PyInt::new(py, x).into_any())
                    .collect()
            } else {
                value
                    .try_iter()
                    .map_err(|_| {
                        PyTypeError::new_err(format!("{}: a sequence of {n} values", f.name))
                    })?
                    .collect::<PyResult<_>>()?
            };
            if items.len() > n {
                return Err(PyValueError::new_err(format!(
                    "{}: {} values for an array of {n}",
                    f.name,
                    items.len()
                )));
            }
            for (i, item) in items.iter().enumerate() {
                let at = f.offset + i * size;
                put_scalar(f, item, &mut payload[at..at + size])?;
            }
            Ok(())
        }
    }
}

/// Writes one element of field `f` into `out` (its size).
fn put_scalar(f: &FieldLayout, value: &Bound<'_, PyAny>, out: &mut [u8]) -> PyResult<()> {
    let range = |e: PyErr| {
        PyValueError::new_err(format!(
            "{}: {} does not fit a {:?} ({e})",
            f.name,
            value
                .repr()
                .map_or_else(|_| "?".to_owned(), |r| r.to_string()),
            f.primitive
        ))
    };
    match f.primitive {
        PrimitiveType::F32 => {
            let v: f64 = value.extract()?;
            out.copy_from_slice(&(v as f32).to_le_bytes());
        }
        PrimitiveType::F64 => {
            let v: f64 = value.extract()?;
            out.copy_from_slice(&v.to_le_bytes());
        }
        PrimitiveType::Char => {
            let b: u8 = if let Ok(s) = value.cast::<PyString>() {
                s.to_cow()?.bytes().next().unwrap_or(0)
            } else {
                value.extract().map_err(range)?
            };
            out[0] = b;
        }
        PrimitiveType::U8 => {
            out.copy_from_slice(&value.extract::<u8>().map_err(range)?.to_le_bytes())
        }
        PrimitiveType::I8 => {
            out.copy_from_slice(&value.extract::<i8>().map_err(range)?.to_le_bytes())
        }
        PrimitiveType::U16 => {
            out.copy_from_slice(&value.extract::<u16>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::I16 => {
            out.copy_from_slice(&value.extract::<i16>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::U32 => {
            out.copy_from_slice(&value.extract::<u32>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::I32 => {
            out.copy_from_slice(&value.extract::<i32>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::U64 => {
            out.copy_from_slice(&value.extract::<u64>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::I64 => {
            out.copy_from_slice(&value.extract::<i64>().map_err(range)?.to_le_bytes());
        }
    }
    Ok(())
}

/// The full payload of `ty` from its fields' values in XML order (pymavlink's arguments).
pub(super) fn encode_payload(ty: &MessageType, args: &Bound<'_, PyTuple>) -> PyResult<Vec<u8>> {
    if args.len() != ty.fields.len() {
        return Err(PyTypeError::new_err(format!(
            "{}: {} values for {} fields",
            ty.name,
            args.len(),
            ty.fields.len()
        )));
    }
    let mut payload = vec![0u8; ty.max_len];
    for (f, v) in ty.fields.iter().zip(args.iter()) {
        put_field(f, &v, &mut payload)?;
    }
    Ok(payload)
}
