//! `mavstack decode` and `mavstack encode` against pymavlink 2.4.50, the reference peer.
//!
//! No expectation is written by hand or produced by mavstack: for each test
//! `tests-interop/make_corpus.py` has pymavlink pack a random stream (every message of the
//! dialect, MAVLink 1 and 2, truncated payloads, signed frames, garbage, unknown ids, bad CRCs)
//! and decode it again into the JSON lines `mavstack decode` must print.
//! `tests-interop/compare_decode.py` compares those lines with ours (floats as their wire
//! type), and `tests-interop/check_encode.py` checks the bytes `mavstack encode` writes
//! against pymavlink's packing of the same JSON and pymavlink's parser (CRC, signature, and
//! `decode(encode(x)) == x`).
//!
//! The commands exercised, exactly:
//!
//! ```text
//! mavstack decode --dialect D FILE.bin                 (and the stream on stdin, no FILE)
//! mavstack decode --dialect D --key HEX FILE.bin       (and on stdin)
//! mavstack encode --dialect D FILE.jsonl               (and on stdin)
//! mavstack encode --dialect D --key HEX FILE.jsonl     (and on stdin)
//! ```
//!
//! for D in `ardupilotmega` and `all`. Python is `$MAVSTACK_PYTHON`, else
//! `<workspace>/.venv/bin/python` (`scripts/setup-peers.sh` creates it). If it cannot run or
//! lacks pymavlink 2.4.50 the tests fail; they are never skipped. On a failure the corpus and
//! our output are kept in a temporary directory whose path is printed. `MAVSTACK_INTEROP_SEED`
//! (added to each test's own seed) and `MAVSTACK_INTEROP_FRAMES` vary the corpus.

use crate::support;

use std::ffi::{OsStr, OsString};

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use support::{require_pymavlink, run_script, text};

/// The signing key of the signed corpora (an arbitrary test key).
const KEY: &str = "5f1e2d3c4b5a69788796a5b4c3d2e1f00f1e2d3c4b5a69788796a5b4c3d2e1f0";
/// Runs `mavstack ARGS`, with `stdin` fed to it when given.
fn mavstack(args: &[&OsStr], stdin: Option<Vec<u8>>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mavstack"));
    cmd.args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .stdin(if stdin.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        });
    let mut child = cmd.spawn().expect("mavstack runs");
    // Write stdin from another thread: the output may fill the pipe before the input ends.
    let writer = stdin.map(|data| {
        let mut pipe = child.stdin.take().expect("stdin pipe");
        std::thread::spawn(move || {
            // A broken pipe is the command's business; its status tells.
            let _ = pipe.write_all(&data);
        })
    });
    let out = child.wait_with_output().expect("mavstack finishes");
    if let Some(w) = writer {
        w.join().expect("stdin writer");
    }
    out
}

fn env_number(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.trim().parse().ok())
}

/// A pymavlink-made corpus in a temporary directory (kept when the test fails).
struct Corpus {
    dir: Option<tempfile::TempDir>,
    path: PathBuf,
    dialect: &'static str,
    key: Option<&'static str>,
}

impl Corpus {
    fn new(dialect: &'static str, seed: u64, key: Option<&'static str>) -> Self {
        require_pymavlink();
        let dir = tempfile::Builder::new()
            .prefix(&format!("mavstack-interop-{dialect}-"))
            .tempdir()
            .expect("temp dir");
        let path = dir.path().to_path_buf();
        let seed = seed + env_number("MAVSTACK_INTEROP_SEED").unwrap_or(0);
        let frames = env_number("MAVSTACK_INTEROP_FRAMES").unwrap_or(2500);
        let corpus = Self {
            dir: Some(dir),
            path,
            dialect,
            key,
        };
        let mut args: Vec<OsString> = vec![
            corpus.file("corpus").into(),
            "--dialect".into(),
            dialect.into(),
            "--seed".into(),
            seed.to_string().into(),
            "--frames".into(),
            frames.to_string().into(),
        ];
        if let Some(k) = key {
            args.extend(["--key".into(), k.into()]);
        }
        run_script("make_corpus.py", &os(&args));
        corpus
    }

    fn file(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    fn bin(&self) -> PathBuf {
        self.file("corpus.bin")
    }

    /// Expected `decode` output: with the key for a signed corpus.
    fn expected(&self) -> PathBuf {
        self.file("corpus.jsonl")
    }

    /// Expected `decode` output of a signed corpus without `--key`.
    fn expected_unkeyed(&self) -> PathBuf {
        self.file("corpus.unkeyed.jsonl")
    }

    fn common_args(&self, command: &str, with_key: bool) -> Vec<OsString> {
        let mut args: Vec<OsString> = vec![command.into(), "--dialect".into(), self.dialect.into()];
        if with_key {
            args.extend(["--key".into(), self.key.expect("a signed corpus").into()]);
        }
        args
    }

    /// Runs `mavstack ARGS` on `input`, given as a file argument or on stdin; it must succeed.
    /// Returns its output and the command as shown in messages.
    fn run(&self, mut args: Vec<OsString>, input: &Path, via_stdin: bool) -> (Output, String) {
        let stdin = if via_stdin {
            Some(std::fs::read(input).expect("input file"))
        } else {
            args.push(input.into());
            None
        };
        let out = mavstack(&os(&args), stdin);
        let shown = show(&args, via_stdin);
        assert!(
            out.status.success(),
            "{shown} failed ({}): {}",
            out.status,
            text(&out.stderr)
        );
        (out, shown)
    }

    /// `mavstack decode` of the corpus (from the file or from stdin), compared with `expected`.
    fn check_decode(&self, with_key: bool, via_stdin: bool, expected: &Path) {
        let (out, shown) = self.run(self.common_args("decode", with_key), &self.bin(), via_stdin);
        let actual = self.file(&format!(
            "decoded{}{}.jsonl",
            if with_key { "-key" } else { "" },
            if via_stdin { "-stdin" } else { "" }
        ));
        std::fs::write(&actual, &out.stdout).expect("write decode output");
        let summary = run_script(
            "compare_decode.py",
            &os(&[
                "--dialect".into(),
                self.dialect.into(),
                expected.into(),
                actual.clone().into(),
            ]),
        );
        eprintln!("{shown}: {}", summary.trim());
    }

    /// `mavstack encode` of the expected JSON lines, checked by pymavlink.
    fn check_encode(&self, via_stdin: bool) {
        let with_key = self.key.is_some();
        let mut check_args: Vec<OsString> = vec![
            "--dialect".into(),
            self.dialect.into(),
            "--orig".into(),
            self.bin().into(),
        ];
        if let Some(k) = self.key {
            check_args.extend(["--key".into(), k.into()]);
        }
        // The harness first proves that pymavlink re-encodes its own JSON losslessly.
        let mut self_check = vec![self.expected().into(), "--self-check".into()];
        self_check.extend(check_args.iter().cloned());
        run_script("check_encode.py", &os(&self_check));

        let (out, shown) = self.run(
            self.common_args("encode", with_key),
            &self.expected(),
            via_stdin,
        );
        let actual = self.file(if via_stdin {
            "encoded-stdin.bin"
        } else {
            "encoded.bin"
        });
        std::fs::write(&actual, &out.stdout).expect("write encode output");
        let mut args: Vec<OsString> = vec![self.expected().into(), actual.into()];
        args.extend(check_args);
        // MAVLink 1 frames whose extensions are all zero go out with the base fields only,
        // as the C library sends them (pymavlink sends the zeros too); every other byte must
        // be pymavlink's.
        args.push("--v1-base-ok".into());
        let summary = run_script("check_encode.py", &os(&args));
        eprintln!("{shown}: {}", summary.trim());
    }
}

impl Drop for Corpus {
    fn drop(&mut self) {
        if std::thread::panicking()
            && let Some(dir) = self.dir.take()
        {
            eprintln!("interop files kept in {}", dir.keep().display());
        }
    }
}

fn os(args: &[OsString]) -> Vec<&OsStr> {
    args.iter().map(OsString::as_os_str).collect()
}

fn show(args: &[OsString], via_stdin: bool) -> String {
    let mut s = String::from("mavstack");
    for a in args {
        s.push(' ');
        s.push_str(&a.to_string_lossy());
    }
    if via_stdin {
        s.push_str(" < stdin");
    }
    s
}

#[test]
fn decode_ardupilotmega_matches_pymavlink() {
    let c = Corpus::new("ardupilotmega", 101, None);
    c.check_decode(false, false, &c.expected());
    c.check_decode(false, true, &c.expected());
}

#[test]
fn decode_all_matches_pymavlink() {
    let c = Corpus::new("all", 102, None);
    c.check_decode(false, false, &c.expected());
    c.check_decode(false, true, &c.expected());
}

#[test]
fn decode_signed_ardupilotmega_matches_pymavlink() {
    let c = Corpus::new("ardupilotmega", 103, Some(KEY));
    c.check_decode(true, false, &c.expected());
    c.check_decode(true, true, &c.expected());
    c.check_decode(false, false, &c.expected_unkeyed());
}

#[test]
fn decode_signed_all_matches_pymavlink() {
    let c = Corpus::new("all", 104, Some(KEY));
    c.check_decode(true, false, &c.expected());
    c.check_decode(true, true, &c.expected());
    c.check_decode(false, false, &c.expected_unkeyed());
}

#[test]
fn encode_ardupilotmega_reproduces_pymavlink_bytes() {
    let c = Corpus::new("ardupilotmega", 105, None);
    c.check_encode(false);
    c.check_encode(true);
}

#[test]
fn encode_all_reproduces_pymavlink_bytes() {
    let c = Corpus::new("all", 106, None);
    c.check_encode(false);
    c.check_encode(true);
}

#[test]
fn encode_signed_ardupilotmega_reproduces_pymavlink_bytes() {
    let c = Corpus::new("ardupilotmega", 107, Some(KEY));
    c.check_encode(false);
    c.check_encode(true);
}

#[test]
fn encode_signed_all_reproduces_pymavlink_bytes() {
    let c = Corpus::new("all", 108, Some(KEY));
    c.check_encode(false);
    c.check_encode(true);
}

/// The counts line of `mavstack decode --count ARGS FILE`, with `stdin` fed to it.
fn counted(args: &[&str], file: &Path, stdin: Option<Vec<u8>>) -> serde_json::Value {
    let mut all: Vec<&OsStr> = ["decode", "--count"].iter().map(OsStr::new).collect();
    all.extend(args.iter().map(OsStr::new));
    all.push(file.as_os_str());
    let out = mavstack(&all, stdin);
    assert!(out.status.success(), "{}", text(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("one JSON object")
}

#[test]
fn count_of_a_file_in_parts_matches_pymavlink() {
    // A signed corpus copied end to end past 8 MiB: parsed in parts, one thread each.
    let c = Corpus::new("ardupilotmega", 105, Some(KEY));
    let one = std::fs::read(c.bin()).expect("the corpus");
    let copies = (9 << 20) / one.len() + 1;
    let big = c.file("big.bin");
    std::fs::write(&big, one.repeat(copies)).expect("the large file");
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(c.file("corpus.summary.json")).expect("summary"))
            .expect("JSON");
    let want = &summary["expected_decode_counts"];
    let times = |field: &str| want[field].as_u64().expect(field) * copies as u64;
    let keyed = ["--dialect", "ardupilotmega", "--key", KEY];
    let in_order = counted(&[&keyed[..], &["--threads", "1"]].concat(), &big, None);
    for (field, got) in [
        ("frames", "frames"),
        ("bytes", "bytes"),
        ("bad_crc", "bad_crc"),
        ("unknown_id", "unknown_id"),
        ("bad_signature_with_key", "bad_signature"),
    ] {
        assert_eq!(in_order[got], times(field), "{got}: {in_order}");
    }
    for threads in [None, Some("2"), Some("5")] {
        let mut args = keyed.to_vec();
        if let Some(n) = threads {
            args.extend(["--threads", n]);
        }
        assert_eq!(
            counted(&args, &big, None),
            in_order,
            "--threads {threads:?}"
        );
    }
    // A file name that is a pipe is read in order (it cannot be read in parts).
    let data = std::fs::read(&big).expect("the large file");
    let from_pipe = counted(&keyed, Path::new("/dev/stdin"), Some(data));
    assert_eq!(from_pipe, in_order, "/dev/stdin, a pipe");
}
