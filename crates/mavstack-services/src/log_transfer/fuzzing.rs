//! The log transfer's fuzzing entry point ([`fuzz_log_transfer`]): a server fed any requests
//! from two clients, a client fed any answers, and a download through a wire the input
//! makes lossy.

use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::MessageSet as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::MavMessage;

use super::{
    CHUNK, ClientConfig, LogClient, LogEvent, LogOutput, LogServer, LogStore, MemoryLogs,
    ServerConfig,
};
use crate::{Address, Service};

const CLIENT_A: Address = Address::new(255, 190);
const CLIENT_B: Address = Address::new(254, 190);
const SERVER: Address = Address::new(1, 1);

/// LOG_REQUEST_LIST, LOG_REQUEST_DATA, LOG_ERASE, LOG_REQUEST_END; LOG_ENTRY, LOG_DATA.
const REQUESTS: [u32; 4] = [117, 119, 121, 122];
const ANSWERS: [u32; 2] = [118, 120];

/// A log's bytes: `n` of them, from `seed`.
fn pattern(n: usize, seed: u8) -> Vec<u8> {
    (0..n)
        .map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed) ^ (i >> 8) as u8)
        .collect()
}

/// Feeds `data` to the log transfer's roles and checks their properties:
///
/// - A server with logs of 0, 1, 90, 91 and 1,000 bytes, sent any requests (records of
///   `[control, kind, len, payload...]`: the control byte's low bit picks one of two
///   clients, its other bits move time; `kind` picks LOG_REQUEST_LIST, LOG_REQUEST_DATA,
///   LOG_ERASE or LOG_REQUEST_END, decoded from the payload as it is): it never sends data
///   outside a log (every LOG_DATA names a log it has, with `ofs + count` within its size,
///   `count` at most 90, the bytes of the log at that offset and zeros after them), every
///   LOG_ENTRY tells a log as it is, and no more than its messages per tick go out at once.
/// - A client listing, then downloading a log whose announced size the input picks, sent any
///   answers: it never asks for data outside the announced size, and a download that ends
///   holds no more than that size; a list holds no more entries than allowed.
/// - A client and a server over a wire that drops what the input says: a log downloaded
///   (when it ends well) is exactly the log.
pub fn fuzz_log_transfer(data: &[u8]) {
    server_under_attack(data);
    client_against_a_liar(data);
    download_through_loss(data);
}

fn server_under_attack(data: &[u8]) {
    let mut logs = MemoryLogs::new();
    for (id, n) in [(1u16, 0usize), (2, 1), (3, 90), (4, 91), (5, 1000)] {
        let _ = logs.insert(id, u32::from(id) * 1000, &pattern(n, id as u8));
    }
    let mut truth = logs.clone();
    let config = ServerConfig {
        per_tick: 7,
        tick: Duration::from_millis(10),
    };
    let mut server = LogServer::new(SERVER, config, logs);
    let mut now = Instant::from_secs(1);
    let mut rest = data;
    while let [control, kind, len, tail @ ..] = rest {
        let n = usize::from(*len).min(tail.len());
        let (payload, next) = tail.split_at(n);
        rest = next;
        now += Duration::from_millis(u64::from(control >> 1));
        let from = if control & 1 == 0 { CLIENT_A } else { CLIENT_B };
        let id = REQUESTS[usize::from(*kind) % REQUESTS.len()];
        server.handle_timeout(now);
        if let Ok(message) = MavMessage::decode(id, payload) {
            let addressed = match &message {
                MavMessage::LogRequestList(m) => (m.target_system, m.target_component),
                MavMessage::LogRequestData(m) => (m.target_system, m.target_component),
                MavMessage::LogRequestEnd(m) => (m.target_system, m.target_component),
                MavMessage::LogErase(m) => (m.target_system, m.target_component),
                _ => (0, 0),
            };
            let used = server.handle_message(now, from, &message);
            assert_eq!(
                used,
                SERVER.is_reached_by(Address::new(addressed.0, addressed.1)),
                "a request taken or ignored against its target"
            );
            if used && matches!(message, MavMessage::LogErase(_)) {
                truth.erase();
            }
        }
        let mut sent = 0u16;
        while let Some(out) = server.poll_transmit() {
            sent += 1;
            assert!(
                sent <= config.per_tick,
                "more than a tick's messages at once"
            );
            assert!(
                out.target == CLIENT_A || out.target == CLIENT_B,
                "an answer to nobody who asked"
            );
            check_answer(&mut truth, &out.message);
        }
        while server.poll_event().is_some() {}
    }
}

/// One message of the server checked against the logs it serves.
fn check_answer(truth: &mut MemoryLogs, message: &MavMessage) {
    let logs = truth.logs();
    match message {
        MavMessage::LogData(m) => {
            let bytes = truth.bytes(m.id).expect("LOG_DATA of a log there is not");
            let count = usize::from(m.count);
            assert!(count <= CHUNK, "count above 90");
            // Count 0 (at or beyond the end) carries nothing; any byte is the log's own.
            if count > 0 {
                let ofs = m.ofs as usize;
                let end = ofs.checked_add(count).expect("offset overflow");
                assert!(end <= bytes.len(), "LOG_DATA beyond the log's end");
                assert_eq!(&m.data[..count], &bytes[ofs..end], "not the log's bytes");
            }
            assert!(m.data[count..].iter().all(|&b| b == 0), "bytes after count");
        }
        MavMessage::LogEntry(e) => {
            if logs.is_empty() {
                assert_eq!((e.id, e.num_logs, e.size), (0, 0, 0), "logs where none are");
            } else {
                let log = logs
                    .iter()
                    .find(|l| l.id == e.id)
                    .expect("LOG_ENTRY of a log there is not");
                assert_eq!((e.size, e.time_utc), (log.size, log.time_utc));
                assert_eq!(usize::from(e.num_logs), logs.len());
            }
        }
        other => panic!("the server sent {other:?}"),
    }
}

fn client_against_a_liar(data: &[u8]) {
    let Some((&first, rest)) = data.split_first() else {
        return;
    };
    let config = ClientConfig {
        max_size: 1 << 16,
        max_entries: 50,
        ..ClientConfig::default()
    };
    let announced = u32::from(first) * 37;
    for download in [false, true] {
        let mut client = LogClient::new(SERVER, config);
        let mut now = Instant::from_secs(1);
        let started = if download {
            client.download(now, 1, announced)
        } else {
            client.list(now)
        };
        if started.is_err() {
            return;
        }
        let mut records = rest;
        loop {
            while let Some(out) = client.poll_transmit() {
                if let MavMessage::LogRequestData(r) = &out.message {
                    assert!(
                        u64::from(r.ofs) + u64::from(r.count) <= u64::from(announced),
                        "asked for data outside the log"
                    );
                }
            }
            while let Some(event) = client.poll_event() {
                if let LogEvent::Finished(Ok(output)) = event {
                    match output {
                        LogOutput::Data(bytes) => assert!(
                            bytes.len() <= announced as usize,
                            "kept more than the announced size"
                        ),
                        LogOutput::Entries(entries) => assert!(
                            entries.len() <= config.max_entries,
                            "kept more entries than allowed"
                        ),
                        LogOutput::Erased => {}
                    }
                }
            }
            let [control, kind, len, tail @ ..] = records else {
                break;
            };
            let n = usize::from(*len).min(tail.len());
            let (payload, next) = tail.split_at(n);
            records = next;
            now += Duration::from_millis(u64::from(*control) * 8);
            client.handle_timeout(now);
            let id = ANSWERS[usize::from(*kind) % ANSWERS.len()];
            if let Ok(message) = MavMessage::decode(id, payload) {
                client.handle_message(now, SERVER, &message);
            }
        }
    }
}

fn download_through_loss(data: &[u8]) {
    let [drops, seed, contents @ ..] = data else {
        return;
    };
    let size = contents.len().min(3000);
    let log = pattern(size, *seed);
    let mut logs = MemoryLogs::new();
    let _ = logs.insert(7, 0, &log);
    let config = ClientConfig {
        window: u32::from(*seed % 4) * 450,
        ..ClientConfig::default()
    };
    let mut client = LogClient::new(SERVER, config);
    let mut server = LogServer::new(SERVER, ServerConfig::default(), logs);
    let mut now = Instant::from_secs(1);
    let Ok(size32) = u32::try_from(size) else {
        return;
    };
    if client.download(now, 7, size32).is_err() {
        return;
    }
    // Every n-th message each way is lost, n from the first byte (0 and 1: none).
    let every = usize::from(drops % 8);
    let mut count = 0usize;
    let lost = |count: &mut usize| {
        *count += 1;
        every > 1 && count.is_multiple_of(every)
    };
    for _ in 0..200_000 {
        let mut moved = false;
        while let Some(out) = client.poll_transmit() {
            moved = true;
            if !lost(&mut count) {
                server.handle_message(now, CLIENT_A, &out.message);
            }
        }
        while let Some(out) = server.poll_transmit() {
            moved = true;
            if !lost(&mut count) {
                client.handle_message(now, SERVER, &out.message);
            }
        }
        while let Some(event) = client.poll_event() {
            if let LogEvent::Finished(result) = event {
                if let Ok(LogOutput::Data(bytes)) = result {
                    assert_eq!(bytes, log, "a download differs from the log");
                }
                return;
            }
        }
        if !moved {
            let next = [client.poll_timeout(), server.poll_timeout()]
                .into_iter()
                .flatten()
                .min();
            let Some(next) = next else {
                return;
            };
            now = now.max(next);
            client.handle_timeout(now);
            server.handle_timeout(now);
        }
    }
    panic!("a download through a lossy wire never ended");
}

#[cfg(test)]
mod tests {
    use alloc::vec::Vec;

    /// The properties hold on pseudo-random inputs and on requests shaped like the
    /// protocol's.
    #[test]
    fn the_properties_hold_on_sample_inputs() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for len in [0usize, 1, 2, 3, 13, 97, 600, 2000] {
            super::fuzz_log_transfer(&crate::fuzzing::sample_bytes(&mut state, len));
        }
        // LOG_REQUEST_DATA for every log, at offsets in, at and beyond the end.
        let mut requests = Vec::new();
        for id in 0u8..7 {
            for ofs in [0u32, 1, 89, 90, 91, 999, 1000, u32::MAX] {
                // [control, kind (1: LOG_REQUEST_DATA), len, ofs, count, id, sys, comp]
                let mut p = Vec::from(ofs.to_le_bytes());
                p.extend_from_slice(&u32::MAX.to_le_bytes());
                p.extend_from_slice(&[id, 0, 1, 1]);
                requests.extend_from_slice(&[20, 1, p.len() as u8]);
                requests.extend_from_slice(&p);
            }
        }
        super::fuzz_log_transfer(&requests);
    }

    /// The `log_transfer` fuzz target's seed corpus (fuzz/corpus/log_transfer), replayed on
    /// stable.
    #[test]
    fn the_seed_corpus_replays() {
        for seed in mavstack_core::fuzz_seeds("log_transfer", 5) {
            super::fuzz_log_transfer(&seed);
        }
    }
}
