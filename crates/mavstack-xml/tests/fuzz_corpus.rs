//! Replays the checked-in seed corpus of the `dialect_xml` fuzz target (fuzz/corpus/) and a
//! property over arbitrary input, on stable Rust: nothing may panic.

use proptest::prelude::*;

#[test]
fn seed_corpus_never_panics() {
    for seed in mavstack_core::fuzz_seeds("dialect_xml", 20) {
        mavstack_xml::fuzz_dialect_xml(&seed);
    }
}

/// XML-shaped fragments glued together at random: deeper than random bytes get.
fn xmlish() -> impl Strategy<Value = String> {
    let pieces = prop_oneof![
        Just("<mavlink>".to_owned()),
        Just("</mavlink>".to_owned()),
        Just("<messages>".to_owned()),
        Just("</messages>".to_owned()),
        Just("<enums><enum name=\"E\">".to_owned()),
        Just("</enum></enums>".to_owned()),
        Just("<include>fuzz.xml</include>".to_owned()),
        Just("<include>other.xml</include>".to_owned()),
        (0u32..20_000_000, "[A-Z]{1,3}")
            .prop_map(|(id, n)| format!("<message id=\"{id}\" name=\"{n}\">")),
        Just("</message>".to_owned()),
        Just("<extensions/>".to_owned()),
        (
            "(u?int(8|16|32|64)_t|float|double|char|array)(\\[[0-9]{1,3}\\])?",
            "[a-z]{1,2}",
            "[A-Z]?"
        )
            .prop_map(|(t, n, e)| if e.is_empty() {
                format!("<field type=\"{t}\" name=\"{n}\">d</field>")
            } else {
                format!("<field type=\"{t}\" name=\"{n}\" enum=\"{e}\">d</field>")
            }),
        ("[A-Z_]{1,4}", "(0x)?[0-9]{0,5}")
            .prop_map(|(n, v)| format!("<entry name=\"E_{n}\" value=\"{v}\"/>")),
        any::<String>(),
    ];
    proptest::collection::vec(pieces, 0..40).prop_map(|v| v.concat())
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..512)) {
        mavstack_xml::fuzz_dialect_xml(&data);
    }

    #[test]
    fn xml_shaped_input_never_panics(text in xmlish()) {
        mavstack_xml::fuzz_dialect_xml(text.as_bytes());
    }
}

/// The `json_frames` seeds: JSON lines pymavlink wrote for frames it packed
/// (fuzz/make_seeds.py), and hand-written edge cases, each a fixed point of encode/decode.
#[cfg(feature = "json")]
#[test]
fn json_frame_seeds() {
    for seed in mavstack_core::fuzz_seeds("json_frames", 20) {
        mavstack_xml::json::fuzz_json_frames(&seed);
    }
}
