//! The PX4 flavour's shell over MAVLink: SERIAL_CONTROL to the SHELL device answered as
//! NuttX's nsh on a flight controller answers it through PX4's `MavlinkShell`.
//!
//! The first message starts a session: the shell greets (`NuttShell (NSH) ...` and the
//! prompt `nsh> `), echoes what it is sent, runs a line at its line feed and prints the
//! prompt again. Its output goes back at once in SERIAL_CONTROL replies of up to 70 bytes
//! (REPLY flag) to whoever wrote, as PX4 pushes it without waiting for a poll; a message
//! without RESPOND ends the session, as PX4 then stops the shell. It knows `ver` (`ver all`
//! and its parts), `help`, `echo`, and says of anything else `nsh: NAME: command not found`.
//! PX4 SITL's own shell is pxh (`pxh> `, `Invalid command: NAME`), which a client meets too.

use core::fmt::Write as _;
use std::collections::VecDeque;

use mavstack_dialects::common::{MavMessage, SerialControl, SerialControlDev, SerialControlFlag};
use mavstack_services::shell::CHUNK_LEN;
use mavstack_services::{Address, Outgoing};

use crate::craft::FLIGHT_SW_VERSION;

/// The longest line the shell keeps; what is typed beyond it is dropped.
const LINE_MAX: usize = 256;

/// The commands `help` lists: PX4's, as a flight controller's nsh has them.
const COMMANDS: [&str; 58] = [
    "actuator_test",
    "battery_status",
    "bmi088",
    "bmp388",
    "bsondump",
    "camera_feedback",
    "camera_trigger",
    "commander",
    "control_allocator",
    "dataman",
    "df",
    "dmesg",
    "dshot",
    "echo",
    "ekf2",
    "flight_mode_manager",
    "free",
    "gps",
    "gyro_calibration",
    "hardfault_log",
    "help",
    "ist8310",
    "land_detector",
    "led_control",
    "listener",
    "load_mon",
    "logger",
    "ls",
    "manual_control",
    "mavlink",
    "mc_att_control",
    "mc_pos_control",
    "mc_rate_control",
    "mkdir",
    "mtd",
    "navigator",
    "nshterm",
    "param",
    "perf",
    "ps",
    "pwm_out",
    "px4io",
    "rc_input",
    "rc_update",
    "reboot",
    "rm",
    "sd_bench",
    "sensors",
    "sleep",
    "system_time",
    "tone_alarm",
    "top",
    "tune_control",
    "uorb",
    "uptime",
    "ver",
    "vtol_att_control",
    "work_queue",
];

/// The shell of the PX4 flavour.
#[derive(Clone, Debug, Default)]
pub(crate) struct Nsh {
    /// Who the session is with, while one is open.
    session: Option<Address>,
    line: Vec<u8>,
    /// Output not yet sent.
    pending: Vec<u8>,
    out: VecDeque<Outgoing>,
    /// Lines run, for the vehicle's log.
    ran: VecDeque<String>,
}

impl Nsh {
    /// Takes a SERIAL_CONTROL from `from`; returns whether it was for the shell.
    pub(crate) fn handle(&mut self, from: Address, m: &SerialControl) -> bool {
        if m.device != SerialControlDev::SHELL || m.flags.0 & SerialControlFlag::REPLY.0 != 0 {
            return false;
        }
        if self.session != Some(from) {
            self.session = Some(from);
            self.line.clear();
            self.print("\nNuttShell (NSH) NuttX-11.0.0\nnsh> ");
        }
        let count = usize::from(m.count);
        if count <= CHUNK_LEN {
            for &b in &m.data[..count] {
                self.key(b);
            }
        }
        self.flush(from);
        if m.flags.0 & SerialControlFlag::RESPOND.0 == 0 {
            self.session = None;
            self.line.clear();
        }
        true
    }

    /// The next reply to send.
    pub(crate) fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    /// The next line run, for the log.
    pub(crate) fn poll_ran(&mut self) -> Option<String> {
        self.ran.pop_front()
    }

    fn key(&mut self, b: u8) {
        match b {
            b'\n' => {
                self.print("\n");
                let line = String::from_utf8_lossy(&self.line).into_owned();
                self.line.clear();
                let output = run(line.trim());
                self.print(&output);
                self.print("nsh> ");
                if !line.trim().is_empty() {
                    self.ran.push_back(line.trim().into());
                }
            }
            b'\r' => {}
            0x08 | 0x7F if self.line.pop().is_some() => self.print("\x08 \x08"),
            0x03 => {
                self.line.clear();
                self.print("^C\nnsh> ");
            }
            0x20..=0x7E | 0x80..=0xFF if self.line.len() < LINE_MAX => {
                self.line.push(b);
                self.pending.push(b);
            }
            _ => {}
        }
    }

    fn print(&mut self, text: &str) {
        self.pending.extend_from_slice(text.as_bytes());
    }

    fn flush(&mut self, to: Address) {
        for chunk in self.pending.chunks(CHUNK_LEN) {
            let mut data = [0u8; CHUNK_LEN];
            data[..chunk.len()].copy_from_slice(chunk);
            self.out.push_back(Outgoing {
                target: to,
                message: MavMessage::SerialControl(SerialControl {
                    device: SerialControlDev::SHELL,
                    flags: SerialControlFlag::REPLY,
                    timeout: 0,
                    baudrate: 0,
                    count: chunk.len() as u8,
                    data,
                }),
            });
        }
        self.pending.clear();
    }
}

/// What a line prints.
fn run(line: &str) -> String {
    let mut words = line.split_ascii_whitespace();
    let Some(command) = words.next() else {
        return String::new();
    };
    let args: Vec<&str> = words.collect();
    match command {
        "ver" => ver(args.first().copied()),
        "help" => help(),
        "echo" => {
            let mut text = args.join(" ");
            text.push('\n');
            text
        }
        _ => format!("nsh: {command}: command not found\n"),
    }
}

/// `ver` and its parts, as PX4's `ver` prints them.
fn ver(part: Option<&str>) -> String {
    let v = FLIGHT_SW_VERSION;
    let [major, minor, patch, _] = v.to_be_bytes();
    let parts: [(&str, String); 8] = [
        ("hw", "HW arch: MAVSTACK_SIM\nHW type: NA\n".into()),
        (
            "git",
            format!(
                "PX4 git-hash: 6d6176737461636b000000000000000000000000\n\
                 PX4 version: Release {major}.{minor}.{patch} ({v})\n\
                 PX4 git-branch: main\nOS: NuttX\n\
                 OS version: Release 11.0.0 (184549631)\n\
                 OS git-hash: 0000000000000000000000000000000000000000\n"
            ),
        ),
        ("bdate", "Build datetime: Jan  1 2026 00:00:00\n".into()),
        ("buri", "Build uri: localhost\n".into()),
        ("all", "Build variant: default\n".into()),
        ("gcc", "Toolchain: GNU GCC, 13.2.1 20231009\n".into()),
        (
            "px4guid",
            "PX4GUID: 000600000000006d6176737461636b\n".into(),
        ),
        ("mcu", "MCU: MAVSTACK simulated, rev. 1\n".into()),
    ];
    match part {
        Some("all") => parts.into_iter().map(|(_, text)| text).collect(),
        Some(p) => parts
            .into_iter()
            .find(|(name, _)| *name == p)
            .map_or_else(|| "ERROR [ver] unknown command\n".into(), |(_, text)| text),
        None => "Usage: ver <command> [arguments...]\n  Commands:\n   hw  git  bdate  buri  \
                 gcc  px4guid  mcu  all\n"
            .into(),
    }
}

/// `help`: the commands, one a line.
fn help() -> String {
    let mut out = String::from("help usage: help [-v] [<cmd>]\n\nBuiltin Apps:\n");
    for name in COMMANDS {
        let _ = writeln!(out, "  {name}");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn to_shell(flags: u8, text: &[u8]) -> SerialControl {
        let mut data = [0u8; CHUNK_LEN];
        data[..text.len()].copy_from_slice(text);
        SerialControl {
            device: SerialControlDev::SHELL,
            flags: SerialControlFlag(flags),
            timeout: 0,
            baudrate: 0,
            count: text.len() as u8,
            data,
        }
    }

    fn output(nsh: &mut Nsh) -> String {
        let mut bytes = Vec::new();
        while let Some(o) = nsh.poll_transmit() {
            let MavMessage::SerialControl(s) = o.message else {
                panic!()
            };
            assert_eq!(s.flags, SerialControlFlag::REPLY);
            assert!(usize::from(s.count) <= CHUNK_LEN);
            bytes.extend_from_slice(&s.data[..usize::from(s.count)]);
        }
        String::from_utf8(bytes).unwrap()
    }

    #[test]
    fn greets_echoes_runs_and_ends_with_the_prompt() {
        let gcs = Address::new(255, 190);
        let mut nsh = Nsh::default();
        assert!(nsh.handle(gcs, &to_shell(6, b"ver al")));
        assert!(nsh.handle(gcs, &to_shell(6, b"l\nfoo\n")));
        let out = output(&mut nsh);
        assert!(out.starts_with("\nNuttShell (NSH) NuttX-11.0.0\nnsh> ver all\nHW arch: "));
        assert!(out.contains("PX4 version: Release 4.1.0 (67174655)\n"));
        assert!(
            out.ends_with("nsh> foo\nnsh: foo: command not found\nnsh> "),
            "{out}"
        );
        assert_eq!(nsh.poll_ran().as_deref(), Some("ver all"));
        // Without RESPOND the session ends; the next message greets again.
        assert!(nsh.handle(gcs, &to_shell(0, b"")));
        assert!(nsh.handle(gcs, &to_shell(6, b"")));
        assert!(output(&mut nsh).contains("NuttShell"));
        // Replies and other devices are not for the shell.
        assert!(!nsh.handle(gcs, &to_shell(1, b"x")));
    }
}
