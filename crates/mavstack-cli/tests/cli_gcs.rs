//! `mavstack param`, `mission` and `command` against `mavstack vehicle` on loopback: the
//! ground-station commands end to end, their output and their errors. Against other
//! implementations: `interop_services.rs` (pymavlink as the ground station and as the
//! vehicle) and `interop_gcs.rs` (MAVProxy, MAVSDK).

use crate::vehicle;

use std::net::UdpSocket;
use std::process::{Command, Output};

use serde_json::Value;
use vehicle::Vehicle;

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port()
}

fn gcs(port: u16, args: &[&str]) -> Output {
    let (command, rest) = args.split_at(if args[0] == "command" { 1 } else { 2 });
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(command)
        .arg(format!("udpout:127.0.0.1:{port}"))
        .args(rest)
        .args(["--timeout", "5"])
        .output()
        .expect("mavstack runs")
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn json_lines(text: &str) -> Vec<Value> {
    text.lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect()
}

#[test]
fn params_list_get_set_and_save_round_trip() {
    let dir = tempfile::tempdir().expect("tmp");
    let file = dir.path().join("table.parm");
    let lines: String = (0..150)
        .map(|i| {
            format!(
                "P_{i:03} {}\n",
                if i % 2 == 0 {
                    format!("{i}")
                } else {
                    format!("{i}.5")
                }
            )
        })
        .collect();
    std::fs::write(&file, lines).expect("write");
    let v = Vehicle::start(&[
        "--autopilot",
        "px4",
        "--params",
        file.to_str().expect("utf-8"),
    ]);
    let port = v.port;
    let list = json_lines(&ok(&gcs(port, &["param", "list", "--json"])));
    assert_eq!(list.len(), 150);
    assert_eq!(list[7]["name"], "P_007");
    assert_eq!(list[7]["value"], 7.5);
    assert_eq!(list[8]["type"], "INT32");
    assert_eq!(list[8]["value"], 8);
    let set = json_lines(&ok(&gcs(
        port,
        &["param", "set", "P_009", "-2.25", "--json"],
    )));
    assert_eq!(set[0]["value"], -2.25);
    assert_eq!(set[0]["previous"], 9.5);
    let got = ok(&gcs(port, &["param", "get", "P_009", "P_010"]));
    assert_eq!(got, "P_009 = -2.25 (REAL32)\nP_010 = 10 (INT32)\n");
    let saved = dir.path().join("saved.parm");
    ok(&gcs(
        port,
        &["param", "list", "--save", saved.to_str().expect("utf-8")],
    ));
    let text = std::fs::read_to_string(&saved).expect("saved");
    assert_eq!(text.lines().count(), 150);
    assert!(
        text.contains("P_009 -2.25\n") && text.contains("P_010 10\n"),
        "{text}"
    );
    let missing = gcs(port, &["param", "get", "NO_SUCH"]);
    assert_eq!(missing.status.code(), Some(1));
    // Beyond f32's range: refused before anything is sent, the value unchanged.
    for huge in ["1e300", "nan"] {
        let out = gcs(port, &["param", "set", "P_009", huge]);
        assert_eq!(out.status.code(), Some(2), "param set P_009 {huge}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("is not a REAL32 value"),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let got = ok(&gcs(port, &["param", "get", "P_009"]));
    assert_eq!(got, "P_009 = -2.25 (REAL32)\n");
}

/// `plan.waypoints` in `dir`: home and a takeoff to 20 m, then the items `more` (QGC WPL 110).
fn plan_file(dir: &tempfile::TempDir, more: &str) -> std::path::PathBuf {
    let wpl = dir.path().join("plan.waypoints");
    let plan = format!(
        "QGC WPL 110\n\
         0\t1\t0\t16\t0\t0\t0\t0\t-35.36326100\t149.16523000\t584\t1\n\
         1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t20\t1\n{more}"
    );
    std::fs::write(&wpl, plan).expect("write");
    wpl
}

#[test]
fn missions_upload_download_clear_in_both_formats() {
    let dir = tempfile::tempdir().expect("tmp");
    let wpl = plan_file(
        &dir,
        "2\t0\t3\t16\t5\t0\t0\tnan\t-35.36200000\t149.16400000\t30\t1\n\
         3\t0\t3\t20\t0\t0\t0\t0\t0\t0\t0\t1\n",
    );
    let v = Vehicle::start(&[]);
    let port = v.port;
    let up = ok(&gcs(
        port,
        &["mission", "upload", wpl.to_str().expect("utf-8")],
    ));
    assert!(up.starts_with("4 mission items uploaded to 1/1"), "{up}");
    let json_file = dir.path().join("plan.json");
    ok(&gcs(
        port,
        &["mission", "download", json_file.to_str().expect("utf-8")],
    ));
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(&json_file).expect("read")).expect("JSON");
    let items = doc["items"].as_array().expect("items");
    assert_eq!(items.len(), 4);
    assert_eq!(items[2]["x"], -353_620_000);
    assert_eq!(items[2]["param1"], 5.0);
    assert_eq!(items[2]["param4"], Value::Null);
    assert_eq!(items[3]["command_name"], "MAV_CMD_NAV_RETURN_TO_LAUNCH");
    // The JSON goes back up as a fence, and comes down as WPL equal to the original.
    ok(&gcs(
        port,
        &[
            "mission",
            "upload",
            json_file.to_str().expect("utf-8"),
            "--type",
            "fence",
        ],
    ));
    let fence = ok(&gcs(port, &["mission", "download", "--type", "fence"]));
    let mission = ok(&gcs(port, &["mission", "download"]));
    assert_eq!(fence, mission);
    assert!(
        mission.starts_with("QGC WPL 110\n0\t1\t0\t16\t"),
        "{mission}"
    );
    assert!(
        mission.contains("\t-35.36200000\t149.16400000\t30\t1\n"),
        "{mission}"
    );
    ok(&gcs(port, &["mission", "clear"]));
    // ArduPilot keeps home as item 0: the cleared mission is that one item.
    let cleared = ok(&gcs(port, &["mission", "download"]));
    assert_eq!(cleared.lines().count(), 2, "{cleared}");
    assert!(
        cleared.starts_with("QGC WPL 110\n0\t")
            && cleared.contains("\t-35.36326100\t149.16523000\t"),
        "{cleared}"
    );
    let bad = dir.path().join("bad.waypoints");
    std::fs::write(&bad, "QGC WPL 110\n0\t1\t0\n").expect("write");
    let out = gcs(port, &["mission", "upload", bad.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.waypoints:2: expected 12 fields"));
}

/// A vehicle busy with another ground station's upload refuses ours (DENIED to the count):
/// the upload is asked for again, the operator is told why it waits, and it goes through once
/// the other upload ends (here: the other station clears the plan instead).
#[test]
fn an_upload_refused_as_busy_is_asked_again_and_the_operator_told() {
    use core::time::Duration;
    use mavstack_core::message::Message;
    use mavstack_core::wire::{self, Frame, FrameHeader, MAX_FRAME_LEN, Version};
    use mavstack_dialects::common::{MavMissionType, MissionCount, MissionRequestInt};
    use std::process::Stdio;
    use std::time::Instant;

    const OTHER: u8 = 200;
    let v = Vehicle::start(&[]);
    let other = UdpSocket::bind("127.0.0.1:0").expect("bind");
    other
        .set_read_timeout(Some(Duration::from_millis(200)))
        .expect("timeout");
    let send_count = |count: u16, seq: u8| {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let header = FrameHeader {
            version: Version::V2,
            seq,
            sysid: OTHER,
            compid: 190,
            signed: false,
        };
        let m = MissionCount {
            target_system: 1,
            target_component: 1,
            count,
            mission_type: MavMissionType::MISSION,
        };
        let len = wire::emit_message(&header, &m, &mut buf).expect("encode");
        other
            .send_to(&buf[..len], ("127.0.0.1", v.port))
            .expect("send");
    };
    // The other station starts an upload and goes quiet: the vehicle waits for its items
    // (it asks for the first; the deadline is long enough for any machine).
    send_count(3, 0);
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut buf = [0u8; 2048];
    loop {
        assert!(
            Instant::now() < deadline,
            "the vehicle never asked the other station"
        );
        let Ok(n) = other.recv(&mut buf) else {
            continue;
        };
        if let Ok(f) = Frame::new_checked(&buf[..n])
            && f.msg_id() == MissionRequestInt::ID
            && MissionRequestInt::decode(f.payload()).target_system == OTHER
        {
            break;
        }
    }
    let dir = tempfile::tempdir().expect("tmp");
    let wpl = plan_file(&dir, "");
    let mut upload = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(["mission", "upload"])
        .arg(format!("udpout:127.0.0.1:{}", v.port))
        .arg(&wpl)
        .args(["--timeout", "30"])
        .env_remove("RUST_LOG")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mavstack runs");
    // The vehicle refuses ours while the other upload is open, and the operator is told
    // (stderr, read as it comes); then the other station gives up its upload by clearing the
    // plan.
    let stderr = upload.stderr.take().expect("stderr");
    let (told, seen) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        use std::io::BufRead as _;
        let mut all = String::new();
        for line in std::io::BufReader::new(stderr).lines() {
            let Ok(line) = line else { break };
            if line.contains("refused to start it as busy") && line.contains("asking again") {
                let _ = told.send(());
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let warned = seen.recv_timeout(Duration::from_secs(30));
    send_count(0, 1);
    let out = upload.wait_with_output().expect("mavstack ends");
    let err = reader.join().expect("stderr read");
    assert!(warned.is_ok(), "no warning that the vehicle is busy: {err}");
    assert!(out.status.success(), "{err}");
    let up = String::from_utf8_lossy(&out.stdout);
    assert!(
        up.starts_with("2 mission items uploaded to 1/1"),
        "{up}\n{err}"
    );
}

#[test]
fn commands_arm_fly_and_report_refusals() {
    let v = Vehicle::start(&["--autopilot", "ardupilot"]);
    let port = v.port;
    let armed = json_lines(&ok(&gcs(port, &["command", "arm", "--json"])));
    assert_eq!(armed[0]["result"], "ACCEPTED");
    assert_eq!(armed[0]["command"], 400);
    // ArduPilot takes off in GUIDED only.
    let refused = gcs(port, &["command", "takeoff", "5"]);
    assert_eq!(refused.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&refused.stdout).contains("NAV_TAKEOFF → FAILED"));
    ok(&gcs(port, &["command", "mode", "guided"]));
    ok(&gcs(port, &["command", "takeoff", "5"]));
    std::thread::sleep(core::time::Duration::from_secs(1));
    let denied = gcs(port, &["command", "disarm"]);
    assert!(String::from_utf8_lossy(&denied.stdout).contains("→ DENIED"));
    ok(&gcs(port, &["command", "disarm", "--force"]));
    let raw = ok(&gcs(port, &["command", "MAV_CMD_REQUEST_MESSAGE", "242"]));
    assert!(raw.starts_with("REQUEST_MESSAGE → ACCEPTED"), "{raw}");
    let unknown = gcs(port, &["command", "NO_SUCH_COMMAND"]);
    assert_eq!(unknown.status.code(), Some(2));
    let mode = gcs(port, &["command", "mode", "warp"]);
    assert_eq!(mode.status.code(), Some(2));
    let err = String::from_utf8_lossy(&mode.stderr);
    // The vehicle's own list (AVAILABLE_MODES), STABILIZE among it.
    assert!(
        err.contains("unknown ArduPilot Copter mode") && err.contains("STABILIZE"),
        "{err}"
    );
}

#[test]
fn no_vehicle_is_a_clear_failure() {
    let port = free_port();
    let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args([
            "param",
            "list",
            &format!("udpout:127.0.0.1:{port}"),
            "--timeout",
            "1",
        ])
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr).trim(),
        format!("error: no vehicle heard on udpout:127.0.0.1:{port} within 1.0 s")
    );
}

#[test]
fn a_refused_command_shows_the_statustext_that_says_why() {
    // As ArduPilot while its EKF settles: COMMAND_ACK FAILED, the reason in STATUSTEXT.
    let v = Vehicle::start(&["--autopilot", "ardupilot", "--estimator-settle", "600"]);
    let refused = gcs(v.port, &["command", "arm"]);
    assert_eq!(refused.status.code(), Some(1));
    let text = String::from_utf8_lossy(&refused.stdout);
    assert!(
        text.starts_with("COMPONENT_ARM_DISARM → FAILED (")
            && text
                .trim_end()
                .ends_with("s): PreArm: Need Position Estimate"),
        "{text}"
    );
    let json = gcs(v.port, &["command", "arm", "--json"]);
    let line = &json_lines(&String::from_utf8_lossy(&json.stdout))[0];
    assert_eq!(line["result"], "FAILED");
    assert_eq!(
        line["statustext"],
        serde_json::json!(["PreArm: Need Position Estimate"])
    );
    // Forced, it arms (both autopilots' 21196), and an accepted command says nothing more.
    let forced = json_lines(&ok(&gcs(v.port, &["command", "arm", "--force", "--json"])));
    assert_eq!(forced[0]["result"], "ACCEPTED");
    assert_eq!(forced[0]["statustext"], serde_json::json!([]));
}

#[test]
fn a_refusal_explained_in_events_shows_their_texts() {
    // As PX4 v1.16 while its estimator settles: TEMPORARILY_REJECTED, the reasons only in
    // EVENT messages, made into text with the metadata it serves over MAVFTP.
    let v = Vehicle::start(&["--autopilot", "px4", "--estimator-settle", "600"]);
    let json = gcs(v.port, &["command", "arm", "--json"]);
    assert_eq!(json.status.code(), Some(1));
    let line = &json_lines(&String::from_utf8_lossy(&json.stdout))[0];
    assert_eq!(line["result"], "TEMPORARILY_REJECTED");
    let said: Vec<&str> = line["statustext"]
        .as_array()
        .expect("a list")
        .iter()
        .filter_map(|v| v.as_str())
        .collect();
    assert_eq!(said.len(), 2, "{said:?}");
    assert!(
        said[0].starts_with("Preflight Fail: position estimate not valid yet"),
        "{said:?}"
    );
    assert_eq!(
        said[1],
        "Arming denied: Resolve system health failures first"
    );
}

#[test]
fn modes_by_name_follow_the_autopilot() {
    let v = Vehicle::start(&["--autopilot", "px4"]);
    let hold = json_lines(&ok(&gcs(v.port, &["command", "mode", "Hold", "--json"])));
    assert_eq!(hold[0]["result"], "ACCEPTED");
    let unknown = gcs(v.port, &["command", "mode", "guided"]);
    assert_eq!(unknown.status.code(), Some(2));
    let err = String::from_utf8_lossy(&unknown.stderr);
    assert!(
        err.contains("unknown PX4 mode \"guided\"") && err.contains("AUTO.MISSION"),
        "{err}"
    );
}

const KEY: &str = "0b0e0c0a0f0d0e0a0d0b0e0e0f000b0a0d0a0c0a0b0e0e0f0c0a0f0e0b0a0b0e";

/// Runs `mavstack ARGS... --timeout 5` with the connection `conn` after ARGS' first `n`.
fn gcs_on(conn: &str, n: usize, args: &[&str]) -> Output {
    let (command, rest) = args.split_at(n);
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(command)
        .arg(conn)
        .args(rest)
        .args(["--timeout", "5"])
        .output()
        .expect("mavstack runs")
}

/// A `mavstack vehicle udpout:127.0.0.1:PORT --secure`: one link, whose signing outlives each
/// ground-station process (a `udpin` vehicle makes a link per client).
struct SecureVehicle(std::process::Child);

impl Drop for SecureVehicle {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn signing_setup_is_proven_by_a_signed_answer_and_remove_by_an_unsigned_one() {
    let port = free_port();
    let _vehicle = SecureVehicle(
        Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args(["vehicle", &format!("udpout:127.0.0.1:{port}"), "--secure"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("vehicle starts"),
    );
    let conn = format!("udpin:127.0.0.1:{port}");
    let on = ok(&gcs_on(
        &conn,
        2,
        &["signing", "setup", "--key", KEY, "--link-id", "2"],
    ));
    assert_eq!(on.trim(), "signing on: 1/1 answers signed");
    // Now the vehicle signs and wants signed frames: an unsigned ground station hears
    // nothing it accepts, a signed one is answered.
    let unsigned = gcs_on(&conn, 1, &["command", "MAV_CMD_REQUEST_MESSAGE", "148"]);
    assert_eq!(unsigned.status.code(), Some(1));
    ok(&gcs_on(
        &conn,
        1,
        &["command", "MAV_CMD_REQUEST_MESSAGE", "148", "--key", KEY],
    ));
    let off = json_lines(&ok(&gcs_on(
        &conn,
        2,
        &["signing", "remove", "--key", KEY, "--json"],
    )));
    assert_eq!(off[0]["signing"], "off");
    assert_eq!(off[0]["proven"], true);
    ok(&gcs_on(
        &conn,
        1,
        &["command", "MAV_CMD_REQUEST_MESSAGE", "148"],
    ));
    // A vehicle that refuses SETUP_SIGNING (an insecure link) leaves the proof unanswered.
    let insecure = Vehicle::start(&[]);
    let out = gcs(insecure.port, &["signing", "setup", "--key", KEY]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).trim(),
        "signing on: 0/1 answers signed"
    );
    let missing = gcs(insecure.port, &["signing", "setup"]);
    assert_eq!(missing.status.code(), Some(2));
}

/// The vehicle has one key, as ArduPilot: SETUP_SIGNING on one link signs its other links
/// too (ArduPilot's SERIAL1 then refuses unsigned frames), and removing it there unsigns them.
#[test]
fn signing_set_up_on_one_link_signs_the_others() {
    let (first, second) = (free_port(), free_port());
    let _vehicle = SecureVehicle(
        Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args([
                "vehicle",
                &format!("udpout:127.0.0.1:{first}?secure=true"),
                &format!("udpout:127.0.0.1:{second}"),
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("vehicle starts"),
    );
    let (first, second) = (
        format!("udpin:127.0.0.1:{first}"),
        format!("udpin:127.0.0.1:{second}"),
    );
    let request = ["command", "MAV_CMD_REQUEST_MESSAGE", "148"];
    ok(&gcs_on(&second, 1, &request));
    ok(&gcs_on(&first, 2, &["signing", "setup", "--key", KEY]));
    let unsigned = gcs_on(&second, 1, &request);
    assert_eq!(
        unsigned.status.code(),
        Some(1),
        "unsigned on the other link"
    );
    let mut signed = request.to_vec();
    signed.extend(["--key", KEY]);
    ok(&gcs_on(&second, 1, &signed));
    ok(&gcs_on(&first, 2, &["signing", "remove", "--key", KEY]));
    ok(&gcs_on(&second, 1, &request));
}

/// ArduPilot ignores SETUP_SIGNING while armed and says so ("ERROR: Won't setup signing when
/// armed", libraries/GCS_MAVLink/GCS_Signing.cpp): the simulator's ArduPilot flavour too, and
/// the ground station shows the reason; disarmed, the same setup is taken.
#[test]
fn signing_setup_is_refused_while_armed_with_ardupilots_reason() {
    let port = free_port();
    let _vehicle = SecureVehicle(
        Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args([
                "vehicle",
                &format!("udpout:127.0.0.1:{port}"),
                "--secure",
                "--autopilot",
                "ardupilot",
                "--estimator-settle",
                "0",
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("vehicle starts"),
    );
    let conn = format!("udpin:127.0.0.1:{port}");
    ok(&gcs_on(&conn, 1, &["command", "arm"]));
    let refused = gcs_on(&conn, 2, &["signing", "setup", "--key", KEY]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("Won't setup signing when armed"),
        "{stderr}"
    );
    // Still unsigned: an unsigned request is answered.
    ok(&gcs_on(
        &conn,
        1,
        &["command", "MAV_CMD_REQUEST_MESSAGE", "148"],
    ));
    ok(&gcs_on(&conn, 1, &["command", "disarm"]));
    let on = ok(&gcs_on(&conn, 2, &["signing", "setup", "--key", KEY]));
    assert_eq!(on.trim(), "signing on: 1/1 answers signed");
}

#[test]
fn listen_asks_the_vehicle_for_the_rates_given() {
    // The simulator streams ATTITUDE at 4 Hz unasked; 20 Hz only comes when asked for.
    let port = free_port();
    let _vehicle = SecureVehicle(
        Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args(["vehicle", &format!("udpout:127.0.0.1:{port}")])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("vehicle starts"),
    );
    let listen = |extra: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args([
                "listen",
                &format!("udpin:127.0.0.1:{port}"),
                "--filter",
                "ATTITUDE",
            ])
            .args(["--duration", "4"])
            .args(extra)
            .output()
            .expect("listen runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).lines().count()
    };
    let asked = listen(&["--rate", "ATTITUDE:20,GLOBAL_POSITION_INT:5"]);
    // At 4 Hz four seconds hold at most 17; asked for 20 Hz, the last three alone hold 60.
    assert!(asked > 25, "{asked} ATTITUDE in 4 s after asking for 20 Hz");
    let bad = Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args([
            "listen",
            &format!("udpin:127.0.0.1:{port}"),
            "--rate",
            "ATTITUDE",
        ])
        .output()
        .expect("listen runs");
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--rate"));
}

/// `listen --table` names each autopilot's mode and says whether it is armed, from its
/// HEARTBEAT, in the autopilot's own names.
#[test]
fn listen_table_names_the_mode() {
    for (autopilot, mode) in [("ardupilot", "STABILIZE"), ("px4", "AUTO.LOITER")] {
        let port = free_port();
        // The vehicle sends to the listener (a listener on udpout would never be heard).
        let mut vehicle = Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args(["vehicle", &format!("udpout:127.0.0.1:{port}")])
            .args(["--autopilot", autopilot])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("the vehicle starts");
        let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args(["listen", &format!("udpin:127.0.0.1:{port}"), "--table"])
            // Until two HEARTBEATs came, however long that takes.
            .args(["--filter", "HEARTBEAT", "--count", "2"])
            .output()
            .expect("mavstack runs");
        let _ = vehicle.kill();
        let _ = vehicle.wait();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains(&format!("mode {mode}, disarmed")),
            "{autopilot}: {text}"
        );
    }
}
