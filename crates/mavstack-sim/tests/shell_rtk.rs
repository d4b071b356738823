//! The simulator's shell (PX4 flavour: SERIAL_CONTROL to the SHELL device answered as nsh)
//! and its RTK corrections (both flavours: GPS_RTCM_DATA put back together and counted), with
//! `mavstack-services`' own client roles on the other side, in process, on a virtual clock.

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::MavMessage;
use mavstack_services::rtcm::{RtcmSender, frame};
use mavstack_services::shell::{ShellCommand, ShellConfig, ShellError};
use mavstack_services::{Address, Service};
use mavstack_sim::{Autopilot, SimConfig, Vehicle, params};

const GCS: Address = Address::new(255, 190);
const VEHICLE: Address = Address::new(1, 1);

fn vehicle(autopilot: Autopilot, now: Instant) -> Vehicle {
    let config = SimConfig {
        own: VEHICLE,
        autopilot,
        mavlink2: true,
        params: params::defaults(autopilot),
        estimator_settle: Duration::ZERO,
        data_streams_only: false,
        streams_on_request: false,
        ftp: false,
        ftp_files: None,
        log_dir: None,
    };
    Vehicle::new(config, now)
}

/// Runs `command` on the vehicle's shell until it gives a result (or 30 s pass), counting
/// the SERIAL_CONTROL replies that carried output.
fn run(v: &mut Vehicle, now: &mut Instant, command: &str) -> (Result<String, ShellError>, usize) {
    let mut shell =
        ShellCommand::start(*now, VEHICLE, ShellConfig::default(), command).expect("one line");
    let end = *now + Duration::from_secs(30);
    let mut replies = 0;
    while *now < end {
        while let Some(out) = shell.poll_transmit() {
            v.handle_message(*now, GCS, &out.message);
        }
        while let Some(out) = v.poll_transmit() {
            if let MavMessage::SerialControl(s) = &out.message {
                assert_eq!(out.target, GCS, "the shell answers whoever wrote");
                assert!(s.count <= 70);
                replies += 1;
            }
            shell.handle_message(*now, VEHICLE, &out.message);
        }
        if let Some(result) = shell.poll_result() {
            // The close goes out too.
            while let Some(out) = shell.poll_transmit() {
                v.handle_message(*now, GCS, &out.message);
            }
            return (result, replies);
        }
        *now += Duration::from_millis(10);
        shell.handle_timeout(*now);
        v.handle_timeout(*now);
    }
    panic!("{command}: no result in 30 s");
}

#[test]
fn px4_answers_its_shell_as_nsh() {
    let mut now = Instant::from_secs(100);
    let mut v = vehicle(Autopilot::Px4, now);
    let (ver, _) = run(&mut v, &mut now, "ver all");
    let ver = ver.expect("ver all");
    assert!(ver.starts_with("HW arch: MAVSTACK_SIM\n"), "{ver}");
    assert!(
        ver.contains("\nPX4 version: Release 4.1.0 (67174655)\n"),
        "{ver}"
    );
    assert!(!ver.contains("nsh>") && !ver.contains("ver all"), "{ver}");
    let (help, replies) = run(&mut v, &mut now, "help");
    let help = help.expect("help");
    let lines: Vec<&str> = help.lines().collect();
    assert!(
        lines.contains(&"  listener") && lines.contains(&"  ver"),
        "{help}"
    );
    assert!(
        help.len() > 600 && replies >= help.len() / 70,
        "{replies} replies"
    );
    let (unknown, _) = run(&mut v, &mut now, "nosuchcmd --flag");
    assert_eq!(
        unknown.expect("an answer"),
        "nsh: nosuchcmd: command not found\n"
    );
    // A line longer than one SERIAL_CONTROL goes in chunks and comes back whole.
    let long: String = (0..200)
        .map(|i| char::from(b'a' + (i % 26) as u8))
        .collect();
    let (echo, _) = run(&mut v, &mut now, &format!("echo {long}"));
    assert_eq!(echo.expect("echo"), format!("{long}\n"));
    let logged: Vec<String> = core::iter::from_fn(|| v.poll_log()).collect();
    assert!(
        logged.iter().any(|l| l == "shell (255/190): ver all"),
        "{logged:?}"
    );
}

#[test]
fn ardupilot_has_no_shell_device() {
    let mut now = Instant::from_secs(100);
    let mut v = vehicle(Autopilot::Ardupilot, now);
    let (result, replies) = run(&mut v, &mut now, "ver all");
    assert!(
        matches!(result, Err(ShellError::NoAnswer { .. })),
        "{result:?}"
    );
    assert_eq!(replies, 0);
}

#[test]
fn both_flavours_put_corrections_together_and_count_them() {
    for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
        let now = Instant::from_secs(100);
        let mut v = vehicle(autopilot, now);
        let mut sender = RtcmSender::default();
        let mut sent = 0;
        // 360 bytes (two full fragments and the empty one), 100, 720 (four full ones).
        let mut messages = vec![frame(&[0x3e, 0xd0, 0x00]), frame(&[0x43, 0x20])];
        messages.push(frame(&[0x43; 354]));
        messages.push(frame(&[0x44; 94]));
        messages.push(frame(&[0x45; 714]));
        for m in &messages {
            for part in sender.fragments(m).expect("fits") {
                v.handle_message(now, GCS, &MavMessage::GpsRtcmData(part));
            }
            sent += m.len() as u64;
        }
        let got = v.rtcm_received();
        assert_eq!(got.messages, messages.len() as u64, "{autopilot}");
        assert_eq!(got.bytes, sent, "{autopilot}");
        assert_eq!(got.fragments_used, 1 + 1 + 3 + 1 + 4, "{autopilot}");
        assert_eq!(got.fragments_discarded, 0, "{autopilot}");
        let logged: Vec<String> = core::iter::from_fn(|| v.poll_log()).collect();
        let rtk: Vec<&String> = logged.iter().filter(|l| l.starts_with("rtk: ")).collect();
        assert_eq!(rtk.len(), messages.len(), "{logged:?}");
        assert!(rtk[0].starts_with("rtk: RTCM 1005, 9 bytes;"), "{}", rtk[0]);
        assert!(rtk[2].contains(", 360 bytes;"), "{}", rtk[2]);
    }
}
