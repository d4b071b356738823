//! Client against server in memory, a lossy wire, a malicious client, a lying server.

use alloc::string::String;
use alloc::vec;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{FileTransferProtocol, MavMessage};

use super::*;
use crate::{Address, Outgoing, Service};

const GCS: Address = Address::new(255, 190);
const OTHER: Address = Address::new(254, 190);
const VEHICLE: Address = Address::new(1, 1);

/// CRC32 computed independently of `payload::crc32`: table driven, zlib-style (seeded and
/// finally inverted by 0xFFFFFFFF), then undone to the servers' raw value.
fn independent_crc(data: &[u8]) -> u32 {
    let mut table = [0u32; 256];
    for (i, t) in table.iter_mut().enumerate() {
        let mut c = i as u32;
        for _ in 0..8 {
            c = if c & 1 == 1 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
        *t = c;
    }
    // zlib.crc32(data, 0xffffffff): its inversion of the seed leaves 0 in the register.
    let mut reg = 0u32;
    for &b in data {
        reg = table[((reg ^ u32::from(b)) & 0xFF) as usize] ^ (reg >> 8);
    }
    let zlib_value = !reg;
    zlib_value ^ 0xFFFF_FFFF
}

fn pattern(n: usize) -> Vec<u8> {
    (0..n).map(|i| (i * 7 + i / 251) as u8).collect()
}

struct Wire {
    client: FtpClient,
    server: FtpServer<MemoryBackend>,
    now: Instant,
    /// Drop every n-th message in each direction (0: none).
    drop_every: usize,
    up: usize,
    down: usize,
    progress: Vec<(u64, u64)>,
}

impl Wire {
    fn new(config: ClientConfig) -> Self {
        Self {
            client: FtpClient::new(GCS, VEHICLE, config),
            server: FtpServer::new(VEHICLE, ServerConfig::default(), MemoryBackend::new()),
            now: Instant::from_secs(1),
            drop_every: 0,
            up: 0,
            down: 0,
            progress: Vec::new(),
        }
    }

    fn lossy(mut self, n: usize) -> Self {
        self.drop_every = n;
        self
    }

    fn run(&mut self) -> Result<FtpOutput, FtpError> {
        for _ in 0..200_000 {
            let mut moved = false;
            while let Some(out) = self.client.poll_transmit() {
                moved = true;
                self.up += 1;
                if self.drop_every == 0 || !self.up.is_multiple_of(self.drop_every) {
                    self.server.handle_message(self.now, GCS, &out.message);
                }
            }
            while let Some(out) = self.server.poll_transmit() {
                moved = true;
                assert_eq!(out.target, GCS);
                self.down += 1;
                if self.drop_every == 0 || !self.down.is_multiple_of(self.drop_every) {
                    self.client.handle_message(self.now, VEHICLE, &out.message);
                }
            }
            while let Some(ev) = self.client.poll_event() {
                match ev {
                    FtpEvent::Finished(r) => return r,
                    FtpEvent::Progress { done, total } => {
                        assert!(done <= total);
                        self.progress.push((done, total));
                    }
                }
            }
            if !moved {
                let next = [self.client.poll_timeout(), self.server.poll_timeout()]
                    .into_iter()
                    .flatten()
                    .min()
                    .expect("nothing moves and nothing is due");
                self.now = self.now.max(next);
                self.client.handle_timeout(self.now);
                self.server.handle_timeout(self.now);
            }
            self.now += Duration::from_micros(100);
        }
        panic!("did not finish");
    }
}

#[test]
fn write_read_crc_for_every_size() {
    for burst in [true, false] {
        let mut w = Wire::new(ClientConfig {
            burst,
            ..Default::default()
        });
        for n in [0, 1, 238, 239, 240, 10_000] {
            let data = pattern(n);
            let path = alloc::format!("/f{n}.bin");
            w.client.write(w.now, &path, &data).unwrap();
            assert_eq!(w.run(), Ok(FtpOutput::Done));
            assert_eq!(w.server.backend().file(&path[1..]), Some(&data[..]));
            w.client.read(w.now, &path).unwrap();
            assert_eq!(
                w.run(),
                Ok(FtpOutput::Data(data.clone())),
                "{n} bytes, burst {burst}"
            );
            w.client.crc32(w.now, &path).unwrap();
            assert_eq!(w.run(), Ok(FtpOutput::Crc32(independent_crc(&data))));
        }
        assert_eq!(w.progress.last(), Some(&(10_000, 10_000)));
        assert_eq!(w.server.open_sessions(), 0);
    }
}

#[test]
fn directories_names_with_spaces_list_remove_rename() {
    let mut w = Wire::new(ClientConfig::default());
    let mut dir = String::new();
    for part in ["a", "b c", "d", "e", "f g", "h", "i", "j"] {
        dir = if dir.is_empty() {
            part.into()
        } else {
            alloc::format!("{dir}/{part}")
        };
        w.client.mkdir(w.now, &dir).unwrap();
        assert_eq!(w.run(), Ok(FtpOutput::Done));
    }
    let file = alloc::format!("{dir}/my file.txt");
    w.client.write(w.now, &file, b"hello world").unwrap();
    assert_eq!(w.run(), Ok(FtpOutput::Done));
    w.client
        .mkdir(w.now, &alloc::format!("{dir}/sub dir"))
        .unwrap();
    assert_eq!(w.run(), Ok(FtpOutput::Done));
    w.client.list(w.now, &dir).unwrap();
    let Ok(FtpOutput::Listing(mut entries)) = w.run() else {
        panic!()
    };
    entries.sort_by(|a, b| a.name.cmp(&b.name));
    assert_eq!(
        entries,
        vec![
            DirEntry {
                name: "my file.txt".into(),
                kind: EntryKind::File { size: 11 }
            },
            DirEntry {
                name: "sub dir".into(),
                kind: EntryKind::Directory
            },
        ]
    );
    // Many entries: several ListDirectory pages.
    for i in 0..40 {
        assert!(
            w.server
                .backend_mut()
                .insert_file(&alloc::format!("many/file number {i}"), &[0; 3])
        );
    }
    w.client.list(w.now, "/many").unwrap();
    let Ok(FtpOutput::Listing(entries)) = w.run() else {
        panic!()
    };
    assert_eq!(entries.len(), 40);
    // Empty directory, missing directory.
    w.client
        .list(w.now, &alloc::format!("{dir}/sub dir"))
        .unwrap();
    assert_eq!(w.run(), Ok(FtpOutput::Listing(Vec::new())));
    w.client.list(w.now, "nope").unwrap();
    assert_eq!(
        w.run(),
        Err(FtpError::Nak {
            code: NakCode::FileNotFound,
            errno: None
        })
    );

    w.client.rename(w.now, &file, "a/renamed.txt").unwrap();
    assert_eq!(w.run(), Ok(FtpOutput::Done));
    assert_eq!(
        w.server.backend().file("a/renamed.txt"),
        Some(&b"hello world"[..])
    );
    w.client.read(w.now, &file).unwrap();
    assert_eq!(
        w.run(),
        Err(FtpError::Nak {
            code: NakCode::FileNotFound,
            errno: None
        })
    );
    w.client.rmdir(w.now, "a").unwrap();
    assert_eq!(
        w.run(),
        Err(FtpError::Nak {
            code: NakCode::FailErrno,
            errno: Some(39)
        })
    );
    w.client.remove(w.now, "a/renamed.txt").unwrap();
    assert_eq!(w.run(), Ok(FtpOutput::Done));
    assert!(w.server.backend().file("a/renamed.txt").is_none());
    w.client.remove(w.now, "a/renamed.txt").unwrap();
    assert_eq!(
        w.run(),
        Err(FtpError::Nak {
            code: NakCode::FileNotFound,
            errno: None
        })
    );
    w.client
        .rmdir(w.now, &alloc::format!("{dir}/sub dir"))
        .unwrap();
    assert_eq!(w.run(), Ok(FtpOutput::Done));
    assert!(!w.server.backend().is_dir(&alloc::format!("{dir}/sub dir")));
    // One operation at a time.
    w.client.remove(w.now, "x").unwrap();
    assert_eq!(w.client.remove(w.now, "y"), Err(StartError::Busy));
    assert!(w.run().is_err());
}

#[test]
fn a_lossy_wire_still_completes() {
    for burst in [true, false] {
        let mut w = Wire::new(ClientConfig {
            burst,
            ..Default::default()
        })
        .lossy(5);
        let data = pattern(10_000);
        w.client.write(w.now, "/logs/x.bin", &data).unwrap();
        // No parent directory yet.
        assert_eq!(
            w.run(),
            Err(FtpError::Nak {
                code: NakCode::FileNotFound,
                errno: None
            })
        );
        w.client.mkdir(w.now, "/logs").unwrap();
        assert_eq!(w.run(), Ok(FtpOutput::Done));
        w.client.write(w.now, "/logs/x.bin", &data).unwrap();
        assert_eq!(w.run(), Ok(FtpOutput::Done));
        assert_eq!(w.server.backend().file("logs/x.bin"), Some(&data[..]));
        w.client.read(w.now, "/logs/x.bin").unwrap();
        assert_eq!(w.run(), Ok(FtpOutput::Data(data.clone())));
        w.client.crc32(w.now, "/logs/x.bin").unwrap();
        assert_eq!(w.run(), Ok(FtpOutput::Crc32(independent_crc(&data))));
        for i in 0..30 {
            w.server
                .backend_mut()
                .insert_file(&alloc::format!("logs/{i:02} log.bin"), &[1]);
        }
        w.client.list(w.now, "logs").unwrap();
        let Ok(FtpOutput::Listing(entries)) = w.run() else {
            panic!()
        };
        assert_eq!(entries.len(), 31);
        w.client.rename(w.now, "logs/x.bin", "logs/y.bin").unwrap();
        assert_eq!(w.run(), Ok(FtpOutput::Done));
        assert!(w.up > 50 && w.down > 50);
        // Let idle sessions (a lost TerminateSession's) time out.
        w.now += Duration::from_secs(10);
        w.server.handle_timeout(w.now);
        assert_eq!(w.server.open_sessions(), 0);
    }
}

#[test]
fn a_dead_server_times_out() {
    let mut c = FtpClient::new(GCS, VEHICLE, ClientConfig::default());
    let mut now = Instant::from_secs(1);
    c.read(now, "x").unwrap();
    let mut sends = 0;
    loop {
        while c.poll_transmit().is_some() {
            sends += 1;
        }
        if let Some(FtpEvent::Finished(r)) = c.poll_event() {
            assert_eq!(r, Err(FtpError::TimedOut { attempts: 5 }));
            break;
        }
        now = c.poll_timeout().unwrap();
        c.handle_timeout(now);
    }
    assert_eq!(sends, 5);
    assert!(!c.is_busy());
}

/// `first_attempts` bounds only the operation's first request: a dead server is given up
/// after two sends, while a transfer under way keeps every attempt (a request answered only
/// at its fourth send still completes the read).
#[test]
fn first_attempts_bound_only_the_first_request() {
    let config = ClientConfig {
        first_attempts: 2,
        burst: false,
        ..ClientConfig::default()
    };
    let mut c = FtpClient::new(GCS, VEHICLE, config);
    let mut now = Instant::from_secs(1);
    c.read(now, "x").unwrap();
    let mut sends = 0;
    let result = loop {
        sends += sent(&mut c).len();
        if let Some(FtpEvent::Finished(r)) = c.poll_event() {
            break r;
        }
        now = c.poll_timeout().unwrap();
        c.handle_timeout(now);
    };
    assert_eq!(result, Err(FtpError::TimedOut { attempts: 2 }));
    assert_eq!(sends, 2);

    let file = pattern(100);
    let mut c = FtpClient::new(GCS, VEHICLE, config);
    c.read(now, "x").unwrap();
    let open = sent(&mut c).remove(0);
    let mut ack = Payload::request(open.seq + 1, 1, Opcode::Ack, 0, &100u32.to_le_bytes());
    ack.req_opcode = Opcode::OpenFileRO;
    deliver(&mut c, now, &ack);
    let mut read = sent(&mut c).remove(0);
    for _ in 0..3 {
        // Lost: the read is sent again, past first_attempts.
        now = c.poll_timeout().unwrap();
        c.handle_timeout(now);
        read = sent(&mut c).remove(0);
        assert_eq!(read.opcode, Opcode::ReadFile);
    }
    let mut data = Payload::request(read.seq + 1, 1, Opcode::Ack, 0, &file);
    data.req_opcode = Opcode::ReadFile;
    deliver(&mut c, now, &data);
    let end = sent(&mut c).remove(0);
    let mut done = Payload::request(end.seq + 1, 1, Opcode::Ack, 0, &[]);
    done.req_opcode = Opcode::TerminateSession;
    deliver(&mut c, now, &done);
    let finished = core::iter::from_fn(|| c.poll_event()).last();
    assert_eq!(
        finished,
        Some(FtpEvent::Finished(Ok(FtpOutput::Data(file))))
    );
}

// ---- a malicious client, talking raw payloads ----

struct Raw {
    server: FtpServer<MemoryBackend>,
    now: Instant,
    seq: u16,
}

impl Raw {
    fn new() -> Self {
        let mut backend = MemoryBackend::new().with_max_file_size(4096);
        backend.insert_file("keep/secret.txt", b"secret");
        backend.insert_file("pub/a.txt", b"abc");
        Self {
            server: FtpServer::new(VEHICLE, ServerConfig::default(), backend),
            now: Instant::from_secs(1),
            seq: 100,
        }
    }

    fn raw(&mut self, from: Address, bytes: [u8; 251]) -> Vec<Payload> {
        let msg = MavMessage::FileTransferProtocol(FileTransferProtocol {
            target_network: 0,
            target_system: VEHICLE.system,
            target_component: VEHICLE.component,
            payload: bytes,
        });
        self.server.handle_message(self.now, from, &msg);
        let mut out = Vec::new();
        while let Some(o) = self.server.poll_transmit() {
            let MavMessage::FileTransferProtocol(m) = o.message else {
                panic!()
            };
            out.push(Payload::decode(&m.payload).unwrap());
            if out.len() > 1000 {
                break;
            }
        }
        out
    }

    fn ask(
        &mut self,
        from: Address,
        opcode: Opcode,
        session: u8,
        offset: u32,
        data: &[u8],
    ) -> Payload {
        self.seq = self.seq.wrapping_add(1);
        let p = Payload::request(self.seq, session, opcode, offset, data);
        let mut out = self.raw(from, p.encode());
        assert_eq!(out.len(), 1, "{out:?}");
        let r = out.remove(0);
        assert_eq!(r.seq, self.seq.wrapping_add(1));
        assert_eq!(r.req_opcode, opcode);
        r
    }
}

fn nak_of(p: &Payload) -> Option<(NakCode, Option<u8>)> {
    (p.opcode == Opcode::Nak).then(|| p.nak()).flatten()
}

#[test]
fn a_malicious_client_gets_naks_and_touches_nothing_outside() {
    let mut r = Raw::new();
    for i in 0..10 {
        let name = alloc::format!("pub/n{i}.txt");
        r.server.backend_mut().insert_file(&name, b"n");
    }
    let before: Vec<_> = r.server.backend().paths().map(String::from).collect();
    for path in [
        &b"../x"[..],
        b"/../../etc/passwd",
        b"pub/../keep/secret.txt",
        b"a/..",
    ] {
        for op in [
            Opcode::OpenFileRO,
            Opcode::OpenFileWO,
            Opcode::CreateFile,
            Opcode::RemoveFile,
            Opcode::RemoveDirectory,
            Opcode::CreateDirectory,
            Opcode::ListDirectory,
            Opcode::CalcFileCRC32,
            Opcode::TruncateFile,
        ] {
            let a = r.ask(GCS, op, 0, 0, path);
            assert_eq!(nak_of(&a), Some((NakCode::Fail, None)), "{op:?}");
        }
        let mut rename = b"pub/a.txt\0".to_vec();
        rename.extend_from_slice(path);
        assert_eq!(
            nak_of(&r.ask(GCS, Opcode::Rename, 0, 0, &rename)),
            Some((NakCode::Fail, None))
        );
    }
    assert_eq!(
        nak_of(&r.ask(GCS, Opcode::Rename, 0, 0, b"no nul")),
        Some((NakCode::InvalidDataSize, None))
    );
    // Unknown opcodes, replies sent to the server, a size byte past the data area.
    for op in [16u8, 100, 127, 130, 255] {
        let a = r.ask(GCS, Opcode::from_u8(op), 0, 0, &[]);
        assert_eq!(nak_of(&a), Some((NakCode::UnknownCommand, None)));
    }
    let mut bad = Payload::request(7, 0, Opcode::ReadFile, 0, &[]).encode();
    bad[4] = 250;
    let out = r.raw(GCS, bad);
    assert_eq!(nak_of(&out[0]), Some((NakCode::InvalidDataSize, None)));
    assert!(
        r.raw(GCS, Payload::request(7, 0, Opcode::Ack, 0, &[]).encode())
            .is_empty()
    );
    // Huge offsets.
    let open = r.ask(GCS, Opcode::OpenFileWO, 0, 0, b"pub/a.txt");
    assert_eq!(open.opcode, Opcode::Ack);
    let s = open.session;
    let a = r.ask(GCS, Opcode::WriteFile, s, u32::MAX - 10, &[1; 200]);
    assert_eq!(nak_of(&a), Some((NakCode::FailErrno, Some(28))));
    let a = r.ask(GCS, Opcode::ReadFile, s, u32::MAX, &[0; 239]);
    assert_eq!(nak_of(&a), Some((NakCode::Eof, None)));
    let a = r.ask(GCS, Opcode::TruncateFile, 0, u32::MAX, b"pub/a.txt");
    assert_eq!(nak_of(&a), Some((NakCode::FailErrno, Some(28))));
    let burst = Payload::request(9, s, Opcode::BurstReadFile, u32::MAX - 5, &[]);
    let out = r.raw(GCS, burst.encode());
    assert_eq!(out.len(), 1);
    assert_eq!(nak_of(&out[0]), Some((NakCode::Eof, None)));
    assert!(out[0].burst_complete);
    // Another client cannot use or close the session.
    assert_eq!(
        nak_of(&r.ask(OTHER, Opcode::ReadFile, s, 0, &[0; 10])),
        Some((NakCode::InvalidSession, None))
    );
    assert_eq!(
        nak_of(&r.ask(OTHER, Opcode::TerminateSession, s, 0, &[])),
        Some((NakCode::InvalidSession, None))
    );
    assert_eq!(
        r.ask(OTHER, Opcode::ResetSessions, 0, 0, &[]).opcode,
        Opcode::Ack
    );
    assert_eq!(r.server.open_sessions(), 1);
    // Sessions never closed: bounded, then timed out.
    for i in 0..10 {
        let name = alloc::format!("pub/n{i}.txt");
        r.ask(GCS, Opcode::OpenFileRO, 0, 0, name.as_bytes());
    }
    assert_eq!(r.server.open_sessions(), 4);
    let a = r.ask(OTHER, Opcode::OpenFileRO, 0, 0, b"pub/a.txt");
    assert_eq!(nak_of(&a), Some((NakCode::NoSessionsAvailable, None)));
    let due = r.server.poll_timeout().unwrap();
    assert!(due <= r.now + Duration::from_secs(5));
    r.now = due;
    r.server.handle_timeout(r.now);
    assert_eq!(r.server.open_sessions(), 0);
    assert_eq!(r.server.poll_timeout(), None);
    // Nothing outside what was addressed changed.
    let after: Vec<_> = r.server.backend().paths().map(String::from).collect();
    assert_eq!(before, after);
    assert_eq!(
        r.server.backend().file("keep/secret.txt"),
        Some(&b"secret"[..])
    );
    assert_eq!(r.server.backend().file("pub/a.txt"), Some(&b"abc"[..]));
}

#[test]
fn retransmissions_are_answered_without_redoing() {
    let mut r = Raw::new();
    let create = Payload::request(5, 0, Opcode::CreateFile, 0, b"pub/new.txt");
    let first = r.raw(GCS, create.encode());
    let again = r.raw(GCS, create.encode());
    assert_eq!(first, again);
    assert_eq!(r.server.open_sessions(), 1);
    let s = first[0].session;
    let write = Payload::request(6, s, Opcode::WriteFile, 0, b"xyz");
    assert_eq!(r.raw(GCS, write.encode()), r.raw(GCS, write.encode()));
    let rm = Payload::request(7, 0, Opcode::RemoveFile, 0, b"pub/a.txt");
    let first = r.raw(GCS, rm.encode());
    assert_eq!(first[0].opcode, Opcode::Ack);
    // Redone, this would be NAK FileNotFound.
    assert_eq!(r.raw(GCS, rm.encode()), first);
    // From another client the same bytes are a new request.
    assert_eq!(
        nak_of(&r.raw(OTHER, rm.encode())[0]),
        Some((NakCode::FileNotFound, None))
    );
    assert_eq!(r.server.backend().file("pub/new.txt"), Some(&b"xyz"[..]));
    // The same bytes long after are a new client's question (a new process whose numbers
    // start where the last one's did), answered afresh.
    r.now += Duration::from_secs(60);
    assert_eq!(
        nak_of(&r.raw(GCS, rm.encode())[0]),
        Some((NakCode::FileNotFound, None))
    );
}

#[test]
fn a_client_can_start_its_numbers_where_another_stopped() {
    let mut a = FtpClient::new(GCS, VEHICLE, ClientConfig::default()).starting_after(u16::MAX);
    a.list(Instant::from_secs(1), "").unwrap();
    let Some(Outgoing {
        message: MavMessage::FileTransferProtocol(m),
        ..
    }) = a.poll_transmit()
    else {
        panic!("no request")
    };
    assert_eq!(Payload::decode(&m.payload).unwrap().seq, 0, "wraps");
    assert_eq!(a.last_seq(), 0);
}

#[test]
fn bursts_stream_and_end() {
    let mut r = Raw::new();
    let data = pattern(1000);
    r.server.backend_mut().insert_file("big", &data);
    let open = r.ask(GCS, Opcode::OpenFileRO, 0, 0, b"big");
    assert_eq!(open.data, 1000u32.to_le_bytes());
    let out = r.raw(
        GCS,
        Payload::request(50, open.session, Opcode::BurstReadFile, 0, &[0; 239]).encode(),
    );
    // 239 × 4 + 44, then the EOF NAK that completes the burst.
    assert_eq!(out.len(), 6);
    let mut got = Vec::new();
    for (i, p) in out.iter().enumerate() {
        assert_eq!(p.seq, 51 + i as u16);
        assert_eq!(p.req_opcode, Opcode::BurstReadFile);
        if p.opcode == Opcode::Ack {
            assert_eq!(p.offset as usize, got.len());
            got.extend_from_slice(&p.data);
        }
    }
    assert_eq!(got, data);
    assert_eq!(nak_of(&out[5]), Some((NakCode::Eof, None)));
    assert!(out[5].burst_complete && !out[4].burst_complete);
}

#[test]
fn a_lying_server_cannot_make_the_client_write_outside_the_file() {
    let mut c = FtpClient::new(GCS, VEHICLE, ClientConfig::default());
    let now = Instant::from_secs(1);
    let deliver = |c: &mut FtpClient, p: Payload| {
        let msg = MavMessage::FileTransferProtocol(FileTransferProtocol {
            target_network: 0,
            target_system: GCS.system,
            target_component: GCS.component,
            payload: p.encode(),
        });
        c.handle_message(now, VEHICLE, &msg)
    };
    let sent = |c: &mut FtpClient| {
        let o = c.poll_transmit().unwrap();
        let MavMessage::FileTransferProtocol(m) = o.message else {
            panic!()
        };
        Payload::decode(&m.payload).unwrap()
    };
    c.read(now, "f").unwrap();
    let open = sent(&mut c);
    let mut ack = Payload::request(
        open.seq.wrapping_add(1),
        3,
        Opcode::Ack,
        0,
        &10u32.to_le_bytes(),
    );
    ack.req_opcode = Opcode::OpenFileRO;
    assert!(deliver(&mut c, ack));
    let burst = sent(&mut c);
    assert_eq!(
        (burst.opcode, burst.session, burst.offset),
        (Opcode::BurstReadFile, 3, 0)
    );
    let burst_reply = |seq: u16, offset: u32, data: &[u8], complete: bool| {
        let mut p = Payload::request(seq, 3, Opcode::Ack, offset, data);
        p.req_opcode = Opcode::BurstReadFile;
        p.burst_complete = complete;
        p
    };
    // Far past the end, and overlapping the end: only bytes 5..10 are kept.
    assert!(deliver(
        &mut c,
        burst_reply(burst.seq.wrapping_add(1), u32::MAX - 3, &[0xEE; 239], false)
    ));
    assert!(deliver(
        &mut c,
        burst_reply(burst.seq.wrapping_add(2), 5, &[0xAA; 239], true)
    ));
    // The gap 0..5 is asked for with ReadFile.
    let read = sent(&mut c);
    assert_eq!(
        (read.opcode, read.offset, read.data.len()),
        (Opcode::ReadFile, 0, 5)
    );
    let mut rr = Payload::request(read.seq.wrapping_add(1), 3, Opcode::Ack, 0, &[0xBB; 239]);
    rr.req_opcode = Opcode::ReadFile;
    // A reply with the wrong sequence number is ignored.
    rr.seq = rr.seq.wrapping_add(7);
    assert!(!deliver(&mut c, rr.clone()));
    rr.seq = read.seq.wrapping_add(1);
    assert!(deliver(&mut c, rr));
    let term = sent(&mut c);
    assert_eq!((term.opcode, term.session), (Opcode::TerminateSession, 3));
    let mut t = Payload::request(term.seq.wrapping_add(1), 3, Opcode::Ack, 0, &[]);
    t.req_opcode = Opcode::TerminateSession;
    assert!(deliver(&mut c, t));
    let mut last = None;
    while let Some(e) = c.poll_event() {
        last = Some(e);
    }
    let mut want = vec![0xBB; 5];
    want.extend_from_slice(&[0xAA; 5]);
    assert_eq!(last, Some(FtpEvent::Finished(Ok(FtpOutput::Data(want)))));
}

#[test]
fn an_oversized_file_is_refused_before_allocating() {
    let mut w = Wire::new(ClientConfig {
        max_read_size: 100,
        ..Default::default()
    });
    w.server.backend_mut().insert_file("big", &[0; 101]);
    w.client.read(w.now, "big").unwrap();
    assert_eq!(w.run(), Err(FtpError::TooLarge { size: 101 }));
    // The session was closed by the client's parting TerminateSession.
    while let Some(o) = w.client.poll_transmit() {
        w.server.handle_message(w.now, GCS, &o.message);
    }
    assert_eq!(w.server.open_sessions(), 0);
}

/// Runs `c` against a server written as `answer` (the replies to each request, their
/// sequence numbers and request opcodes filled in), for at most 50 requests; the events.
fn talk(
    c: &mut FtpClient,
    now: Instant,
    mut answer: impl FnMut(&Payload) -> Vec<Payload>,
) -> Vec<FtpEvent> {
    let mut events = Vec::new();
    for _ in 0..50 {
        let Some(o) = c.poll_transmit() else { break };
        let MavMessage::FileTransferProtocol(m) = o.message else {
            panic!()
        };
        let req = Payload::decode(&m.payload).unwrap();
        for mut reply in answer(&req) {
            reply.seq = req.seq.wrapping_add(1);
            reply.req_opcode = req.opcode;
            let msg = MavMessage::FileTransferProtocol(FileTransferProtocol {
                target_network: 0,
                target_system: GCS.system,
                target_component: GCS.component,
                payload: reply.encode(),
            });
            c.handle_message(now, VEHICLE, &msg);
        }
        events.extend(core::iter::from_fn(|| c.poll_event()));
    }
    events
}

#[test]
fn a_server_sending_nothing_useful_ends_the_read() {
    let mut c = FtpClient::new(
        GCS,
        VEHICLE,
        ClientConfig {
            burst: false,
            ..Default::default()
        },
    );
    let now = Instant::from_secs(1);
    c.read(now, "f").unwrap();
    let events = talk(&mut c, now, |req| {
        vec![match req.opcode {
            Opcode::OpenFileRO => Payload::request(0, 1, Opcode::Ack, 0, &1000u32.to_le_bytes()),
            // Always the wrong place.
            _ => Payload::request(0, 1, Opcode::Ack, req.offset + 1, &[9; 239]),
        }]
    });
    assert_eq!(
        events.last(),
        Some(&FtpEvent::Finished(Err(FtpError::Protocol)))
    );
}

/// ArduPilot opens `@PARAM/param.pck` announcing an estimate (12 bytes a parameter) and
/// ends the file earlier with NAK EndOfFile: the file is what came before it, by burst and
/// by ReadFile alike.
#[test]
fn a_file_shorter_than_announced_ends_at_end_of_file() {
    for burst in [true, false] {
        let mut c = FtpClient::new(
            GCS,
            VEHICLE,
            ClientConfig {
                burst,
                ..Default::default()
            },
        );
        let now = Instant::from_secs(1);
        let file = pattern(600);
        c.read(now, "@PARAM/param.pck").unwrap();
        let events = talk(&mut c, now, |req| {
            let at = req.offset as usize;
            match req.opcode {
                Opcode::OpenFileRO => {
                    vec![Payload::request(
                        0,
                        1,
                        Opcode::Ack,
                        0,
                        &1200u32.to_le_bytes(),
                    )]
                }
                Opcode::TerminateSession => vec![Payload::request(0, 1, Opcode::Ack, 0, &[])],
                _ if at >= file.len() => {
                    vec![Payload::request(0, 1, Opcode::Nak, req.offset, &[6])]
                }
                Opcode::BurstReadFile => file[at..]
                    .chunks(239)
                    .enumerate()
                    .map(|(i, chunk)| {
                        let mut p =
                            Payload::request(0, 1, Opcode::Ack, (at + i * 239) as u32, chunk);
                        p.burst_complete = at + (i + 1) * 239 >= file.len();
                        p
                    })
                    .collect(),
                _ => {
                    let end = (at + 239).min(file.len());
                    vec![Payload::request(
                        0,
                        1,
                        Opcode::Ack,
                        req.offset,
                        &file[at..end],
                    )]
                }
            }
        });
        assert_eq!(
            events.last(),
            Some(&FtpEvent::Finished(Ok(FtpOutput::Data(file.clone())))),
            "burst {burst}"
        );
    }
}

/// A new session takes the number the client asked for when it is free (ArduPilot does the
/// same; pymavlink writes in its own session number before CreateFile's ACK arrives), the
/// lowest free one otherwise; the count of sessions stays bounded either way.
#[test]
fn a_session_takes_the_number_the_client_asked_for() {
    let mut r = Raw::new();
    let created = r.ask(GCS, Opcode::CreateFile, 7, 0, b"pub/new.bin");
    assert_eq!((created.opcode, created.session), (Opcode::Ack, 7));
    let wrote = r.ask(GCS, Opcode::WriteFile, 7, 0, b"abc");
    assert_eq!(wrote.opcode, Opcode::Ack, "{wrote:?}");
    // Number 7 is taken: another open gets the lowest free number.
    let other = r.ask(OTHER, Opcode::OpenFileRO, 7, 0, b"pub/a.txt");
    assert_eq!((other.opcode, other.session), (Opcode::Ack, 0));
    for (session, path) in [(200, &b"pub/a.txt"[..]), (201, b"keep/secret.txt")] {
        let p = r.ask(GCS, Opcode::OpenFileRO, session, 0, path);
        assert_eq!((p.opcode, p.session), (Opcode::Ack, session));
    }
    r.server.backend_mut().insert_file("pub/b.txt", b"b");
    let full = r.ask(GCS, Opcode::OpenFileRO, 9, 0, b"pub/b.txt");
    assert_eq!(
        nak_of(&full).map(|n| n.0),
        Some(NakCode::NoSessionsAvailable)
    );
    assert_eq!(r.server.open_sessions(), 4);
}

/// Decodes what the client sent.
fn sent(c: &mut FtpClient) -> Vec<Payload> {
    core::iter::from_fn(|| c.poll_transmit())
        .map(|o| {
            let MavMessage::FileTransferProtocol(m) = o.message else {
                panic!()
            };
            Payload::decode(&m.payload).unwrap()
        })
        .collect()
}

fn deliver(c: &mut FtpClient, now: Instant, reply: &Payload) {
    let msg = MavMessage::FileTransferProtocol(FileTransferProtocol {
        target_network: 0,
        target_system: GCS.system,
        target_component: GCS.component,
        payload: reply.encode(),
    });
    assert!(c.handle_message(now, VEHICLE, &msg));
}

/// The holes a burst leaves are asked for five at a time without waiting for each other's
/// replies (a round trip per lost packet made lossy, slow links crawl), each with its own
/// retransmission, and the file comes out whole.
#[test]
fn gaps_after_a_burst_are_asked_for_in_a_window() {
    let file = pattern(239 * 16);
    let mut c = FtpClient::new(GCS, VEHICLE, ClientConfig::default());
    let now = Instant::from_secs(1);
    c.read(now, "f").unwrap();
    let open = sent(&mut c).remove(0);
    let mut ack = Payload::request(
        open.seq + 1,
        3,
        Opcode::Ack,
        0,
        &(file.len() as u32).to_le_bytes(),
    );
    ack.req_opcode = Opcode::OpenFileRO;
    deliver(&mut c, now, &ack);
    let burst = sent(&mut c).remove(0);
    assert_eq!(
        (burst.opcode, burst.offset, burst.session),
        (Opcode::BurstReadFile, 0, 3)
    );
    // Every odd packet of the burst is lost: eight holes.
    for i in (0..16).step_by(2) {
        let at = i * 239;
        let mut p = Payload::request(
            burst.seq + 1 + i as u16,
            3,
            Opcode::Ack,
            at as u32,
            &file[at..at + 239],
        );
        p.req_opcode = Opcode::BurstReadFile;
        deliver(&mut c, now, &p);
    }
    // The last packet (15) was lost too, so the burst never completes: it goes quiet.
    let quiet = c.poll_timeout().unwrap();
    assert!(sent(&mut c).is_empty());
    c.handle_timeout(quiet);
    let first = sent(&mut c);
    let reads: Vec<u32> = first
        .iter()
        .filter(|p| p.opcode == Opcode::ReadFile)
        .map(|p| p.offset)
        .collect();
    assert_eq!(
        reads,
        [239, 239 * 3, 239 * 5, 239 * 7, 239 * 9],
        "five holes at once"
    );
    // And beside them a burst for what lies past the furthest data.
    let bursts: Vec<u32> = first
        .iter()
        .filter(|p| p.opcode == Opcode::BurstReadFile)
        .map(|p| p.offset)
        .collect();
    assert_eq!(bursts, [239 * 15]);
    assert_eq!(first.len(), 6);
    // No reply yet: the timeout resends the same requests, nothing more.
    let later = c.poll_timeout().unwrap();
    c.handle_timeout(later);
    let again: Vec<(Opcode, u32)> = sent(&mut c).iter().map(|p| (p.opcode, p.offset)).collect();
    let before: Vec<(Opcode, u32)> = first.iter().map(|p| (p.opcode, p.offset)).collect();
    assert_eq!(again.len(), 6);
    assert!(again.iter().all(|r| before.contains(r)));
    // Each answer lets one more hole be asked for, until the file is whole.
    let mut queue: Vec<Payload> = first;
    while let Some(req) = (!queue.is_empty()).then(|| queue.remove(0)) {
        if req.opcode == Opcode::TerminateSession {
            let mut done = Payload::request(req.seq + 1, 3, Opcode::Ack, 0, &[]);
            done.req_opcode = Opcode::TerminateSession;
            deliver(&mut c, later, &done);
            break;
        }
        let at = req.offset as usize;
        let end = (at + req.data.len()).min(file.len());
        let mut p = Payload::request(req.seq + 1, 3, Opcode::Ack, req.offset, &file[at..end]);
        p.req_opcode = req.opcode;
        p.burst_complete = req.opcode == Opcode::BurstReadFile;
        deliver(&mut c, later, &p);
        let next = sent(&mut c);
        assert!(
            next.len() <= 1,
            "one answer, at most one new request: {next:?}"
        );
        queue.extend(next);
    }
    let finished = core::iter::from_fn(|| c.poll_event()).last();
    assert_eq!(
        finished,
        Some(FtpEvent::Finished(Ok(FtpOutput::Data(file))))
    );
}

/// A client opening the same file again (its first ACK lost; MAVProxy sends each retry
/// with a new sequence number) gets its open session again, not one more: four retries
/// used to leave no session for anybody.
#[test]
fn opening_the_same_file_again_gives_the_same_session() {
    let mut r = Raw::new();
    let first = r.ask(GCS, Opcode::OpenFileRO, 0, 0, b"pub/a.txt");
    for _ in 0..6 {
        let again = r.ask(GCS, Opcode::OpenFileRO, 0, 0, b"/pub/a.txt");
        assert_eq!(again.opcode, Opcode::Ack);
        assert_eq!(
            (again.session, &again.data[..]),
            (first.session, &3u32.to_le_bytes()[..])
        );
    }
    assert_eq!(r.server.open_sessions(), 1);
    // Another file, or another client, is another session.
    let other_file = r.ask(GCS, Opcode::OpenFileRO, 0, 0, b"keep/secret.txt");
    let other_client = r.ask(OTHER, Opcode::OpenFileRO, 0, 0, b"pub/a.txt");
    assert_eq!(other_file.opcode, Opcode::Ack);
    assert_eq!(other_client.opcode, Opcode::Ack);
    assert_eq!(r.server.open_sessions(), 3);
    let read = r.ask(GCS, Opcode::ReadFile, first.session, 0, &[0; 3]);
    assert_eq!(read.data, b"abc");
}
