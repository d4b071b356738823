//! The `events` fuzz target's body: event metadata from a stranger (the vehicle serves it)
//! read, unpacked and used to fill EVENTs, with properties beyond "no panic".

use super::{Catalog, MAX_UNPACKED, XZ_MAGIC, events_uri, ftp_path, safe, unpack};

/// Fuzzing entry point for event metadata: the input as a metadata file (xz or JSON), its
/// tail (up to 40 bytes) as an EVENT's arguments. Properties:
/// - [`unpack`] returns (the xz decoder's panics are its errors), gives back a file that is
///   not xz unchanged, and never more than [`MAX_UNPACKED`] bytes of one that is;
/// - a [`Catalog`] read from it decodes every event it defines (and nothing else), the same
///   way twice, into text with no control character and no longer than the template and
///   the whole input allow for each of its arguments;
/// - the events URI of a general metadata file maps to an absolute MAVFTP path that is the
///   URI's own tail.
#[doc(hidden)]
pub fn fuzz_events(data: &[u8]) {
    let args = &data[data.len().saturating_sub(40)..];
    // `unpack` contains the xz decoder's own panics (lzma-rs 0.3.0's unchecked footer
    // arithmetic) and returns them as errors; the harness's hook would abort on the panic
    // before `unpack` catches it, so it is quiet for that call. A panic that leaves `unpack`
    // still reaches the harness and fails.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let unpacked = std::panic::catch_unwind(|| unpack(data));
    std::panic::set_hook(hook);
    let unpacked = unpacked.unwrap_or_else(|_| panic!("a panic left unpack"));
    let json = match unpacked {
        Ok(json) => {
            assert!(json.len() <= MAX_UNPACKED, "unpacked {} bytes", json.len());
            if !data.starts_with(XZ_MAGIC) {
                assert_eq!(json, data, "a file that is not xz was changed");
            }
            json
        }
        Err(_) => return,
    };
    if let Ok(catalog) = Catalog::from_json(&json) {
        for (&id, def) in &catalog.events {
            let once = catalog.decode(id, args).expect("a defined event decodes");
            assert_eq!(
                Some(&once),
                catalog.decode(id, args).as_ref(),
                "decoding is not pure"
            );
            assert_eq!(once.name, safe(&def.name));
            for text in [&once.text, &once.name, &once.group] {
                assert!(
                    !text.chars().any(char::is_control),
                    "control character in {text:?}"
                );
            }
            // Each of the template's characters expands to at most one argument's text, which
            // is at most a number or the enum descriptions the input holds.
            let bound = (def.message.len() + 1) * (json.len() + 64) * 3;
            assert!(
                once.text.len() <= bound,
                "{} bytes of text",
                once.text.len()
            );
            let other = id.wrapping_add(1);
            if !catalog.events.contains_key(&other) {
                assert!(
                    catalog.decode(other, args).is_none(),
                    "an undefined event decoded"
                );
            }
        }
    }
    if let Ok(Some(uri)) = events_uri(&json)
        && let Some(path) = ftp_path(&uri)
    {
        assert!(uri.starts_with("mftp://"), "{uri:?} is no mftp URI");
        assert!(path.starts_with('/'), "{path:?} is not absolute");
        assert!(
            uri.ends_with(path.trim_start_matches('/')),
            "{path:?} is not {uri:?}'s tail"
        );
    }
}
