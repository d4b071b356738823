use alloc::string::ToString;

use super::*;
use crate::camera::SIMULATED_DEFINITION;

fn sim() -> CameraDefinition {
    CameraDefinition::parse(SIMULATED_DEFINITION.as_bytes()).unwrap()
}

fn err(xml: &str) -> DefinitionError {
    CameraDefinition::parse(xml.as_bytes()).unwrap_err()
}

#[test]
fn reads_the_simulated_cameras_definition() {
    let d = sim();
    assert_eq!(
        (d.version, d.model.as_str(), d.vendor.as_str()),
        (1, "Simulated camera", "mavstack")
    );
    assert_eq!(d.settings.len(), 8);
    assert!(d.warnings.is_empty(), "{:?}", d.warnings);
    let mode = d.setting("CAM_MODE").unwrap();
    assert_eq!(mode.ty, ExtType::U32);
    assert!(!mode.control);
    assert_eq!(mode.options[1].name, "Video");
    assert_eq!(mode.options[1].exclusions, ["CAM_PHOTOFMT"]);
    let ev = d.setting("CAM_EV").unwrap();
    assert_eq!(
        (ev.min.clone(), ev.max.clone()),
        (Some(ExtValue::F32(-2.0)), Some(ExtValue::F32(2.0)))
    );
    assert_eq!(
        d.setting("CAM_EXPMODE").unwrap().updates,
        ["CAM_ISO", "CAM_SHUTTERSPD"]
    );
}

#[test]
fn exclusions_follow_the_current_choices() {
    let d = sim();
    let defaults = |_: &str| None;
    // Photo mode, auto exposure.
    let out = d.excluded(&defaults);
    assert!(out.contains("CAM_VIDRES") && out.contains("CAM_ISO") && !out.contains("CAM_EV"));
    let manual = |n: &str| (n == "CAM_EXPMODE").then_some(ExtValue::U32(1));
    let out = d.excluded(&manual);
    assert!(!out.contains("CAM_ISO") && out.contains("CAM_EV"));
    assert_eq!(
        d.check("CAM_ISO", &ExtValue::U32(400), &defaults),
        Err(SettingError::Excluded {
            name: "CAM_ISO".into(),
            by: "CAM_EXPMODE".into(),
            option: "Auto".into()
        })
    );
    assert_eq!(d.check("CAM_ISO", &ExtValue::U32(400), &manual), Ok(()));
}

#[test]
fn values_are_checked_against_options_and_limits() {
    let d = sim();
    let none = |_: &str| None;
    assert!(matches!(
        d.check("CAM_WBMODE", &ExtValue::U32(7), &none),
        Err(SettingError::NotAnOption { .. })
    ));
    assert!(matches!(
        d.check("CAM_EV", &ExtValue::F32(3.0), &none),
        Err(SettingError::OutOfRange { .. })
    ));
    assert_eq!(d.check("CAM_EV", &ExtValue::F32(-1.5), &none), Ok(()));
    assert!(matches!(
        d.check("CAM_EV", &ExtValue::U32(1), &none),
        Err(SettingError::WrongType { .. })
    ));
    assert!(matches!(
        d.check("CAM_NOPE", &ExtValue::U32(1), &none),
        Err(SettingError::Unknown(_))
    ));
    // By option name, any case, or by value.
    assert_eq!(d.value_of("CAM_WBMODE", "cloudy"), Ok(ExtValue::U32(2)));
    assert_eq!(
        d.value_of("CAM_SHUTTERSPD", "1/500"),
        Ok(ExtValue::F32(0.002))
    );
    assert_eq!(d.value_of("CAM_EV", "0.5"), Ok(ExtValue::F32(0.5)));
    assert!(d.value_of("CAM_EV", "bright").is_err());
}

#[test]
fn ranges_narrow_a_settings_options() {
    let xml = r#"<mavlinkcamera><definition version="2"><model>m</model><vendor>v</vendor></definition>
<parameters>
  <parameter name="CAM_EXPMODE" type="uint32" default="0">
    <options><option name="Auto" value="0"/><option name="Manual" value="1"/></options>
  </parameter>
  <parameter name="CAM_MODE" type="uint32" default="1">
    <options>
      <option name="Photo" value="0"/>
      <option name="Video" value="1">
        <parameterranges>
          <parameterrange parameter="CAM_ISO" condition="CAM_EXPMODE=1">
            <roption name="100" value="100"/><roption name="200" value="200"/>
          </parameterrange>
        </parameterranges>
      </option>
    </options>
  </parameter>
  <parameter name="CAM_ISO" type="int32" default="100">
    <options><option name="100" value="100"/><option name="200" value="200"/><option name="800" value="800"/></options>
  </parameter>
</parameters></mavlinkcamera>"#;
    let d = CameraDefinition::parse(xml.as_bytes()).unwrap();
    let auto = |_: &str| None;
    assert_eq!(d.options_of("CAM_ISO", &auto).len(), 3);
    let manual = |n: &str| (n == "CAM_EXPMODE").then_some(ExtValue::U32(1));
    assert_eq!(
        d.options_of("CAM_ISO", &manual),
        [
            ("100".to_string(), ExtValue::I32(100)),
            ("200".to_string(), ExtValue::I32(200))
        ]
    );
    assert!(d.check("CAM_ISO", &ExtValue::I32(800), &manual).is_err());
    assert!(d.check("CAM_ISO", &ExtValue::I32(800), &auto).is_ok());
}

#[test]
fn malformed_files_say_where() {
    let e = err("<mavlinkcamera>\n  <definition>\n</mavlinkcamera>");
    assert_eq!((e.line, e.column), (3, 1), "{e}");
    assert!(matches!(e.kind, DefinitionErrorKind::Xml(_)));
    let e = err("<camera/>");
    assert_eq!(
        e.kind,
        DefinitionErrorKind::NotACameraDefinition("camera".into())
    );
    let e = err("<mavlinkcamera><parameters/></mavlinkcamera>");
    assert_eq!(e.kind, DefinitionErrorKind::Missing("<definition>"));
    let head = "<mavlinkcamera><definition/>\n<parameters>\n";
    let e = err(&format!(
        "{head}  <parameter name=\"A\" type=\"uint8\" default=\"300\"/></parameters></mavlinkcamera>"
    ));
    assert_eq!((e.line, e.column), (3, 3), "{e}");
    assert_eq!(
        e.to_string(),
        "camera definition, line 3 column 3: A's default \"300\" is not valid"
    );
    let e = err(&format!(
        "{head}<parameter name=\"A\" type=\"string\" default=\"x\"/></parameters></mavlinkcamera>"
    ));
    assert!(matches!(e.kind, DefinitionErrorKind::Invalid { ref what, .. } if what == "A's type"));
    let e = err(&format!(
        "{head}<parameter name=\"A_NAME_LONGER_THAN_16\" type=\"uint8\" default=\"1\"/></parameters></mavlinkcamera>"
    ));
    assert!(matches!(e.kind, DefinitionErrorKind::Invalid { .. }));
    let e = err(&format!(
        "{head}<parameter name=\"A\" type=\"uint8\" default=\"1\"/>\n<parameter name=\"A\" type=\"uint8\" default=\"1\"/></parameters></mavlinkcamera>"
    ));
    assert_eq!(
        (e.line, e.kind),
        (4, DefinitionErrorKind::Duplicate("A".into()))
    );
    let e = err(&format!(
        "{head}<parameter name=\"A\" type=\"float\" default=\"1\"><options><option name=\"x\" value=\"fast\"/></options></parameter></parameters></mavlinkcamera>"
    ));
    assert!(
        matches!(e.kind, DefinitionErrorKind::Invalid { ref what, .. } if what.contains("option"))
    );
    assert!(matches!(err("\u{feff}").kind, DefinitionErrorKind::Xml(_)));
    assert_eq!(
        CameraDefinition::parse(&[0xff, 0xfe]).unwrap_err().kind,
        DefinitionErrorKind::NotText
    );
    let long = alloc::vec![b' '; MAX_DEFINITION_LEN + 1];
    assert!(matches!(
        CameraDefinition::parse(&long).unwrap_err().kind,
        DefinitionErrorKind::TooLong(_)
    ));
    // An entity bomb is not expanded.
    let bomb = r#"<!DOCTYPE x [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]><mavlinkcamera/>"#;
    assert!(matches!(err(bomb).kind, DefinitionErrorKind::Xml(_)));
}

#[test]
fn dangling_references_are_warnings() {
    let xml = r#"<mavlinkcamera><definition version="1"/><parameters>
<parameter name="A" type="uint8" default="0"><updates><update>NOPE</update></updates>
<options><option name="x" value="0"><exclusions><exclude>GONE</exclude></exclusions></option></options></parameter>
</parameters></mavlinkcamera>"#;
    let d = CameraDefinition::parse(xml.as_bytes()).unwrap();
    assert_eq!(d.warnings.len(), 2, "{:?}", d.warnings);
    assert!(d.warnings[0].contains("GONE") || d.warnings[1].contains("GONE"));
}
