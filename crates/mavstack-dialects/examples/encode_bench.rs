//! Encode throughput, the same work as the encode benchmarks of the peers'
//! harness that `scripts/bench-peers.sh` runs (the C library's and rust-mavlink's,
//! `--encode N [--sign]`; the harness is outside this repository): N messages,
//! HEARTBEAT, ATTITUDE and GLOBAL_POSITION_INT in turn with the same field values, serialised
//! as MAVLink 2 frames (signed with key 00..1f, link 0, when `--sign`) into a 1 MiB buffer
//! that is reused when full. Prints `frames=N bytes=B seconds=S` (S: the encode loop only).
//!
//! `cargo run --release -p mavstack-dialects --example encode_bench -- 10000000 [--sign]`;
//! `scripts/bench-peers.sh` runs it beside the peers.

use core::hint::black_box;
use std::process::ExitCode;
use std::time::Instant;

use mavstack_core::signing::{SecretKey, append_signature};
use mavstack_core::wire::{FrameHeader, MAX_FRAME_LEN, Version, emit_message};
use mavstack_dialects::ardupilotmega::{
    Attitude, GlobalPositionInt, Heartbeat, MavAutopilot, MavModeFlag, MavState, MavType,
};

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(n) = args.next().and_then(|a| a.parse::<u64>().ok()) else {
        eprintln!("usage: encode_bench N [--sign]");
        return ExitCode::from(2);
    };
    let sign = args.next().as_deref() == Some("--sign");
    let key = SecretKey::new(core::array::from_fn(|i| i as u8));
    let header = FrameHeader {
        version: Version::V2,
        seq: 0,
        sysid: 1,
        compid: 1,
        signed: sign,
    };
    let mut out = vec![0u8; (1 << 20) + MAX_FRAME_LEN];
    let (mut pos, mut total, mut timestamp) = (0usize, 0u64, 1u64);
    let started = Instant::now();
    for i in 0..n {
        let f = i as f32 * 0.001;
        if pos + MAX_FRAME_LEN > out.len() - MAX_FRAME_LEN {
            pos = 0; // reuse the buffer, as the peers do
        }
        let header = FrameHeader {
            seq: i as u8,
            ..header
        };
        let buf = &mut out[pos..];
        let written = match i % 3 {
            0 => emit_message(
                &header,
                &Heartbeat {
                    r#type: MavType::QUADROTOR,
                    autopilot: MavAutopilot::ARDUPILOTMEGA,
                    base_mode: MavModeFlag((i & 0xC1) as u8),
                    custom_mode: i as u32,
                    system_status: MavState::ACTIVE,
                    mavlink_version: 3,
                },
                buf,
            ),
            1 => emit_message(
                &header,
                &Attitude {
                    time_boot_ms: i as u32,
                    roll: f,
                    pitch: -f,
                    yaw: f * 2.0,
                    rollspeed: f * 0.5,
                    pitchspeed: -f * 0.5,
                    yawspeed: f * 0.25,
                },
                buf,
            ),
            _ => emit_message(
                &header,
                &GlobalPositionInt {
                    time_boot_ms: i as u32,
                    lat: 473_977_420 + i as i32,
                    lon: 85_455_940 - i as i32,
                    alt: (i & 0xFFFF) as i32 * 10,
                    relative_alt: (i & 0xFFF) as i32,
                    vx: (i & 0x7FF) as i16,
                    vy: -((i & 0x3FF) as i16),
                    vz: (i & 0xFF) as i16,
                    hdg: (i % 36000) as u16,
                },
                buf,
            ),
        };
        let Ok(mut len) = written else {
            eprintln!("encode_bench: a frame did not fit");
            return ExitCode::FAILURE;
        };
        if sign {
            let Ok(signed) = append_signature(buf, len, 0, timestamp, &key) else {
                eprintln!("encode_bench: signing failed");
                return ExitCode::FAILURE;
            };
            timestamp += 1;
            len = signed;
        }
        pos += len;
        total += len as u64;
    }
    let seconds = started.elapsed().as_secs_f64();
    black_box(&out);
    println!("frames={n} bytes={total} seconds={seconds:.6}");
    ExitCode::SUCCESS
}
