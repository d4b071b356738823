//! Message structs and their `Message` implementations.
//!
//! Decoding copies the received payload into a zeroed array of the full length and reads
//! each field at its constant offset; encoding writes each field at its offset. Both are
//! straight-line code with no allocation and no failure.

use std::collections::BTreeMap;

use mavstack_xml::{Field, Message, PrimitiveType};
use proc_macro2::{Literal, TokenStream};
use quote::quote;

use crate::Options;
use crate::docs::{doc_attrs, field_doc, message_doc};
use crate::names::{field_ident, ident, type_name};
use crate::plan::{EnumKey, EnumPlan, Plan, Unit};

/// How one field is represented in Rust.
enum Repr<'a> {
    /// A plain number or an array of them.
    Plain,
    /// A scalar of an open enum type.
    Enum(&'a EnumPlan),
}

fn field_repr<'a>(f: &Field, unit: &Unit, enums: &'a BTreeMap<EnumKey, EnumPlan>) -> Repr<'a> {
    match (&f.enum_name, f.ty.array_len) {
        (Some(e), None) => unit
            .enum_owner(e)
            .and_then(|owner| enums.get(&(e.clone(), owner)))
            .map_or(Repr::Plain, Repr::Enum),
        _ => Repr::Plain,
    }
}

fn usize_lit(n: usize) -> Literal {
    Literal::usize_unsuffixed(n)
}

/// The offset of element `i` of an array at `offset` with elements of `size` bytes, written
/// without operations that do nothing (`0 + i * 1`).
fn element_offset(offset: usize, size: usize) -> TokenStream {
    let (off, sz) = (usize_lit(offset), usize_lit(size));
    match (offset, size) {
        (0, 1) => quote!(i),
        (0, _) => quote!(i * #sz),
        (_, 1) => quote!(#off + i),
        _ => quote!(#off + i * #sz),
    }
}

/// Path to an enum type from a sibling module.
fn enum_path(plan: &EnumPlan) -> TokenStream {
    let module = ident(&plan.owner);
    let name = type_name(&plan.def.name);
    quote!(super::#module::#name)
}

fn rust_type(f: &Field, repr: &Repr<'_>) -> TokenStream {
    let elem = ident(f.ty.primitive.rust_name());
    match (repr, f.ty.array_len) {
        (Repr::Enum(plan), _) => enum_path(plan),
        (Repr::Plain, Some(n)) => {
            let n = usize_lit(usize::from(n));
            quote!([#elem; #n])
        }
        (Repr::Plain, None) => quote!(#elem),
    }
}

fn decode_expr(f: &Field, repr: &Repr<'_>) -> TokenStream {
    let p = f.ty.primitive;
    let elem = ident(p.rust_name());
    let off = usize_lit(f.offset);
    match (repr, f.ty.array_len) {
        (_, Some(n)) if p.size() == 1 && matches!(p, PrimitiveType::U8 | PrimitiveType::Char) => {
            let n = usize_lit(usize::from(n));
            quote!(get::<#n>(buf, #off))
        }
        (_, Some(_)) => {
            let at = element_offset(f.offset, p.size());
            quote!(::core::array::from_fn(|i| #elem::from_le_bytes(get(buf, #at))))
        }
        (Repr::Enum(plan), None) => {
            let path = enum_path(plan);
            let raw = quote!(#elem::from_le_bytes(get(buf, #off)));
            if plan.repr.rust_name() == p.rust_name() {
                quote!(#path(#raw))
            } else {
                let target = ident(plan.repr.rust_name());
                quote!(#path(#raw as #target))
            }
        }
        (Repr::Plain, None) => quote!(#elem::from_le_bytes(get(buf, #off))),
    }
}

fn encode_stmt(f: &Field, repr: &Repr<'_>) -> TokenStream {
    let p = f.ty.primitive;
    let name = field_ident(&f.name);
    let off = usize_lit(f.offset);
    match (repr, f.ty.array_len) {
        (_, Some(_)) if p.size() == 1 && matches!(p, PrimitiveType::U8 | PrimitiveType::Char) => {
            quote!(put(out, #off, &self.#name);)
        }
        (_, Some(_)) => {
            let at = element_offset(f.offset, p.size());
            quote! {
                for (i, v) in self.#name.iter().enumerate() {
                    put(out, #at, &v.to_le_bytes());
                }
            }
        }
        (Repr::Enum(plan), None) => {
            if plan.repr.rust_name() == p.rust_name() {
                quote!(put(out, #off, &self.#name.0.to_le_bytes());)
            } else {
                let wire = ident(p.rust_name());
                quote!(put(out, #off, &(self.#name.0 as #wire).to_le_bytes());)
            }
        }
        (Repr::Plain, None) => quote!(put(out, #off, &self.#name.to_le_bytes());),
    }
}

fn default_expr(f: &Field, repr: &Repr<'_>, version: Option<u8>) -> TokenStream {
    match (repr, f.ty.array_len) {
        (Repr::Enum(plan), _) => {
            let path = enum_path(plan);
            quote!(#path(0))
        }
        (Repr::Plain, Some(n)) => {
            let n = usize_lit(usize::from(n));
            let zero = zero_lit(f.ty.primitive);
            quote!([#zero; #n])
        }
        (Repr::Plain, None) if f.ty.mavlink_version => {
            let v = Literal::u8_unsuffixed(version.unwrap_or(0));
            quote!(#v)
        }
        (Repr::Plain, None) => zero_lit(f.ty.primitive),
    }
}

fn zero_lit(p: PrimitiveType) -> TokenStream {
    if p.is_float() { quote!(0.0) } else { quote!(0) }
}

fn opt_u8(v: Option<usize>) -> TokenStream {
    match v.and_then(|v| u8::try_from(v).ok()) {
        Some(v) => {
            let v = Literal::u8_unsuffixed(v);
            quote!(Some(#v))
        }
        None => quote!(None),
    }
}

/// The `MessageInfo` literal of a message.
pub(crate) fn info_literal(m: &Message, core: &TokenStream) -> TokenStream {
    let id = Literal::u32_unsuffixed(m.id);
    let name = &m.name;
    let crc = Literal::u8_unsuffixed(m.crc_extra);
    // Lengths are at most 255: the loader rejects longer payloads.
    let min = Literal::u8_unsuffixed(u8::try_from(m.min_len).unwrap_or(u8::MAX));
    let max = Literal::u8_unsuffixed(u8::try_from(m.max_len).unwrap_or(u8::MAX));
    let ts = opt_u8(m.target_system_offset);
    let tc = opt_u8(m.target_component_offset);
    quote! {
        #core::MessageInfo {
            id: #id, name: #name, crc_extra: #crc, min_len: #min, max_len: #max,
            target_system_offset: #ts, target_component_offset: #tc,
        }
    }
}

pub(crate) fn emit(m: &Message, unit: &Unit, plan: &Plan, opts: &Options) -> TokenStream {
    let core = opts.core_path();
    let name = type_name(&m.name);
    let doc = doc_attrs(&message_doc(m));
    let version = unit.dialect.version;
    let serde = opts.serde_derive();
    let xml_order = m.fields_in_xml_order();
    let mut fields = Vec::new();
    let mut defaults = Vec::new();
    for f in &xml_order {
        let repr = field_repr(f, unit, &plan.enums);
        let ident = field_ident(&f.name);
        let ty = rust_type(f, &repr);
        let fdoc = doc_attrs(&field_doc(f));
        let serde_with = if opts.serde && f.ty.array_len.is_some() && matches!(repr, Repr::Plain) {
            let with = format!("{}::serde_arrays", opts.core_path_str());
            quote!(#[cfg_attr(feature = "serde", serde(with = #with))])
        } else {
            TokenStream::new()
        };
        fields.push(quote!(#fdoc #serde_with pub #ident: #ty,));
        let d = default_expr(f, &repr, version);
        defaults.push(quote!(#ident: #d,));
    }
    let mut decodes = Vec::new();
    let mut encodes = Vec::new();
    for f in &m.fields {
        let repr = field_repr(f, unit, &plan.enums);
        let ident = field_ident(&f.name);
        let e = decode_expr(f, &repr);
        decodes.push(quote!(#ident: #e,));
        encodes.push(encode_stmt(f, &repr));
    }
    let id = Literal::u32_unsuffixed(m.id);
    let xml_name = &m.name;
    let crc = Literal::u8_unsuffixed(m.crc_extra);
    let min = usize_lit(m.min_len);
    let max = usize_lit(m.max_len);
    let info = info_literal(m, &core);
    // `Default` is derived unless a field defaults to something else than zero (the
    // dialect's version) or is an array too long for the standard library's impls.
    let derivable = m
        .fields
        .iter()
        .all(|f| !f.ty.mavlink_version && f.ty.array_len.is_none_or(|n| n <= 32));
    let (derive_default, default_impl) = if derivable {
        (quote!(Default,), TokenStream::new())
    } else {
        let default_impl = quote! {
            impl ::core::default::Default for #name {
                fn default() -> Self {
                    Self { #(#defaults)* }
                }
            }
        };
        (TokenStream::new(), default_impl)
    };
    quote! {
        #doc
        #[derive(Clone, Copy, Debug, #derive_default PartialEq)]
        #serde
        pub struct #name {
            #(#fields)*
        }

        #default_impl

        impl #core::Message for #name {
            const ID: u32 = #id;
            const NAME: &'static str = #xml_name;
            const CRC_EXTRA: u8 = #crc;
            const MIN_LEN: usize = #min;
            const ENCODED_LEN: usize = #max;
            const INFO: #core::MessageInfo = #info;

            #[inline]
            fn decode(payload: &[u8]) -> Self {
                // A full payload is read in place; a truncated one from a zero-extended copy.
                let extended: [u8; #max];
                let buf: &[u8; #max] = match payload.first_chunk::<#max>() {
                    Some(full) => full,
                    None => {
                        extended = #core::payload::zero_extended(payload);
                        &extended
                    }
                };
                Self { #(#decodes)* }
            }

            #[inline]
            fn encode(&self, out: &mut [u8; #core::MAX_PAYLOAD_LEN]) -> usize {
                #(#encodes)*
                #max
            }
        }
    }
}
