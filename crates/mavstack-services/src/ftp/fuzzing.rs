//! The MAVFTP fuzzing entry point ([`fuzz_ftp`]): a server fed any requests from two clients,
//! a client fed any replies, and a client and server over a wire the input makes lossy.

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{FileTransferProtocol, MavMessage};

use super::payload::PAYLOAD_LEN;
use super::{ClientConfig, FtpClient, FtpEvent, FtpOutput, FtpServer, MemoryBackend, ServerConfig};
use crate::{Address, Service};

const CLIENT_A: Address = Address::new(255, 190);
const CLIENT_B: Address = Address::new(254, 190);
const SERVER: Address = Address::new(1, 1);

fn message(target: Address, payload: [u8; PAYLOAD_LEN]) -> MavMessage {
    MavMessage::FileTransferProtocol(FileTransferProtocol {
        target_network: 0,
        target_system: target.system,
        target_component: target.component,
        payload,
    })
}

/// A payload from the input: up to 251 bytes, the rest zero.
fn payload_from(bytes: &[u8]) -> [u8; PAYLOAD_LEN] {
    let mut p = [0u8; PAYLOAD_LEN];
    let n = bytes.len().min(PAYLOAD_LEN);
    p[..n].copy_from_slice(&bytes[..n]);
    p
}

/// Feeds `data` to the FTP roles and checks their properties:
///
/// - A server over an in-memory tree, sent any requests from two clients (records of
///   `[control, len, payload...]`, the control byte's low bit picking the client, its
///   other bits moving time): it never holds more sessions than allowed; every path in its
///   tree stays normal (no `..`, `.` or empty component: nothing was made outside the root);
///   after the session timeout passes with no request, no session is left open; what it
///   queues stays bounded.
/// - A client reading a file, sent any replies: a read that succeeds never holds more bytes
///   than the largest read allowed, and a listing no more entries than allowed.
/// - A client and a server over a wire that drops what the input says: a file written and
///   then read back (when both succeed) is what was written.
pub fn fuzz_ftp(data: &[u8]) {
    server_under_attack(data);
    client_against_a_liar(data);
    write_then_read(data);
}

fn server_under_attack(data: &[u8]) {
    let config = ServerConfig::default();
    let mut backend = MemoryBackend::new().with_max_file_size(1 << 16);
    let _ = backend.insert_file("/logs/one.bin", &[7; 600]);
    let _ = backend.insert_file("/readme.txt", b"hello");
    let mut server = FtpServer::new(SERVER, config, backend);
    let mut now = Instant::from_secs(1);
    let mut rest = data;
    while let [control, len, tail @ ..] = rest {
        let n = usize::from(*len).min(tail.len());
        let (bytes, next) = tail.split_at(n);
        rest = next;
        now += Duration::from_millis(u64::from(control >> 1) * 10);
        let from = if control & 1 == 0 { CLIENT_A } else { CLIENT_B };
        server.handle_timeout(now);
        server.handle_message(now, from, &message(SERVER, payload_from(bytes)));
        let mut queued = 0usize;
        while server.poll_transmit().is_some() {
            queued += 1;
            assert!(queued <= 4096, "a request made the server send without end");
        }
        assert!(
            server.open_sessions() <= usize::from(config.max_sessions),
            "more sessions than allowed"
        );
    }
    for path in server.backend().paths() {
        assert!(
            path.split('/')
                .skip(1)
                .all(|part| !part.is_empty() && part != ".." && part != "."),
            "a path outside the normal form: {path:?}"
        );
    }
    now += config.session_timeout + Duration::from_secs(1);
    server.handle_timeout(now);
    assert_eq!(server.open_sessions(), 0, "a session outlived the timeout");
}

fn client_against_a_liar(data: &[u8]) {
    let config = ClientConfig {
        max_read_size: 1 << 16,
        max_entries: 64,
        ..ClientConfig::default()
    };
    for listing in [false, true] {
        let mut client = FtpClient::new(CLIENT_A, SERVER, config);
        let mut now = Instant::from_secs(1);
        let started = if listing {
            client.list(now, "/")
        } else {
            client.read(now, "/x.bin")
        };
        if started.is_err() {
            return;
        }
        for chunk in data.chunks(PAYLOAD_LEN) {
            while client.poll_transmit().is_some() {}
            now += Duration::from_millis(u64::from(chunk[0] & 7) * 100);
            client.handle_timeout(now);
            client.handle_message(now, SERVER, &message(CLIENT_A, payload_from(chunk)));
            while let Some(event) = client.poll_event() {
                if let FtpEvent::Finished(Ok(output)) = event {
                    match output {
                        FtpOutput::Data(bytes) => assert!(
                            bytes.len() <= config.max_read_size as usize,
                            "a read kept more than allowed"
                        ),
                        FtpOutput::Listing(entries) => assert!(
                            entries.len() <= config.max_entries,
                            "a listing kept more than allowed"
                        ),
                        _ => {}
                    }
                }
            }
        }
    }
}

fn write_then_read(data: &[u8]) {
    let Some((&drops, contents)) = data.split_first() else {
        return;
    };
    let contents = &contents[..contents.len().min(4096)];
    let mut wire = Wire {
        client: FtpClient::new(CLIENT_A, SERVER, ClientConfig::default()),
        server: FtpServer::new(SERVER, ServerConfig::default(), MemoryBackend::new()),
        now: Instant::from_secs(1),
        // Every n-th message each way is lost, n from the first byte (0: none).
        every: usize::from(drops % 8),
        count: 0,
    };
    if wire
        .client
        .write(wire.now, "/dir one/f.bin", contents)
        .is_err()
    {
        return;
    }
    let Some(Ok(_)) = wire.run() else {
        return;
    };
    if wire.client.read(wire.now, "/dir one/f.bin").is_err() {
        return;
    }
    if let Some(Ok(FtpOutput::Data(back))) = wire.run() {
        assert_eq!(
            back, contents,
            "a file read back differs from what was written"
        );
    }
}

/// A client and a server over a wire that loses every `every`-th message.
struct Wire {
    client: FtpClient,
    server: FtpServer<MemoryBackend>,
    now: Instant,
    every: usize,
    count: usize,
}

impl Wire {
    fn lost(&mut self) -> bool {
        self.count += 1;
        self.every != 0 && self.count.is_multiple_of(self.every)
    }

    /// Runs the client's operation to its end (`None`: it never ended).
    fn run(&mut self) -> Option<Result<FtpOutput, super::FtpError>> {
        for _ in 0..100_000 {
            let mut moved = false;
            while let Some(out) = self.client.poll_transmit() {
                moved = true;
                if !self.lost() {
                    self.server.handle_message(self.now, CLIENT_A, &out.message);
                }
            }
            while let Some(out) = self.server.poll_transmit() {
                moved = true;
                if !self.lost() {
                    self.client.handle_message(self.now, SERVER, &out.message);
                }
            }
            while let Some(event) = self.client.poll_event() {
                if let FtpEvent::Finished(result) = event {
                    return Some(result);
                }
            }
            if !moved {
                self.now += Duration::from_millis(600);
                self.client.handle_timeout(self.now);
                self.server.handle_timeout(self.now);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use alloc::vec::Vec;

    /// The properties hold on pseudo-random inputs and on requests that look like the
    /// protocol's (every opcode, paths with `..`).
    #[test]
    fn the_properties_hold_on_sample_inputs() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for len in [0usize, 1, 2, 13, 251, 600, 2000] {
            super::fuzz_ftp(&crate::fuzzing::sample_bytes(&mut state, len));
        }
        let mut requests = Vec::new();
        for opcode in 0u8..20 {
            let path = b"../../etc/passwd";
            // [control, len, seq lo, seq hi, session, opcode, size, req, burst, pad, offset x4, data]
            let mut p = alloc::vec![0, 0, 0, opcode, path.len() as u8, 0, 0, 0, 0, 0, 0, 0];
            p.extend_from_slice(path);
            requests.push(opcode.wrapping_mul(2));
            requests.push(p.len() as u8);
            requests.extend_from_slice(&p);
        }
        super::fuzz_ftp(&requests);
    }

    /// The `ftp` fuzz target's seed corpus (fuzz/corpus/ftp: sessions opened and never
    /// closed, paths that try to leave the root, writes at huge offsets, unknown opcodes,
    /// files through lossy wires) and what fuzzing kept as regressions, replayed on stable.
    #[test]
    fn the_seed_corpus_replays() {
        for seed in mavstack_core::fuzz_seeds("ftp", 9) {
            super::fuzz_ftp(&seed);
        }
    }
}
