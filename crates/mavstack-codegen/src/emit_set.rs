//! The message enum of a dialect: every message of the file's include closure, with id
//! dispatch.

use mavstack_xml::Message;
use proc_macro2::{Literal, TokenStream};
use quote::quote;

use crate::Options;
use crate::emit_message::info_literal;
use crate::names::{ident, type_name};
use crate::plan::{Plan, Unit};

pub(crate) fn emit(unit: &Unit, plan: &Plan, opts: &Options) -> TokenStream {
    let core = opts.core_path();
    let messages: Vec<&Message> = unit.dialect.messages.iter().collect();
    let count = Literal::usize_unsuffixed(messages.len());
    let mut variants = Vec::new();
    let mut infos = Vec::new();
    let mut info_arms = Vec::new();
    let mut decode_arms = Vec::new();
    let mut encode_arms = Vec::new();
    let mut id_arms = Vec::new();
    let mut self_info_arms = Vec::new();
    let mut from_impls = Vec::new();
    for (i, m) in messages.iter().enumerate() {
        let name = type_name(&m.name);
        let module = ident(plan.module_of(&m.file).unwrap_or_default());
        let path = quote!(super::#module::#name);
        let id = Literal::u32_unsuffixed(m.id);
        let index = Literal::usize_unsuffixed(i);
        let doc = format!(" `{}` (id {}).", m.name, m.id);
        variants.push(quote!(#[doc = #doc] #name(#path),));
        infos.push(info_literal(m, &core));
        info_arms.push(quote!(#id => Some(&MESSAGES[#index]),));
        decode_arms.push(quote!(#id => #core::message::decode_as::<Self, #path>(payload),));
        encode_arms.push(quote!(Self::#name(m) => #core::Message::encode(m, out),));
        id_arms.push(quote!(Self::#name(_) => #id,));
        self_info_arms.push(quote!(Self::#name(_) => &MESSAGES[#index],));
        from_impls.push(quote! {
            impl ::core::convert::From<#path> for MavMessage {
                fn from(m: #path) -> Self { Self::#name(m) }
            }
        });
    }
    let doc = format!(
        " Every message of the `{}` dialect ({} messages, from `{}` and the files it includes).",
        unit.module,
        messages.len(),
        unit.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    );
    let serde = opts.serde_derive();
    // An enum without variants matches on `*self` with no arms.
    let (encode_body, id_body, info_body) = if messages.is_empty() {
        (
            quote!(match *self {}),
            quote!(match *self {}),
            quote!(match *self {}),
        )
    } else {
        (
            quote!(match self { #(#encode_arms)* }),
            quote!(match self { #(#id_arms)* }),
            quote!(match self { #(#self_info_arms)* }),
        )
    };
    quote! {
        /// Facts about every message of this dialect, sorted by id.
        pub static MESSAGES: [#core::MessageInfo; #count] = [#(#infos),*];

        #[doc = #doc]
        #[derive(Clone, Debug, PartialEq)]
        #serde
        #[allow(clippy::large_enum_variant)]
        pub enum MavMessage {
            #(#variants)*
        }

        impl #core::MessageSet for MavMessage {
            #[inline]
            fn info(id: u32) -> Option<&'static #core::MessageInfo> {
                match id {
                    #(#info_arms)*
                    _ => None,
                }
            }

            fn all() -> &'static [#core::MessageInfo] {
                &MESSAGES
            }

            #[inline]
            fn decode(id: u32, payload: &[u8]) -> Result<Self, #core::UnknownMessage> {
                match id {
                    #(#decode_arms)*
                    _ => Err(#core::UnknownMessage { id }),
                }
            }

            #[inline]
            fn encode(&self, out: &mut [u8; #core::MAX_PAYLOAD_LEN]) -> usize {
                #encode_body
            }

            #[inline]
            fn id(&self) -> u32 {
                #id_body
            }

            fn message_info(&self) -> &'static #core::MessageInfo {
                #info_body
            }
        }

        #(#from_impls)*
    }
}
