#!/usr/bin/env python3
"""`mavstack router` with an MQTT 5 fleet link (mqtt://...?fleet=F&vid=V), against mosquitto
(Debian's broker, started here on a free port) and paho-mqtt as the independent MQTT peer;
pymavlink 2.4.50 plays the vehicle's network and packs and reads every frame.

Usage: bridge_interop.py SCENARIO --mavstack BIN

Topology: pymavlink peer (or `mavstack vehicle`) --udp--> router --mqtt--> mosquitto <-- paho.
Keys as docs/contracts/fleet-keys.md gives them. Exit 0 with "<scenario>: ... ok", or 1
with FAIL lines. Never skipped: without mosquitto or paho-mqtt it fails.

Scenarios:
  telemetry  a pymavlink vehicle (1/1) sends MAVLink 2, MAVLink 1, signed MAVLink 2 frames and a
             frame of an id no dialect knows; a paho subscriber on mav/F/V/# gets each on
             mav/F/V/{sysid}/{compid}/{pymavlink's message name} (the number for the unknown
             id), byte for byte, signature and all; telemetry at QoS 0, control (HEARTBEAT,
             COMMAND_ACK) at QoS 1
  inbound    frames published on mav/F/V/in (pymavlink-packed COMMAND_LONG, a MAVLink 1
             HEARTBEAT, a signed frame) reach the vehicle's UDP socket byte for byte, and are
             never published back
  command    `mavstack vehicle` behind the router: an MQTT 5 request (response topic +
             correlation data) with a COMMAND_LONG to mav/F/V/1/1/@cmd gets the vehicle's
             COMMAND_ACK frame (pymavlink decodes it: command and result) with the same
             correlation data; a request to a system nobody has seen gets the payload
             `timeout` and error=timeout after the resends; a key that does not match the
             frame's target gets error=target_mismatch at once
  ground     two vehicle routers (truck-1, truck-2), each with a pymavlink vehicle that is system
             1, and a ground router subscribed to the whole fleet (vid=*) with a pymavlink
             ground station: truck-1's frames arrive byte for byte as system 1, truck-2's as
             system 2 (exactly pymavlink's packing of its message as system 2, same seq); the
             ground station's COMMAND_LONG to system 2 reaches truck-2 as pymavlink's packing of
             the command to system 1, and truck-1 never gets it
  tls        mosquitto with a TLS listener that asks for client certificates (a CA, server and client
             certificates made with openssl): a mqtts:// link with ca=, client_cert= and client_key=
             carries frames both ways; one without ca= (the system's roots) never connects
  alive      @alive is retained `online` while the router runs, `offline` after SIGTERM
             (published by the router), and `offline` by the last will after SIGKILL
  corrupt    frames packed by pymavlink, then one payload byte flipped: a COMMAND_LONG on
             mav/F/V/in and one as a request on @cmd never reach the pymavlink vehicle (nor
             does any resend of the request: a valid request sent after it reaches it, resent
             until its own timeout reply); the request gets error=bad_crc at once; the
             router's stats count both (bad_crc 2)
  vehicles   a ground router on vid=*&max_vehicles=3 with a real vehicle (truck-1, a vehicle
             router with a pymavlink vehicle) heard first; a paho client announces 20 more
             vehicles (@alive online and a HEARTBEAT each): at most 3 vehicle links, the
             refusals counted (vehicles_refused), truck-1's frames still reach the ground
             station and a command reaches truck-1; one announced vehicle going offline frees
             a place for a new one
"""

import os
import signal
import socket
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import mqtt_broker  # noqa: E402
import router_interop as ri  # noqa: E402
from router_interop import KEY, M, V1, Peer, decode, heartbeat, start_router  # noqa: E402
import scenario  # noqa: E402
from scenario import check, fail, failures, free_port  # noqa: E402

try:
    import paho.mqtt.client as mqtt
    from paho.mqtt.packettypes import PacketTypes
    from paho.mqtt.properties import Properties
except ImportError as e:  # a missing peer is a failure, never a skip
    print("FAIL: paho-mqtt is not installed (%s); run scripts/setup-peers.sh" % e, file=sys.stderr)
    sys.exit(1)

FLEET, VID = "fleet1", "veh-7"
# How long a wait for something that must come lasts: only what never comes fails.
DEADLINE = 30
PREFIX = "mav/%s/%s" % (FLEET, VID)


class Broker(mqtt_broker.Broker):
    """mosquitto for one scenario, with this script's fleet and vehicle in its URL."""

    def url(self, extra=""):
        return super().url(FLEET, VID, extra)


class Client:
    """A paho MQTT 5 client that records every message: (topic, payload, qos, retain, properties)."""

    def __init__(self, broker, subs=(), name="paho"):  # TLS (with a client certificate) if broker.tls
        self.got = []
        self.lock = threading.Lock()
        self.c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="%s-%d" % (name, os.getpid()),
                             protocol=mqtt.MQTTv5)
        self.c.on_message = self._on_message
        self.ready = threading.Event()
        self.subs = list(subs)
        self.c.on_connect = self._on_connect
        self.c.on_subscribe = lambda *a: self.ready.set()
        if getattr(broker, "tls", None):
            self.c.tls_set(ca_certs=broker.tls.ca, certfile=broker.tls.client_cert, keyfile=broker.tls.client_key)
        self.c.connect("127.0.0.1", broker.port)
        self.c.loop_start()
        if self.subs and not self.ready.wait(5):
            fail("%s: not subscribed within 5 s" % name)
        elif not self.subs:
            time.sleep(0.2)

    def _on_connect(self, client, userdata, flags, reason, props):
        for s in self.subs:
            client.subscribe(s, qos=1)
        if not self.subs:
            self.ready.set()

    def _on_message(self, client, userdata, m):
        with self.lock:
            self.got.append((m.topic, bytes(m.payload), m.qos, m.retain, m.properties, time.monotonic()))

    def messages(self, pred=lambda t, p: True, after=0):
        """The messages (of all, or of those after the first `after`) for which `pred` holds."""
        with self.lock:
            return [g for g in self.got[after:] if pred(g[0], g[1])]

    def wait(self, pred, timeout=5.0, after=0):
        """The first message (of all, or of those after the first `after`) for which `pred`
        holds, waiting up to `timeout` seconds; None if none came."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = self.messages(pred, after)
            if m:
                return m[0]
            time.sleep(0.02)
        return None

    def publish(self, topic, payload, qos=1, props=None):
        info = self.c.publish(topic, payload, qos=qos, properties=props)
        info.wait_for_publish(5)

    def close(self):
        self.c.loop_stop()
        self.c.disconnect()


def with_router(bin_, broker, udp_link, extra_links=()):
    router, _ = start_router(bin_, lambda: [udp_link(), broker.url(), *extra_links])
    return router


def telemetry(bin_):
    broker = Broker()
    sub = Client(broker, ["%s/#" % PREFIX], "sub")
    port = free_port()
    router = with_router(bin_, broker, lambda: "udpin:127.0.0.1:%d" % port)
    if router is None:
        broker.stop()
        return None
    veh = Peer("vehicle", M, 1, 1, dest=port)
    signer = Peer("signed", M, 1, 2, dest=port, key=KEY, link_id=3)
    v1 = Peer("v1", V1, 2, 1, dest=port)
    try:
        sent = send_telemetry(veh, signer, v1, PREFIX)  # (topic, raw, qos)
        for topic, raw, qos in sent:
            got = sub.messages(lambda t, p, raw=raw: p == raw)
            check(got, "%s: frame %s never reached the subscriber" % (topic, raw.hex()))
            for t, p, q, retain, _, _ in got:
                check(t == topic, "frame %s on %s, expected %s" % (raw.hex()[:40], t, topic))
                check(q == qos, "%s at QoS %d, expected %d" % (topic, q, qos))
        signed = [p for t, p, *_ in sub.messages() if len(p) > 12 and p[0] == 0xFD and p[2] & 1]
        check(signed and all(mi_verify(p) for p in signed),
              "signed frames on the broker: %d, all verify with the key: %s" % (len(signed), signed and all(mi_verify(p) for p in signed)))
        nframes = len([1 for t, *_ in sub.messages() if not t.endswith("@alive")])
        stats = router.stop()
        bridges = (stats or {}).get("bridges") or [{}]
        check(bridges[0].get("published", 0) >= len(sent) and bridges[0].get("connections") == 1,
              "the router's last stats line: bridge counters %r (published >= %d, one connection)" % (bridges, len(sent)))
        return "%d frames on their keys byte for byte (v1, v2, signed, unknown id), %d messages in all; %s" % (
            len(sent), nframes, "bridge stats: %d published" % bridges[0].get("published", 0))
    finally:
        for p in (veh, signer, v1):
            p.close()
        if router.running():
            router.stop()
        sub.close()
        broker.stop()


def send_telemetry(veh, signer, v1, prefix):
    """The telemetry scenario's frames (MAVLink 2 from 1/1, signed from 1/2, MAVLink 1 from
    2/1, an id no dialect has), sent through the peers: [(key, raw, MQTT QoS)]."""
    veh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
    time.sleep(0.3)  # the route to the bridge link exists from the start; the UDP peer is learned
    msgs = [
        (veh, M.MAVLink_attitude_message(1000, 0.1, -0.2, 0.3, 0.01, 0.02, 0.03), 0),
        (veh, M.MAVLink_global_position_int_message(2000, -353632610, 1491652380, 584000, 10000, 1, 2, 3, 9000), 0),
        (veh, M.MAVLink_command_ack_message(M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 255, 190), 1),
        (signer, M.MAVLink_sys_status_message(1, 1, 1, 500, 11000, 10, 90, 0, 0, 0, 0, 0, 0), 0),
        (v1, V1.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3), 1),
        (v1, V1.MAVLink_vfr_hud_message(10.0, 11.0, 90, 50, 100.0, 1.0), 0),
    ]
    sent = []
    for peer, m, qos in msgs:
        f = peer.send(m)
        sent.append(("%s/%d/%d/%s" % (prefix, f.sysid, f.compid, f.type), f.raw, qos))
    # An id no dialect has (MAVLink 2 frame, id 60001, valid header and CRC bytes as sent).
    unknown = bytes([0xFD, 3, 0, 0, 9, 1, 1]) + (60001).to_bytes(3, "little") + b"\x01\x02\x03\xaa\xbb"
    veh.write(unknown)
    sent.append(("%s/1/1/60001" % prefix, unknown, 0))
    time.sleep(1.0)
    return sent


def inbound_frames():
    """What the inbound scenario lets into the vehicle's network: (plain frames for 1/1, a
    signed frame for 2/1), all packed by pymavlink."""
    gcs_tx = M.MAVLink(None, srcSystem=255, srcComponent=190)
    gcs_v1 = V1.MAVLink(None, srcSystem=255, srcComponent=191)
    signed_tx = M.MAVLink(None, srcSystem=254, srcComponent=1)
    signed_tx.signing.secret_key, signed_tx.signing.link_id = KEY, 9
    signed_tx.signing.sign_outgoing, signed_tx.signing.timestamp = True, ri.signing_now()
    plain = [
        bytes(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs_tx)),
        bytes(V1.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(gcs_v1)),
    ]
    return plain, [bytes(M.MAVLink_param_request_list_message(2, 1).pack(signed_tx))]


def check_delivered(want, timeout=3.0):
    """Waits until every (peer, raw) of `want` reached its peer byte for byte; a FAIL for each
    that did not."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not all(any(f.raw == raw for f in p.frames()) for p, raw in want):
        time.sleep(0.05)
    for p, raw in want:
        check(any(f.raw == raw for f in p.frames()), "frame %s from mav/F/V/in never reached the %s byte for byte; "
              "it got %s" % (raw.hex(), p.name, p.frames()[:5]))


def mi_verify(raw):
    """pymavlink verifies the signature of raw with KEY."""
    mav = M.MAVLink(None)
    mav.signing.secret_key = KEY
    mav.signing.allow_unsigned_callback = None
    msgs = mav.parse_buffer(raw) or []
    return len(msgs) == 1 and msgs[0].get_type() != "BAD_DATA" and mav.signing.sig_count == 1


def inbound(bin_):
    broker = Broker()
    sub = Client(broker, ["%s/#" % PREFIX], "sub")
    pub = Client(broker, [], "pub")
    ports = (free_port(), free_port())
    router, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % ports[0],
                                            "udpin:127.0.0.1:%d?key=%s" % (ports[1], KEY.hex()),
                                            broker.url()])
    veh = Peer("vehicle", M, 1, 1, dest=ports[0])
    sveh = Peer("signed vehicle", M, 2, 1, dest=ports[1], key=KEY, link_id=4)
    if router is None:
        broker.stop()
        return None
    plain, signed = inbound_frames()
    try:
        # Each vehicle makes itself known (the router learns where 1/1 and 2/1 are).
        # The plain one in MAVLink 1: its auto link carries what comes in the framing it came in.
        veh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA), v1=True)
        sveh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        time.sleep(0.3)
        for raw in plain + signed:
            pub.publish("%s/in" % PREFIX, raw)
        want = [(veh, raw) for raw in plain] + [(sveh, raw) for raw in signed]
        check_delivered(want)
        echoed = [t for t, p, *_ in sub.messages() if p in plain + signed and not t.endswith("/in")]
        check(not echoed, "frames from the broker were published back on %s" % echoed)
        return ("%d frames from mav/F/V/in reached the vehicles byte for byte (v2, v1, and a signed one through a "
                "key= link), none published back" % len(want))
    finally:
        veh.close()
        sveh.close()
        router.stop()
        sub.close()
        pub.close()
        broker.stop()


def request(client, topic, raw, corr):
    props = Properties(PacketTypes.PUBLISH)
    props.ResponseTopic = "replies/%s" % corr
    props.CorrelationData = corr.encode()
    client.publish(topic, raw, props=props)
    return props.ResponseTopic


def user_props(props):
    return dict(getattr(props, "UserProperty", None) or [])


def command(bin_):
    broker = Broker()
    heartbeats = "%s/1/1/HEARTBEAT" % PREFIX
    cli = Client(broker, ["replies/#", heartbeats], "cloud")
    vport = free_port()
    vehicle = subprocess.Popen([bin_, "vehicle", "udpout:127.0.0.1:%d" % vport], stdin=subprocess.DEVNULL,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    router = with_router(bin_, broker, lambda: "udpin:127.0.0.1:%d" % vport)
    if router is None:
        vehicle.kill()
        broker.stop()
        return None
    gcs = M.MAVLink(None, srcSystem=255, srcComponent=190)
    try:
        # The vehicle's HEARTBEAT teaches the router its route; published, it has been learned.
        if not check(cli.wait(lambda t, p: t == heartbeats, DEADLINE) is not None,
                     "no HEARTBEAT of the vehicle on %s within %d s" % (heartbeats, DEADLINE)):
            return None
        arm = bytes(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs))
        t0 = time.monotonic()
        reply_topic = request(cli, "%s/1/1/@cmd" % PREFIX, arm, "arm-1")
        got = cli.wait(lambda t, p: t == reply_topic, DEADLINE)
        check(got is not None, "no reply to the ARM request within %d s" % DEADLINE)
        summary = []
        if got:
            t, payload, qos, _, props, at = got
            msgs = M.MAVLink(None).parse_buffer(payload) or []
            check(len(msgs) == 1 and msgs[0].get_type() == "COMMAND_ACK", "the reply is not one COMMAND_ACK frame: %s" % payload.hex())
            if msgs and msgs[0].get_type() == "COMMAND_ACK":
                ack = msgs[0]
                check(ack.command == M.MAV_CMD_COMPONENT_ARM_DISARM, "ACK for command %d" % ack.command)
                check(ack.result == M.MAV_RESULT_ACCEPTED, "ARM result %d, expected ACCEPTED" % ack.result)
                check(ack.get_srcSystem() == 1, "ACK from system %d" % ack.get_srcSystem())
                summary.append("ARM -> COMMAND_ACK ACCEPTED in %.0f ms" % ((at - t0) * 1000))
            check(getattr(props, "CorrelationData", None) == b"arm-1", "correlation data %r, expected b'arm-1'" %
                  getattr(props, "CorrelationData", None))
            check(qos == 1, "reply at QoS %d" % qos)
        # Nobody is system 9: the bridge resends, then answers timeout.
        lost = bytes(M.MAVLink_command_long_message(9, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs))
        t0 = time.monotonic()
        reply_topic = request(cli, "%s/9/1/@cmd" % PREFIX, lost, "lost-1")
        got = cli.wait(lambda t, p: t == reply_topic, DEADLINE)
        check(got is not None, "no timeout reply for a command to nobody within %d s" % DEADLINE)
        if got:
            waited = got[5] - t0
            check(got[1] == b"timeout" and user_props(got[4]).get("error") == "timeout",
                  "reply %r %r, expected b'timeout' with error=timeout" % (got[1], user_props(got[4])))
            # Only a lower bound: the bridge's timers never fire early, a busy machine only
            # makes the reply later.
            check(waited >= 1.5, "the timeout came after %.1f s, before the 4 sends 0.5 s apart" % waited)
            check(getattr(got[4], "CorrelationData", None) == b"lost-1", "timeout reply's correlation data")
            summary.append("no one -> timeout after %.1f s" % waited)
        # Key 1/2, frame to 1/1: refused at once.
        reply_topic = request(cli, "%s/1/2/@cmd" % PREFIX, arm, "bad-1")
        got = cli.wait(lambda t, p: t == reply_topic, DEADLINE)
        check(got is not None and user_props(got[4]).get("error") == "target_mismatch",
              "a key that does not match the target: %r" % ((got and (got[1], user_props(got[4]))),))
        summary.append("mismatched key -> target_mismatch")
        return "; ".join(summary)
    finally:
        router.stop()
        vehicle.send_signal(signal.SIGINT)
        try:
            vehicle.wait(5)
        except subprocess.TimeoutExpired:
            vehicle.kill()
        cli.close()
        broker.stop()


def alive(bin_):
    broker = Broker()
    try:
        port = free_port()
        router = with_router(bin_, broker, lambda: "udpin:127.0.0.1:%d" % port)
        if router is None:
            return None
        time.sleep(0.5)
        watch = Client(broker, ["%s/@alive" % PREFIX], "watch")
        first = watch.wait(lambda t, p: True, DEADLINE)
        check(first is not None and first[1] == b"online" and first[3], "retained @alive while running: %r" % (first,))
        router.stop()
        off = watch.wait(lambda t, p: p == b"offline", DEADLINE)
        check(off is not None, "no offline on @alive after SIGTERM")
        late = Client(broker, ["%s/@alive" % PREFIX], "late")
        r = late.wait(lambda t, p: True, DEADLINE)
        check(r is not None and r[1] == b"offline" and r[3], "retained @alive after exit: %r" % (r,))
        late.close()
        # SIGKILL: the broker's last will says offline. The second router's own "online"
        # (not the first's, still in the list) says it is connected, its will with the broker.
        before = len(watch.messages())
        router2 = with_router(bin_, broker, lambda: "udpin:127.0.0.1:%d" % free_port())
        if router2 is None:
            return None
        t_on = watch.wait(lambda t, p: p == b"online" and t == "%s/@alive" % PREFIX, DEADLINE, after=before)
        online_at = len(watch.messages())
        router2.kill()
        will = watch.wait(lambda t, p: p == b"offline", 10, after=online_at)
        check(t_on is not None, "second router never said online within %d s" % DEADLINE)
        check(will is not None, "no last will (offline) within 10 s of SIGKILL")
        watch.close()
        return "online (retained) -> offline on SIGTERM -> online -> offline by the last will on SIGKILL"
    finally:
        broker.stop()


def ground(bin_):
    broker = Broker()
    try:
        return ground_through(bin_, lambda vid: mqtt_broker.Broker.url(broker, FLEET, vid))
    finally:
        broker.stop()


def ground_through(bin_, url):
    """The ground scenario over the bridge links url(vid) gives (MQTT here, Zenoh in
    bridge_zenoh.py)."""
    vports = (free_port(), free_port())
    routers = []
    peers = []
    try:
        for vid, port in zip(("truck-1", "truck-2"), vports):
            r, _ = start_router(bin_, lambda vid=vid, port=port: ["udpin:127.0.0.1:%d" % port, url(vid)])
            if r is None:
                return None
            routers.append(r)
        gport = free_port()
        g, _ = start_router(bin_, lambda: [url("*"), "udpin:127.0.0.1:%d?name=gcs" % gport])
        if g is None:
            return None
        routers.append(g)
        a = Peer("truck-1", M, 1, 1, dest=vports[0])
        b = Peer("truck-2", M, 1, 1, dest=vports[1])
        gcs = Peer("gcs", M, 255, 190, dest=gport)
        peers += [a, b, gcs]
        gcs.send(heartbeat())
        for p in (a, b):
            p.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        time.sleep(0.5)
        fa = a.send(M.MAVLink_attitude_message(111, 0.1, 0, 0, 0, 0, 0))
        fb = b.send(M.MAVLink_attitude_message(222, 0.2, 0, 0, 0, 0, 0))
        got_a = gcs.wait_for(lambda f: f.type == "ATTITUDE" and f.msg.time_boot_ms == 111, DEADLINE)
        got_b = gcs.wait_for(lambda f: f.type == "ATTITUDE" and f.msg.time_boot_ms == 222, DEADLINE)
        check(got_a is not None and got_a.raw == fa.raw,
              "truck-1's ATTITUDE at the ground station byte for byte as system 1: %r" % got_a)
        # The expectation is pymavlink's packing of truck-2's message as system 2, same seq.
        want_b = ri.repack(M, fb.msg, (2, 1, fb.seq))
        check(got_b is not None and got_b.sysid == 2, "truck-2's ATTITUDE as system 2 at the ground station: %r" % got_b)
        if got_b is not None:
            check(got_b.raw == want_b, "truck-2's remapped ATTITUDE %s, pymavlink packs %s" % (got_b.raw.hex(), want_b.hex()))
        # A command to system 2 reaches truck-2 as a command to its own system 1, and not truck-1.
        t = time.monotonic()
        cmd = gcs.send(M.MAVLink_command_long_message(2, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
        arrived = b.wait_for(lambda f: f.type == "COMMAND_LONG", DEADLINE, since=t)
        want = ri.repack(M, M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0),
                         (255, 190, cmd.seq))
        check(arrived is not None and arrived.raw == want,
              "truck-2 got %r for the command to system 2; pymavlink packs %s" % (arrived, want.hex()))
        check(not [f for f in a.frames(t) if f.type == "COMMAND_LONG"], "truck-1 got the command meant for truck-2")
        return "two vehicles with sysid 1 seen as systems 1 and 2 (pymavlink's packing), a command to 2 reaches truck-2 as 1"
    finally:
        for p in peers:
            p.close()
        for r in routers:
            r.stop()


def tls(bin_):
    certs = mqtt_broker.Certs()
    broker = Broker(tls=certs)
    sub = Client(broker, ["%s/#" % PREFIX], "sub")
    pub = Client(broker, [], "pub")
    port, port2 = free_port(), free_port()
    opts = "&ca=%s&client_cert=%s&client_key=%s" % (certs.ca, certs.client_cert, certs.client_key)
    url = "mqtts://127.0.0.1:%d?fleet=%s&vid=%s" % (broker.port, FLEET, VID)
    router, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % port, url + opts])
    # Without the test CA the broker's certificate does not verify (the system's roots).
    untrusting, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % port2, url.replace(VID, "other") +
                                                "&client_cert=%s&client_key=%s" % (certs.client_cert, certs.client_key)])
    veh = Peer("vehicle", M, 1, 1, dest=port)
    try:
        if router is None or untrusting is None:
            return None
        veh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        time.sleep(0.5)
        f = veh.send(M.MAVLink_attitude_message(1000, 0.1, -0.2, 0.3, 0.01, 0.02, 0.03))
        got = sub.wait(lambda t, p: p == f.raw, DEADLINE)
        check(got is not None and got[0] == "%s/1/1/ATTITUDE" % PREFIX,
              "ATTITUDE over TLS on its key byte for byte: %r" % (got and got[:2],))
        gcs = M.MAVLink(None, srcSystem=255, srcComponent=190)
        raw = bytes(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs))
        pub.publish("%s/in" % PREFIX, raw)
        arrived = veh.wait_for(lambda fr: fr.raw == raw, DEADLINE)
        check(arrived is not None, "a frame published on in over TLS never reached the vehicle")
        stats = router.stop()
        bridges = (stats or {}).get("bridges") or [{}]
        check(bridges[0].get("connections") == 1, "the TLS link's connections: %r" % (bridges,))
        stats2 = untrusting.stop()
        b2 = (stats2 or {}).get("bridges") or [{}]
        check(b2[0].get("connections") == 0, "a link without the CA connected anyway: %r" % (b2,))
        check(not sub.messages(lambda t, p: "/other/" in t), "frames from the link without the CA reached the broker")
        return ("mqtts:// with a client certificate: ATTITUDE byte for byte, a frame on in reached the vehicle; "
                "without the CA the broker's certificate is refused (0 connections)")
    finally:
        veh.close()
        for r in (router, untrusting):
            if r is not None and r.running():
                r.stop()
        sub.close()
        pub.close()
        broker.stop()
        certs.close()


def pymavlink_refuses(raw):
    """pymavlink finds no good frame in raw."""
    try:
        msgs = M.MAVLink(None).parse_buffer(raw) or []
    except Exception:  # pymavlink raises on a bad checksum unless robust_parsing
        return True
    return all(m.get_type() == "BAD_DATA" for m in msgs)


def corrupt_copy(raw, at=14):
    """raw with one payload byte flipped (its checksum no longer matches)."""
    b = bytearray(raw)
    b[at] ^= 0x01
    return bytes(b)


def corrupt(bin_):
    broker = Broker()
    cli = Client(broker, ["replies/#"], "cloud")
    pub = Client(broker, [], "pub")
    port = free_port()
    router = with_router(bin_, broker, lambda: "udpin:127.0.0.1:%d" % port)
    veh = Peer("vehicle", M, 1, 1, dest=port)
    if router is None:
        veh.close()
        broker.stop()
        return None
    gcs = M.MAVLink(None, srcSystem=255, srcComponent=190)

    def command_long(cmd, p1):
        return bytes(M.MAVLink_command_long_message(1, 1, cmd, 0, p1, 0, 0, 0, 0, 0, 0).pack(gcs))

    try:
        veh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        time.sleep(0.3)
        # On in: a corrupt frame, then a valid one on the same key (MQTT keeps their order).
        bad_in = corrupt_copy(command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 1))
        good_in = command_long(M.MAV_CMD_DO_SET_MODE, 1)
        check(pymavlink_refuses(bad_in), "pymavlink takes the flipped frame for a good one")
        pub.publish("%s/in" % PREFIX, bad_in)
        pub.publish("%s/in" % PREFIX, good_in)
        check(veh.wait_for(lambda f: f.raw == good_in, DEADLINE) is not None,
              "the valid frame published on in after the corrupt one never reached the vehicle")
        # On @cmd: a corrupt request is refused at once ...
        bad_cmd = corrupt_copy(command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 1), at=16)
        topic = request(cli, "%s/1/1/@cmd" % PREFIX, bad_cmd, "bad-crc")
        got = cli.wait(lambda t, p: t == topic, DEADLINE)
        check(got is not None and user_props(got[4]).get("error") == "bad_crc",
              "a corrupt request on @cmd: %r, expected error=bad_crc" % ((got and (got[1], user_props(got[4]))),))
        # ... and never resent: a valid request after it is resent until its timeout reply
        # (pymavlink's vehicle answers nothing), time in which the corrupt one would have been.
        good_cmd = command_long(M.MAV_CMD_DO_SET_MODE, 4)
        topic = request(cli, "%s/1/1/@cmd" % PREFIX, good_cmd, "good")
        got = cli.wait(lambda t, p: t == topic, DEADLINE)
        check(got is not None and user_props(got[4]).get("error") == "timeout",
              "the valid request's reply: %r, expected its timeout" % ((got and (got[1], user_props(got[4]))),))
        longs = [f for f in veh.frames() if f.type == "COMMAND_LONG"]
        arrived = [f for f in longs if f.msg.command == M.MAV_CMD_DO_SET_MODE and f.msg.param1 == 4]
        check(len(arrived) == 4, "the valid request reached the vehicle %d times, expected 4 (3 resends)" % len(arrived))
        leaked = [f for f in veh.got if f.raw in (bad_in, bad_cmd) or
                  (f.type == "COMMAND_LONG" and f.msg.command == M.MAV_CMD_COMPONENT_ARM_DISARM)]
        check(not leaked, "corrupt frames (or frames made of them) reached the vehicle: %r" % leaked)
        check(not veh.bad, "the vehicle got frames pymavlink refuses: %r" % veh.bad)
        stats = router.stop()
        bridges = (stats or {}).get("bridges") or [{}]
        check(bridges[0].get("bad_crc") == 2, "bridge counters %r: bad_crc 2 expected" % (bridges,))
        return ("a corrupt frame on in and a corrupt request on @cmd (error=bad_crc) never reached the vehicle, "
                "nor a resend; bad_crc %s" % bridges[0].get("bad_crc"))
    finally:
        veh.close()
        if router.running():
            router.stop()
        cli.close()
        pub.close()
        broker.stop()


def vehicle_links(stats):
    """The ground router's links that are vehicles of its bridge: their peers, "mqtt F/V"."""
    return [str(e.get("peer")) for e in (stats or {}).get("links", []) if "%s/" % FLEET in str(e.get("peer", ""))]


def vehicles(bin_):
    broker = Broker()
    fake = Client(broker, [], "fake-fleet")
    routers, peers = [], []
    try:
        vport, gport = free_port(), free_port()
        v, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % vport, mqtt_broker.Broker.url(broker, FLEET, "truck-1")])
        if v is None:
            return None
        routers.append(v)
        truck = Peer("truck-1", M, 1, 1, dest=vport)
        gcs = Peer("gcs", M, 255, 190, dest=gport)
        peers += [truck, gcs]
        truck.keep_alive(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        g, _ = start_router(bin_, lambda: [mqtt_broker.Broker.url(broker, FLEET, "*", "&max_vehicles=3"),
                                           "udpin:127.0.0.1:%d?name=gcs" % gport])
        if g is None:
            return None
        routers.append(g)
        gcs.send(heartbeat())
        # truck-1 is a link first: its retained online is there when the ground subscribes.
        first = gcs.wait_for(lambda f: f.type == "HEARTBEAT" and f.sysid == 1, DEADLINE)
        check(first is not None, "truck-1's HEARTBEAT never reached the ground station")
        t = time.monotonic()
        for n in range(20):
            vid = "fake-%d" % n
            fake.publish("mav/%s/%s/@alive" % (FLEET, vid), b"online")
            hb = M.MAVLink(None, srcSystem=100 + n, srcComponent=1)
            raw = bytes(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA).pack(hb))
            fake.publish("mav/%s/%s/%d/1/HEARTBEAT" % (FLEET, vid, 100 + n), raw)
        # The fleet's last message has been handled when its HEARTBEAT (or nothing) came.
        time.sleep(1.5)
        links = []
        deadline = time.monotonic() + DEADLINE
        while time.monotonic() < deadline:
            seen = g.stats(t)
            links = vehicle_links(seen[-1][1]) if seen else []
            refused = (((seen[-1][1] if seen else {}).get("bridges") or [{}])[0]).get("vehicles_refused", 0)
            if refused >= 36:  # 18 vehicles without a place, 2 messages each
                break
            time.sleep(0.2)
        check(0 < len(links) <= 3, "vehicle links on the ground router: %r, expected at most 3" % links)
        check(any(l.endswith("/truck-1") for l in links), "truck-1 lost its link: %r" % links)
        # truck-1 works both ways.
        f = truck.send(M.MAVLink_attitude_message(4242, 0.1, 0, 0, 0, 0, 0))
        got = gcs.wait_for(lambda fr: fr.type == "ATTITUDE" and fr.msg.time_boot_ms == 4242, DEADLINE)
        check(got is not None and got.raw == f.raw, "truck-1's ATTITUDE at the ground station: %r" % got)
        t2 = time.monotonic()
        gcs.send(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
        check(truck.wait_for(lambda fr: fr.type == "COMMAND_LONG", DEADLINE, since=t2) is not None,
              "the ground station's command never reached truck-1")
        # A placed fake vehicle goes offline: a new one takes its place.
        placed = [l.rsplit("/", 1)[-1] for l in links if not l.endswith("/truck-1")]
        t3 = time.monotonic()
        if placed:
            fake.publish("mav/%s/%s/@alive" % (FLEET, placed[0]), b"offline")
            time.sleep(0.3)
            fake.publish("mav/%s/fake-new/@alive" % FLEET, b"online")
        deadline = time.monotonic() + DEADLINE
        now_links = []
        while time.monotonic() < deadline:
            seen = g.stats(t3)
            now_links = vehicle_links(seen[-1][1]) if seen else now_links
            if any(l.endswith("/fake-new") for l in now_links):
                break
            time.sleep(0.2)
        check(placed and any(l.endswith("/fake-new") for l in now_links) and len(now_links) <= 3,
              "after %s went offline: links %r, expected fake-new among at most 3" % (placed[:1], now_links))
        stats = g.stop()
        # One warning for the refusals so far (one per 10 s at most), naming the link.
        name = mqtt_broker.Broker.url(broker, FLEET, "*").split("?")[0]
        warned = [l for _, l in g.err if "max_vehicles" in l]
        check(len(warned) == 1 and name in warned[0],
              "warnings about max_vehicles: %r, expected one naming %s" % (warned, name))
        bridges = (stats or {}).get("bridges") or [{}]
        check(bridges[0].get("vehicles_refused", 0) >= 18,
              "bridge counters %r: vehicles_refused >= 18 expected (20 announced, 2 places)" % (bridges,))
        return "%d vehicle links of 21 vehicles (max_vehicles=3), truck-1 works both ways, offline frees a place; " \
               "vehicles_refused %s" % (len(links), bridges[0].get("vehicles_refused"))
    finally:
        for p in peers:
            p.close()
        for r in routers:
            if r.running():
                r.stop()
        fake.close()
        broker.stop()


SCENARIOS = {"telemetry": telemetry, "inbound": inbound, "command": command, "alive": alive, "ground": ground,
             "tls": tls, "corrupt": corrupt, "vehicles": vehicles}


if __name__ == "__main__":
    scenario.main(SCENARIOS, __doc__)
