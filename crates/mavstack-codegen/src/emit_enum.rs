//! Open enums and bitmasks.
//!
//! Every MAVLink enum becomes `#[repr(transparent)] pub struct Name(pub uN)` with one
//! associated constant per entry, so values the dialect does not know survive a round trip
//! (a router must forward what it does not understand). Bitmasks get the bit operators and
//! keep unknown bits.

use proc_macro2::TokenStream;
use quote::quote;

use crate::Options;
use crate::docs::{doc_attrs, entry_doc, enum_doc};
use crate::names::{entry_names, ident, type_name};
use crate::plan::EnumPlan;

/// `#[cfg(...)]` for an entry contributed by other files than the owner's, when gated.
fn entry_cfg(plan: &EnumPlan, contributors: &[String], opts: &Options) -> TokenStream {
    if !opts.feature_gates || contributors.contains(&plan.owner) {
        return TokenStream::new();
    }
    let features = contributors.iter().map(String::as_str);
    quote!(#[cfg(any(#(feature = #features),*))])
}

pub(crate) fn emit(plan: &EnumPlan, opts: &Options) -> TokenStream {
    let name = type_name(&plan.def.name);
    let repr = ident(plan.repr.rust_name());
    let doc = doc_attrs(&enum_doc(&plan.def));
    let xml_names: Vec<&str> = plan.entries.iter().map(|(e, _)| e.name.as_str()).collect();
    let const_names = entry_names(&plan.def.name, xml_names.iter().copied());
    let mut consts = Vec::new();
    let mut name_arms = Vec::new();
    let mut from_name_arms = Vec::new();
    for ((entry, contributors), const_name) in plan.entries.iter().zip(&const_names) {
        let cfg = entry_cfg(plan, contributors, opts);
        let c = ident(const_name);
        let value = proc_macro2::Literal::u64_unsuffixed(entry.value);
        let entry_doc = doc_attrs(&entry_doc(entry));
        let xml_name = &entry.name;
        consts.push(quote! { #entry_doc #cfg pub const #c: Self = Self(#value); });
        name_arms.push(quote! { #cfg #value => Some(#xml_name), });
        from_name_arms.push(quote! { #cfg #xml_name => Some(Self::#c), });
    }
    let serde = opts.serde_derive();
    let debug = if plan.def.bitmask {
        quote! {
            impl ::core::fmt::Debug for #name {
                fn fmt(&self, f: &mut ::core::fmt::Formatter<'_>) -> ::core::fmt::Result {
                    let mut rest = self.0;
                    let mut first = true;
                    for bit in 0..#repr::BITS {
                        let flag = 1 << bit;
                        if rest & flag != 0 && let Some(n) = Self(flag).name() {
                            f.write_str(if first { "" } else { " | " })?;
                            f.write_str(n)?;
                            rest &= !flag;
                            first = false;
                        }
                    }
                    if rest != 0 || first {
                        if !first {
                            f.write_str(" | ")?;
                        }
                        write!(f, "{:#x}", rest)?;
                    }
                    Ok(())
                }
            }
            impl #name {
                /// No bit set.
                pub const EMPTY: Self = Self(0);
                /// The raw bits.
                #[must_use]
                pub const fn bits(self) -> #repr { self.0 }
                /// Whether every bit of `other` is set in `self`.
                #[must_use]
                pub const fn contains(self, other: Self) -> bool { self.0 & other.0 == other.0 }
                /// Whether any bit of `other` is set in `self`.
                #[must_use]
                pub const fn intersects(self, other: Self) -> bool { self.0 & other.0 != 0 }
                /// Whether no bit is set.
                #[must_use]
                pub const fn is_empty(self) -> bool { self.0 == 0 }
                /// Sets or clears the bits of `other`.
                pub fn set(&mut self, other: Self, on: bool) {
                    if on { self.0 |= other.0 } else { self.0 &= !other.0 }
                }
            }
            impl ::core::ops::BitOr for #name {
                type Output = Self;
                fn bitor(self, rhs: Self) -> Self { Self(self.0 | rhs.0) }
            }
            impl ::core::ops::BitOrAssign for #name {
                fn bitor_assign(&mut self, rhs: Self) { self.0 |= rhs.0 }
            }
            impl ::core::ops::BitAnd for #name {
                type Output = Self;
                fn bitand(self, rhs: Self) -> Self { Self(self.0 & rhs.0) }
            }
            impl ::core::ops::BitAndAssign for #name {
                fn bitand_assign(&mut self, rhs: Self) { self.0 &= rhs.0 }
            }
            impl ::core::ops::Not for #name {
                type Output = Self;
                fn not(self) -> Self { Self(!self.0) }
            }
        }
    } else {
        quote! {
            impl ::core::fmt::Debug for #name {
                fn fmt(&self, f: &mut ::core::fmt::Formatter<'_>) -> ::core::fmt::Result {
                    match self.name() {
                        Some(n) => f.write_str(n),
                        None => write!(f, "{}({})", stringify!(#name), self.0),
                    }
                }
            }
        }
    };
    quote! {
        #doc
        #[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
        #serde
        #[repr(transparent)]
        pub struct #name(pub #repr);

        #[allow(missing_docs)]
        impl #name {
            #(#consts)*
        }

        impl #name {
            /// The XML name of the entry with this value, or `None` for a value this dialect
            /// does not define (for a bitmask: a value that is not exactly one named flag).
            #[must_use]
            #[allow(unreachable_patterns)]
            pub const fn name(self) -> Option<&'static str> {
                match self.0 {
                    #(#name_arms)*
                    _ => None,
                }
            }

            /// The entry with this XML name.
            #[must_use]
            pub fn from_name(name: &str) -> Option<Self> {
                match name {
                    #(#from_name_arms)*
                    _ => None,
                }
            }
        }

        #debug

        impl ::core::convert::From<#repr> for #name {
            fn from(v: #repr) -> Self { Self(v) }
        }

        impl ::core::convert::From<#name> for #repr {
            fn from(v: #name) -> Self { v.0 }
        }
    }
}
