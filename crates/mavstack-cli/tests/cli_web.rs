//! The web API of `mavstack vehicle --http` and `mavstack router --http` end to end, over
//! real sockets: REST answers, a POSTed COMMAND_LONG the vehicle answers, the WebSocket and
//! its filter, refusals that send nothing, the token, the body limit, and WebSocket clients
//! that never read while the router forwards (counted, not timed).

use core::net::SocketAddr;
use core::time::Duration;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpStream, UdpSocket};
use std::process::{Child, Command, Stdio};
use std::time::Instant;

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use crate::router::Router;
use crate::support;

/// A `mavstack vehicle udpout:... --http 127.0.0.1:0 EXTRA`, killed when dropped.
struct WebVehicle {
    child: Child,
    http: SocketAddr,
}

impl WebVehicle {
    fn start(extra: &[&str]) -> Self {
        let sink = UdpSocket::bind("127.0.0.1:0").expect("a port");
        let port = sink.local_addr().expect("bound").port();
        drop(sink);
        let mut child = Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args([
                "vehicle",
                &format!("udpout:127.0.0.1:{port}"),
                "--http",
                "127.0.0.1:0",
            ])
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("vehicle starts");
        let mut err = BufReader::new(child.stderr.take().expect("piped"));
        let http = loop {
            let mut line = String::new();
            assert!(
                err.read_line(&mut line).expect("stderr") > 0,
                "vehicle exited"
            );
            if let Some(rest) = line.split("status page on http://").nth(1) {
                break rest
                    .trim()
                    .trim_end_matches('/')
                    .parse()
                    .expect("an address");
            }
        };
        std::thread::spawn(move || {
            let mut rest = String::new();
            let _ = err.read_to_string(&mut rest);
        });
        Self { child, http }
    }
}

impl Drop for WebVehicle {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The `--http` address a router printed before it was ready.
fn router_http(router: &Router) -> SocketAddr {
    router
        .before_ready
        .iter()
        .find_map(|l| l.split("status page on http://").nth(1))
        .expect("the router printed its address")
        .trim_end_matches('/')
        .parse()
        .expect("an address")
}

/// One HTTP/1.1 request: (status, body).
fn request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> (u16, String) {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(20)))
        .expect("timeout");
    let mut head = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: {}\r\n",
        body.len()
    );
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    head.push_str("\r\n");
    s.write_all(head.as_bytes()).expect("write");
    // A refused body may be answered before it is all read: a write error is no failure.
    let _ = s.write_all(body);
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    let text = String::from_utf8_lossy(&out).into_owned();
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no status line in {text:?}"));
    let (_, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let body = if text
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        unchunk(body)
    } else {
        body.to_owned()
    };
    (status, body)
}

fn unchunk(body: &str) -> String {
    let mut out = String::new();
    let mut rest = body;
    while let Some((size, after)) = rest.split_once("\r\n") {
        let n = usize::from_str_radix(size.trim(), 16).unwrap_or(0);
        if n == 0 {
            break;
        }
        out.push_str(&after[..n]);
        rest = &after[n + 2..];
    }
    out
}

fn get(addr: SocketAddr, path: &str) -> (u16, String) {
    request(addr, "GET", path, &[], b"")
}

fn post(addr: SocketAddr, body: &str) -> (u16, String) {
    request(
        addr,
        "POST",
        "/mavlink",
        &[("Content-Type", "application/json")],
        body.as_bytes(),
    )
}

fn json_of(text: &str) -> Value {
    serde_json::from_str(text).unwrap_or_else(|e| panic!("{e}: {text}"))
}

/// Waits (up to 20 s) until `path` answers 200 and `ok` holds for its JSON.
fn wait_for(addr: SocketAddr, path: &str, ok: impl Fn(&Value) -> bool) -> Value {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let (status, body) = get(addr, path);
        if status == 200 {
            let v = json_of(&body);
            if ok(&v) {
                return v;
            }
        }
        assert!(Instant::now() < deadline, "{path}: {status} {body}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn command_long(command: &str, params: [f32; 7]) -> String {
    let mut message = json!({
        "type": "COMMAND_LONG", "target_system": 1, "target_component": 1,
        "command": {"type": command}, "confirmation": 0,
    });
    for (i, p) in params.iter().enumerate() {
        message[format!("param{}", i + 1)] = json!(p);
    }
    json!({"header": {"system_id": 255, "component_id": 190, "sequence": 0}, "message": message})
        .to_string()
}

fn sent(addr: SocketAddr) -> u64 {
    json_of(&get(addr, "/api/status").1)["web"]["sent"]
        .as_u64()
        .expect("web.sent")
}

#[test]
fn vehicle_serves_mavlink2rest_s_rest_api() {
    let v = WebVehicle::start(&[]);
    let hb = wait_for(
        v.http,
        "/mavlink/vehicles/1/components/1/messages/HEARTBEAT",
        |_| true,
    );
    assert_eq!(hb["message"]["type"], "HEARTBEAT");
    assert_eq!(
        hb["message"]["autopilot"],
        json!({"type": "MAV_AUTOPILOT_ARDUPILOTMEGA"})
    );
    assert!(hb["status"]["time"]["counter"].as_u64().expect("counter") >= 1);
    // The same under /v1, and a pointer deeper into the object.
    let (status, body) = get(
        v.http,
        "/v1/mavlink/vehicles/1/components/1/messages/HEARTBEAT/message/type",
    );
    assert_eq!((status, json_of(&body)), (200, json!("HEARTBEAT")));
    let all = json_of(&get(v.http, "/mavlink").1);
    assert_eq!(all["vehicles"]["1"]["components"]["1"]["id"], 1);
    assert_eq!(
        get(
            v.http,
            "/mavlink/vehicles/9/components/9/messages/HEARTBEAT"
        ),
        (404, "None".to_owned())
    );
    let (status, body) = get(v.http, "/helper/mavlink?name=COMMAND_LONG");
    assert_eq!(status, 200);
    assert_eq!(
        json_of(&body)["message"]["command"],
        json!({"type": "MAV_CMD_NAV_WAYPOINT"})
    );
    assert_eq!(get(v.http, "/v1/helper/mavlink?name=NOPE").0, 404);
    assert_eq!(json_of(&get(v.http, "/info").1)["version"], 0);
    assert_eq!(json_of(&get(v.http, "/docs.json").1)["openapi"], "3.0.3");

    // A COMMAND_LONG posted to the vehicle's own API reaches its component, which answers.
    let (status, body) = post(
        v.http,
        &command_long(
            "MAV_CMD_REQUEST_MESSAGE",
            [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        ),
    );
    assert_eq!((status, body.as_str()), (200, ""));
    let ack = wait_for(
        v.http,
        "/mavlink/vehicles/1/components/1/messages/COMMAND_ACK",
        |a| a["message"]["command"]["type"] == "MAV_CMD_REQUEST_MESSAGE",
    );
    assert_eq!(
        ack["message"]["result"],
        json!({"type": "MAV_RESULT_ACCEPTED"})
    );
    assert_eq!(ack["message"]["target_system"], 255);
    wait_for(
        v.http,
        "/mavlink/vehicles/1/components/1/messages/AUTOPILOT_VERSION",
        |_| true,
    );

    // Refusals name the problem and send nothing.
    let before = sent(v.http);
    let (status, body) = post(v.http, "{not json");
    assert_eq!(status, 400, "{body}");
    assert!(body.contains("not valid JSON"), "{body}");
    let unknown = json!({"header": {"system_id": 255, "component_id": 190, "sequence": 0},
                         "message": {"type": "NO_SUCH_MESSAGE"}});
    let (status, body) = post(v.http, &unknown.to_string());
    assert_eq!(status, 400);
    assert!(body.contains("unknown message `NO_SUCH_MESSAGE`"), "{body}");
    let mut wrong = json_of(&command_long("MAV_CMD_REQUEST_MESSAGE", [0.0; 7]));
    wrong["message"]["target_system"] = json!(300);
    let (status, body) = post(v.http, &wrong.to_string());
    assert_eq!(status, 400);
    assert!(body.contains("COMMAND_LONG.target_system"), "{body}");
    assert_eq!(sent(v.http), before);
}

#[test]
fn token_is_required_on_every_request_and_websocket() {
    let v = WebVehicle::start(&["--http-token", "s3cret"]);
    for path in [
        "/",
        "/api/status",
        "/mavlink",
        "/v1/info",
        "/helper/mavlink?name=HEARTBEAT",
    ] {
        assert_eq!(get(v.http, path).0, 401, "{path}");
    }
    assert_eq!(
        post(
            v.http,
            &command_long(
                "MAV_CMD_REQUEST_MESSAGE",
                [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
            )
        )
        .0,
        401
    );
    assert_eq!(
        request(
            v.http,
            "GET",
            "/mavlink",
            &[("Authorization", "Bearer wrong")],
            b""
        )
        .0,
        401
    );
    assert_eq!(
        request(
            v.http,
            "GET",
            "/mavlink",
            &[("Authorization", "Bearer s3cret")],
            b""
        )
        .0,
        200
    );
    assert_eq!(get(v.http, "/api/status?token=s3cret").0, 200);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        let refused = ws_connect(v.http, "/ws/mavlink").await;
        assert!(
            refused.is_err(),
            "a WebSocket without the token was accepted"
        );
        let mut ws = ws_connect(v.http, "/ws/mavlink?token=s3cret&filter=HEARTBEAT")
            .await
            .expect("with the token");
        let first = next_text(&mut ws).await;
        assert_eq!(json_of(&first)["message"]["type"], "HEARTBEAT");
    });
}

#[test]
fn bodies_over_the_limit_are_refused() {
    let v = WebVehicle::start(&[]);
    let big = format!("{{\"pad\": \"{}\"}}", "x".repeat(100 * 1024));
    let (status, _) = request(
        v.http,
        "POST",
        "/mavlink",
        &[("Content-Type", "application/json")],
        big.as_bytes(),
    );
    assert_eq!(status, 413);
    assert_eq!(sent(v.http), 0);
}

type Ws = tokio_tungstenite::WebSocketStream<tokio::net::TcpStream>;

async fn ws_connect(
    addr: SocketAddr,
    path: &str,
) -> Result<Ws, tokio_tungstenite::tungstenite::Error> {
    ws_connect_with(addr, path, None).await
}

/// A WebSocket client; with `rcvbuf`, its socket's receive buffer that small (a client that
/// stops reading then holds the server's sends back at once).
async fn ws_connect_with(
    addr: SocketAddr,
    path: &str,
    rcvbuf: Option<u32>,
) -> Result<Ws, tokio_tungstenite::tungstenite::Error> {
    let socket = tokio::net::TcpSocket::new_v4().expect("socket");
    if let Some(n) = rcvbuf {
        socket.set_recv_buffer_size(n).expect("rcvbuf");
    }
    let stream = socket.connect(addr).await.expect("connect");
    let req = format!("ws://{addr}{path}").into_client_request()?;
    tokio_tungstenite::client_async(req, stream)
        .await
        .map(|(ws, _)| ws)
}

async fn next_text(ws: &mut Ws) -> String {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    loop {
        let msg = tokio::time::timeout_at(deadline, ws.next())
            .await
            .expect("a message within 20 s")
            .expect("open")
            .expect("no error");
        if let Message::Text(t) = msg {
            return t.to_string();
        }
    }
}

#[test]
fn router_websocket_filters_and_sends() {
    let vehicle = crate::vehicle::Vehicle::start(&[]);
    // The router's own HEARTBEAT makes the vehicle (waiting on udpin) start talking.
    let router = Router::start([
        format!("udpout:127.0.0.1:{}", vehicle.port),
        "--heartbeat".into(),
        "--http".into(),
        "127.0.0.1:0".into(),
    ]);
    let http = router_http(&router);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        // A filter that no expression can be is refused before the upgrade.
        assert!(ws_connect(http, "/ws/mavlink?filter=(").await.is_err());
        let mut heartbeats = ws_connect(http, "/ws/mavlink?filter=%5EHEARTBEAT%24")
            .await
            .expect("ws");
        let mut acks = ws_connect(http, "/ws/mavlink?filter=COMMAND_ACK")
            .await
            .expect("ws");
        // The router sends nothing to the vehicle until it hears it: wait for its HEARTBEAT.
        for _ in 0..3 {
            let v = json_of(&next_text(&mut heartbeats).await);
            assert_eq!(v["message"]["type"], "HEARTBEAT");
            assert_eq!(v["header"]["system_id"], 1);
        }
        let cmd = command_long(
            "MAV_CMD_REQUEST_MESSAGE",
            [148.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        );
        heartbeats
            .send(Message::Text(cmd.into()))
            .await
            .expect("sent");
        // The answer to the sender, among the HEARTBEATs the filter still passes.
        loop {
            let text = next_text(&mut heartbeats).await;
            if text.starts_with("Ok(") {
                break;
            }
            assert_eq!(json_of(&text)["message"]["type"], "HEARTBEAT", "{text}");
        }
        let ack = json_of(&next_text(&mut acks).await);
        assert_eq!(ack["message"]["type"], "COMMAND_ACK");
        assert_eq!(ack["message"]["target_system"], 255);
        assert_eq!(ack["message"]["target_component"], 190);
        // An object that does not fit is refused with the reason.
        heartbeats
            .send(Message::Text(r#"{"header": {}, "message": {}}"#.into()))
            .await
            .expect("sent");
        loop {
            let text = next_text(&mut heartbeats).await;
            if text.starts_with("Could not convert input message") {
                assert!(text.contains("header: missing field `system_id`"), "{text}");
                break;
            }
        }
    });
    let status = json_of(&get(http, "/api/status").1);
    assert_eq!(status["web"]["sent"], 1);
    assert_eq!(status["web"]["refused"], 2);
    router.stop();
}

#[test]
fn websocket_clients_that_never_read_do_not_hold_the_router_back() {
    // A sender → router → receiver stream of ATTITUDE frames, with 5 WebSocket clients that
    // never read (small receive buffers: their server-side sends block at once) and one that
    // reads: every frame is forwarded, and the clients that do not read lose the oldest frames
    // instead of growing a queue.
    const FRAMES: u32 = 20_000;
    let receiver = UdpSocket::bind("127.0.0.1:0").expect("receiver");
    receiver
        .set_read_timeout(Some(Duration::from_secs(5)))
        .expect("timeout");
    let input = UdpSocket::bind("127.0.0.1:0").expect("a port");
    let in_port = input.local_addr().expect("bound").port();
    drop(input);
    let router = Router::start([
        format!("udpin:127.0.0.1:{in_port}?name=in"),
        format!("udpout:{}?name=out", receiver.local_addr().expect("bound")),
        "--http".into(),
        "127.0.0.1:0".into(),
    ]);
    let http = router_http(&router);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .expect("runtime");
    let mut stalled = Vec::new();
    for _ in 0..5 {
        stalled.push(
            rt.block_on(ws_connect_with(http, "/ws/mavlink", Some(4096)))
                .expect("ws"),
        );
    }
    let reader = rt.spawn(async move {
        let mut ws = ws_connect(http, "/ws/mavlink?filter=ATTITUDE")
            .await
            .expect("ws");
        let mut n = 0u64;
        while let Ok(Some(Ok(_))) = tokio::time::timeout(Duration::from_secs(3), ws.next()).await {
            n += 1;
        }
        n
    });
    std::thread::sleep(Duration::from_millis(300));
    let sender = UdpSocket::bind("127.0.0.1:0").expect("sender");
    sender.connect(("127.0.0.1", in_port)).expect("connect");
    // What the receiver has got so far: the sender keeps at most WINDOW frames in flight,
    // so that no socket buffer on the way can overflow however the machine schedules the
    // three processes (a loss is then the router's).
    const WINDOW: u32 = 128;
    let got = std::sync::Arc::new(core::sync::atomic::AtomicU32::new(0));
    let counted = std::sync::Arc::clone(&got);
    let receiving = std::thread::spawn(move || {
        let mut buf = [0u8; 2048];
        let mut n = 0u32;
        while let Ok(len) = receiver.recv(&mut buf) {
            if len > 0 {
                n += 1;
                counted.store(n, core::sync::atomic::Ordering::Release);
            }
            if n == FRAMES {
                break;
            }
        }
        n
    });
    let mut frame = [0u8; 64];
    for i in 0..FRAMES {
        // ATTITUDE (30), MAVLink 2, from 7/1: time_boot_ms = i, the rest zero.
        let header = mavstack::core::wire::FrameHeader {
            version: mavstack::core::wire::Version::V2,
            seq: i as u8,
            sysid: 7,
            compid: 1,
            signed: false,
        };
        let len = mavstack::core::wire::emit_message::<mavstack::dialects::common::Attitude>(
            &header,
            &mavstack::dialects::common::Attitude {
                time_boot_ms: i,
                ..Default::default()
            },
            &mut frame,
        )
        .expect("fits");
        // At most WINDOW frames ahead of the receiver; a frame lost for good stalls the
        // window for 5 s at most, and the count below fails.
        let stall = Instant::now() + Duration::from_secs(5);
        while i.saturating_sub(got.load(core::sync::atomic::Ordering::Acquire)) >= WINDOW
            && Instant::now() < stall
        {
            std::thread::sleep(Duration::from_micros(200));
        }
        sender.send(&frame[..len]).expect("sent");
    }
    let received = receiving.join().expect("receiver");
    let status = json_of(&get(http, "/api/status").1);
    let read = rt.block_on(reader).expect("reader");
    drop(stalled);
    router.stop();
    assert_eq!(received, FRAMES, "frames forwarded to the UDP receiver");
    let out = status["links"]
        .as_array()
        .expect("links")
        .iter()
        .find(|l| l["name"] == "out")
        .expect("out");
    assert_eq!(out["tx_frames"], FRAMES);
    // The web service saw the stream (it may miss frames when it falls behind: its link's
    // queue is bounded too).
    assert!(
        status["web"]["frames"].as_u64().expect("frames") > 0,
        "{}",
        status["web"]
    );
    assert!(
        status["web"]["ws_dropped"].as_u64().expect("ws_dropped") > 0,
        "{}",
        status["web"]
    );
    assert!(read > 0, "the reading client got frames");
    assert_eq!(status["web"]["clients"], 6);
}

#[test]
fn status_page_in_chromium_shows_the_vehicle_flown_through_the_api() {
    // tests-interop/web_page.py: the vehicle flown through POST /mavlink with the token, the
    // page opened in headless chromium; every value on the vehicle's card checked against
    // the API. Never skipped: without pymavlink, chromium or chromedriver it fails.
    support::require_pymavlink();
    let artifacts = support::workspace().join("target/operator-tools");
    let out = support::run_script(
        "web_page.py",
        &[
            std::ffi::OsStr::new("--mavstack"),
            std::ffi::OsStr::new(env!("CARGO_BIN_EXE_mavstack")),
            std::ffi::OsStr::new("--artifacts"),
            artifacts.as_os_str(),
        ],
    );
    assert!(
        out.starts_with("web_page: ") && out.trim_end().ends_with(" ok"),
        "{out}"
    );
}

#[test]
fn a_non_loopback_address_needs_a_token_or_http_public() {
    for args in [
        &["--http", "0.0.0.0:0"][..],
        &["--http", "127.0.0.1:0", "--http-token", ""][..],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args(["router", "udpin:127.0.0.1:0"])
            .args(args)
            .output()
            .expect("runs");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--http"), "{err}");
        if args[1] == "0.0.0.0:0" {
            assert!(err.contains("--http-token"), "{err}");
        }
    }
}
