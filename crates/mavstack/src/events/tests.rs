use super::*;

/// A catalog shaped as PX4's all_events.json is (objects keyed by id and name), with a
/// bitfield, an enum from another namespace and the template features.
const PX4_LIKE: &str = r#"{
  "version": 1,
  "components": {
    "0": {"namespace": "common", "enums": {"side_t": {"type": "uint8_t", "is_bitfield": true,
        "entries": {"1": {"name": "top", "description": "Top"}, "4": {"name": "left", "description": "Left"}}}}},
    "1": {"namespace": "px4", "component_id": 1,
      "enums": {"arming_state_t": {"name": "arming_state_t", "type": "uint8_t",
        "entries": {"0": {"name": "init", "description": "Init"}, "1": {"name": "standby", "description": "Standby"}}}},
      "event_groups": {
        "default": {"name": "default", "events": {
          "7372373": {"name": "commander_arm_denied_resolve_failures",
                      "message": "Arming denied: Resolve system health failures first"},
          "12": {"name": "alt", "message": "Altitude {1:.1m_v}, speed {2:.2m/s}, raw {3}, <param>MPC_Z_VEL</param>",
                 "arguments": [{"type": "float", "name": "a"}, {"type": "float", "name": "s"}, {"type": "int16_t", "name": "r"}]},
          "13": {"name": "sides", "message": "Sides {1}, state {2}\\{literal\\} <a href=\"https://x\">docs</a><profile name=\"dev\"> (dev only)</profile><profile name=\"!dev\"> (normal)</profile><b>gone</b>",
                 "arguments": [{"type": "common::side_t", "name": "s"}, {"type": "arming_state_t", "name": "a"}]}
        }},
        "arming_check": {"name": "arming_check", "events": {
          "99": {"name": "bad_arg", "message": "x {1}", "arguments": [{"type": "nope_t", "name": "x"}]},
          "100": {"name": "out_of_range", "message": "{1} {5} {0} {x} {2", "arguments": [{"type": "uint64_t", "name": "v"}]}
        }}
      }
    }
  }
}"#;

/// `json` packed as xz (as the simulator packs its metadata).
fn pack(json: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut input = json;
    lzma_rs::xz_compress(&mut input, &mut out).expect("into a Vec");
    out
}

fn px4() -> Catalog {
    Catalog::from_json(PX4_LIKE.as_bytes()).expect("parses")
}

fn args(parts: &[&[u8]]) -> [u8; 40] {
    let mut a = [0u8; 40];
    let mut at = 0;
    for p in parts {
        a[at..at + p.len()].copy_from_slice(p);
        at += p.len();
    }
    a
}

#[test]
fn ids_are_the_component_in_the_top_byte_and_the_sub_id_below() {
    let c = px4();
    let e = c.decode((1 << 24) | 7_372_373, &[0; 40]).expect("defined");
    assert_eq!(e.name, "commander_arm_denied_resolve_failures");
    assert_eq!(e.group, "default");
    assert_eq!(
        e.text,
        "Arming denied: Resolve system health failures first"
    );
    assert!(
        c.decode(7_372_373, &[0; 40]).is_none(),
        "component 0 has no such event"
    );
    // An argument of an unknown type drops the event, as libevents does.
    assert!(c.decode((1 << 24) | 99, &[0; 40]).is_none());
    assert_eq!(c.len(), 4);
}

#[test]
fn arguments_take_decimals_units_and_tags() {
    let c = px4();
    let a = args(&[
        &12.345f32.to_le_bytes(),
        &3.0f32.to_le_bytes(),
        &(-7i16).to_le_bytes(),
    ]);
    let e = c.decode((1 << 24) | 12, &a).expect("defined");
    assert_eq!(e.text, "Altitude 12.3 m, speed 3.00 m/s, raw -7, MPC_Z_VEL");
}

#[test]
fn enums_bitfields_profiles_links_and_escapes() {
    let c = px4();
    let e = c
        .decode((1 << 24) | 13, &args(&[&[5], &[1]]))
        .expect("defined");
    assert_eq!(
        e.text,
        "Sides Top|Left, state Standby{literal} docs (normal)"
    );
    let e = c
        .decode((1 << 24) | 13, &args(&[&[2], &[9]]))
        .expect("defined");
    assert_eq!(
        e.text,
        "Sides (unknown: 2), state (unknown: 9){literal} docs (normal)"
    );
}

#[test]
fn placeholders_that_name_no_argument_stay_as_written() {
    let c = px4();
    let e = c
        .decode((1 << 24) | 100, &args(&[&u64::MAX.to_le_bytes()]))
        .expect("defined");
    assert_eq!(e.text, "18446744073709551615 {5} {0} {x} {2");
}

#[test]
fn arguments_past_the_40_bytes_are_unknown_not_a_panic() {
    let c = px4();
    let e = c.decode((1 << 24) | 12, &[0; 6]).expect("defined");
    assert_eq!(
        e.text,
        "Altitude 0.0 m, speed (unknown), raw (unknown), MPC_Z_VEL"
    );
}

#[test]
fn arrays_serve_as_well_as_objects() {
    let json = r#"{"version": 1, "components": [{"namespace": "x", "component_id": 200,
        "event_groups": [{"name": "g", "events": [{"sub_id": 5, "name": "n", "message": "hello\u0007 {1}",
        "arguments": [{"type": "uint8_t", "name": "a"}]}]}]}]}"#;
    let c = Catalog::from_json(json.as_bytes()).expect("parses");
    let e = c.decode((200 << 24) | 5, &[42; 40]).expect("defined");
    assert_eq!(
        (e.group.as_str(), e.text.as_str()),
        ("g", "hello\u{fffd} 42")
    );
}

/// PX4 1.16's `all_events.json` as it is shaped: version 2 with its `translation` hints,
/// components by id, groups without a `name` (their key is the name), an enum type named
/// without its namespace, and the arming check summary event (`"type": "summary"`).
#[test]
fn px4_1_16_metadata_reads() {
    let json = serde_json::json!({
        "version": 2,
        "translation": {"items": {"components": {}}},
        "components": {"1": {"namespace": "px4", "enums": {"navigation_mode_group_t": {
            "type": "uint32_t", "is_bitfield": true, "entries": {"1": {"name": "manual", "description": "Manual"}}}},
          "event_groups": {"arming_check": {"events": {
            "13835193": {"name": "check_modes_local_pos", "message": "Navigation error: No valid position estimate",
                "arguments": [{"name": "modes", "type": "navigation_mode_group_t"},
                              {"name": "health_component_index", "type": "uint8_t"}]},
            "11047904": {"name": "commander_arming_check_summary", "type": "summary",
                "message": "Arming check summary event",
                "arguments": [{"name": "chunk_idx", "type": "uint8_t"}]}}}}}}
    });
    let catalog = Catalog::from_json(json.to_string().as_bytes()).expect("version 2 reads");
    let e = catalog
        .decode(0x01d3_1bb9, &[0; 40])
        .expect("check_modes_local_pos");
    assert_eq!(
        (e.group.as_str(), e.text.as_str(), e.summary),
        (
            "arming_check",
            "Navigation error: No valid position estimate",
            false
        )
    );
    assert!(
        catalog
            .decode(0x01a8_93e0, &[0; 40])
            .expect("summary")
            .summary
    );
}

#[test]
fn bad_files_say_what_is_wrong() {
    for (json, what) in [
        ("not json", "not JSON"),
        (r#"{"version": 0, "components": {}}"#, "version 0"),
        (r#"{"components": {}}"#, "(none)"),
        (r#"{"version": 1}"#, "no \"components\""),
    ] {
        let e = Catalog::from_json(json.as_bytes()).expect_err(json);
        assert!(e.to_string().contains(what), "{json}: {e}");
    }
}

#[test]
fn deeply_nested_tags_do_not_recurse_without_bound() {
    let depth = 10_000;
    let message = format!("{}x{}", "<a>".repeat(depth), "</a>".repeat(depth));
    let json = serde_json::json!({"version": 1, "components": {"1": {"namespace": "p",
        "event_groups": {"g": {"events": {"1": {"name": "deep", "message": message}}}}}}});
    let c = Catalog::from_json(json.to_string().as_bytes()).expect("parses");
    let e = c.decode((1 << 24) | 1, &[0; 40]).expect("defined");
    assert!(e.text.contains('x'));
}

/// `{"version": 1, "components": {}}` packed by liblzma (Python's `lzma.compress`: xz's own
/// encoder, with a CRC64 check, as PX4's build packs its metadata).
const LIBLZMA_PACKED: &[u8] = &[
    0xfd, 0x37, 0x7a, 0x58, 0x5a, 0x00, 0x00, 0x04, 0xe6, 0xd6, 0xb4, 0x46, 0x02, 0x00, 0x21, 0x01,
    0x16, 0x00, 0x00, 0x00, 0x74, 0x2f, 0xe5, 0xa3, 0x01, 0x00, 0x1f, 0x7b, 0x22, 0x76, 0x65, 0x72,
    0x73, 0x69, 0x6f, 0x6e, 0x22, 0x3a, 0x20, 0x31, 0x2c, 0x20, 0x22, 0x63, 0x6f, 0x6d, 0x70, 0x6f,
    0x6e, 0x65, 0x6e, 0x74, 0x73, 0x22, 0x3a, 0x20, 0x7b, 0x7d, 0x7d, 0x00, 0x62, 0xa8, 0x0e, 0x99,
    0x55, 0x14, 0x34, 0xe0, 0x00, 0x01, 0x38, 0x20, 0x18, 0x29, 0x77, 0x0c, 0x1f, 0xb6, 0xf3, 0x7d,
    0x01, 0x00, 0x00, 0x00, 0x00, 0x04, 0x59, 0x5a,
];

#[test]
fn xz_files_unpack_and_plain_ones_pass() {
    let small = unpack(LIBLZMA_PACKED).expect("unpacks");
    assert_eq!(small, br#"{"version": 1, "components": {}}"#);
    assert!(Catalog::from_json(&small).expect("parses").is_empty());
    // A flipped byte of the data fails the check; a cut file fails too.
    let mut damaged = LIBLZMA_PACKED.to_vec();
    damaged[40] ^= 0x01;
    assert!(unpack(&damaged).is_err());
    assert!(unpack(&LIBLZMA_PACKED[..LIBLZMA_PACKED.len() - 8]).is_err());
    // Ours (the simulator's) round-trips; a plain file passes as it is.
    let json = PX4_LIKE.as_bytes();
    let packed = pack(json);
    assert!(packed.starts_with(&[0xfd, b'7', b'z', b'X', b'Z', 0]));
    assert_eq!(unpack(&packed).expect("unpacks"), json);
    assert_eq!(unpack(json).expect("plain"), json);
}

#[test]
fn an_xz_bomb_stops_at_the_limit() {
    let zeros = vec![0u8; MAX_UNPACKED + 1];
    let packed = pack(&zeros);
    assert!(matches!(unpack(&packed), Err(EventsError::TooLarge)));
}

#[test]
fn the_general_file_names_the_events_file() {
    let general = br#"{"version": 1, "metadataTypes": [
        {"type": 1, "uri": "mftp://etc/extras/parameters.json.xz", "fileCrc": 1},
        {"type": 4, "uri": "mftp://etc/extras/all_events.json.xz", "fileCrc": 2}]}"#;
    let uri = events_uri(general).expect("json").expect("named");
    assert_eq!(
        ftp_path(&uri).as_deref(),
        Some("/etc/extras/all_events.json.xz")
    );
    assert_eq!(events_uri(br#"{"version": 1}"#).expect("json"), None);
    assert_eq!(
        ftp_path("mftp://[;comp=1]etc/x.json").as_deref(),
        Some("/etc/x.json")
    );
    assert_eq!(ftp_path("https://example.com/x.json"), None);
    assert_eq!(ftp_path("mftp://"), None);
}

proptest::proptest! {
    /// Any template and arguments: no panic, nothing a terminal would act on, and text
    /// without tags or placeholders comes out as written (escapes aside).
    #[test]
    fn any_template_gives_safe_text(
        message in "[ -~\\x00-\\x1f\u{80}-\u{200}]{0,120}",
        args in proptest::collection::vec(proptest::num::u8::ANY, 0..48),
    ) {
        let json = serde_json::json!({"version": 1, "components": {"1": {"namespace": "p",
            "enums": {"e_t": {"type": "uint16_t", "is_bitfield": true,
                "entries": {"1": {"name": "a", "description": "A"}}}},
            "event_groups": {"g": {"events": {"3": {"name": "n", "message": message,
                "arguments": [{"type": "float", "name": "f"}, {"type": "e_t", "name": "e"},
                              {"type": "int64_t", "name": "i"}]}}}}}}});
        let c = Catalog::from_json(json.to_string().as_bytes()).expect("parses");
        let e = c.decode((1 << 24) | 3, &args).expect("defined");
        proptest::prop_assert!(!e.text.chars().any(char::is_control), "{:?}", e.text);
        if !message.contains(['<', '{', '\\']) {
            let plain: String = message
                .trim()
                .chars()
                .map(|c| if c.is_control() { '\u{fffd}' } else { c })
                .collect();
            proptest::prop_assert_eq!(e.text, plain);
        }
    }

    /// Any bytes as a metadata file, plain or as xz: an error or a catalog, never a panic.
    #[test]
    fn any_file_is_an_error_or_a_catalog(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..200)) {
        let _ = Catalog::from_json(&bytes);
        let mut xz = LIBLZMA_PACKED.to_vec();
        let at = bytes.first().map_or(0, |&b| usize::from(b) % xz.len());
        xz[at] ^= bytes.get(1).copied().unwrap_or(1) | 1;
        if let Ok(json) = unpack(&xz) {
            let _ = Catalog::from_json(&json);
        }
        let _ = events_uri(&bytes);
    }
}

/// A Backward Size of 0xFFFFFFFF in the footer (lzma-rs 0.3.0 adds 1 to it unchecked: a
/// panic with overflow checks, found by the fuzz target) and one pointing before the file's
/// start are refused as damaged; the file as packed still unpacks.
#[test]
fn a_footer_pointing_outside_the_file_is_refused() {
    let json = br#"{"version": 1, "components": {}}"#;
    let packed = pack(json);
    assert_eq!(unpack(&packed).expect("as packed"), json);
    let at = packed.len() - 8;
    for backward in [u32::MAX, 1000] {
        let mut damaged = packed.clone();
        damaged[at..at + 4].copy_from_slice(&backward.to_le_bytes());
        let e = unpack(&damaged).expect_err("a footer pointing outside");
        assert!(e.to_string().contains("stream footer"), "{e}");
    }
    assert!(unpack(&packed[..packed.len() - 1]).is_err());
}
