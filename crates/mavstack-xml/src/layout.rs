//! Wire layout and CRC_EXTRA of a message.
//!
//! Base fields are stable-sorted by element size, largest first; extension fields follow in
//! XML order. CRC_EXTRA hashes the message name and, for every base field in wire order, its
//! element type, its name and (for arrays) the length as one raw byte.

use std::collections::HashSet;
use std::path::Path;

use mavstack_core::Crc16;

use crate::error::{Error, ErrorKind};
use crate::model::{Field, Message};
use crate::xml::MessageDecl;

/// The most fields a message may have.
pub const MAX_FIELDS: usize = 64;

/// CRC_EXTRA of a message with `name` whose base fields, in wire order, are `fields`
/// (extension fields are skipped).
#[must_use]
pub fn crc_extra<'a>(name: &str, fields: impl IntoIterator<Item = &'a Field>) -> u8 {
    let mut crc = Crc16::new();
    crc.update(name.as_bytes());
    crc.update(b" ");
    for f in fields.into_iter().filter(|f| !f.extension) {
        crc.update(f.ty.primitive.c_name().as_bytes());
        crc.update(b" ");
        crc.update(f.name.as_bytes());
        crc.update(b" ");
        if let Some(len) = f.ty.array_len {
            crc.update_byte(len);
        }
    }
    let v = crc.value();
    // Fold the two bytes of the checksum into one.
    (v as u8) ^ ((v >> 8) as u8)
}

/// Orders `fields` (given in XML order) for the wire and fills in their offsets.
pub(crate) fn wire_order(mut fields: Vec<Field>) -> Vec<Field> {
    // `sort_by_key` is stable: equal sizes keep XML order, and extensions (all "size 0" for
    // the key) keep theirs after every base field.
    fields.sort_by_key(|f| if f.extension { 1 } else { 0 });
    let base_count = fields.iter().filter(|f| !f.extension).count();
    fields[..base_count].sort_by_key(|f| core::cmp::Reverse(f.ty.primitive.size()));
    let mut offset = 0;
    for f in &mut fields {
        f.offset = offset;
        offset += f.ty.wire_size();
    }
    fields
}

/// Lays out a declared message and checks the limits.
pub(crate) fn layout(decl: MessageDecl, file: &Path) -> Result<Message, Error> {
    let err = |kind| Error::new(decl.location.clone(), kind);
    if decl.fields.is_empty() {
        return Err(err(ErrorKind::NoFields {
            message: decl.name.clone(),
        }));
    }
    let mut seen = HashSet::new();
    for f in &decl.fields {
        if !seen.insert(f.name.as_str()) {
            return Err(Error::new(
                f.location.clone(),
                ErrorKind::DuplicateField {
                    message: decl.name.clone(),
                    field: f.name.clone(),
                },
            ));
        }
    }
    if decl.fields.len() > MAX_FIELDS {
        return Err(err(ErrorKind::TooManyFields {
            message: decl.name.clone(),
            count: decl.fields.len(),
        }));
    }
    let fields = wire_order(decl.fields);
    let max_len: usize = fields.iter().map(|f| f.ty.wire_size()).sum();
    if max_len > mavstack_core::MAX_PAYLOAD_LEN {
        return Err(err(ErrorKind::PayloadTooLarge {
            message: decl.name.clone(),
            len: max_len,
        }));
    }
    let min_len = fields
        .iter()
        .filter(|f| !f.extension)
        .map(|f| f.ty.wire_size())
        .sum();
    let offset_of = |name: &str| fields.iter().find(|f| f.name == name).map(|f| f.offset);
    // MANUAL_CONTROL names its target system field `target`; pymavlink and the C library's
    // routing tables treat it as the target system, and so do we.
    let target_system_offset = offset_of("target_system").or_else(|| {
        if decl.name == "MANUAL_CONTROL" {
            offset_of("target")
        } else {
            None
        }
    });
    Ok(Message {
        id: decl.id,
        crc_extra: crc_extra(&decl.name, &fields),
        target_system_offset,
        target_component_offset: offset_of("target_component"),
        name: decl.name,
        description: decl.description,
        min_len,
        max_len,
        fields,
        deprecation: decl.deprecation,
        wip: decl.wip,
        file: file.to_path_buf(),
        location: decl.location,
    })
}
