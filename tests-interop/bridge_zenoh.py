#!/usr/bin/env python3
"""`mavstack router` with a Zenoh fleet link (zenoh://HOST:PORT?fleet=F&vid=V, or zenoh:
as a peer), against eclipse-zenoh (PyPI) as the independent Zenoh peer: this script's own
session is the Zenoh router the link connects to (mode "router", on a free port), and also
subscribes, queries and watches liveliness; pymavlink 2.4.50 plays the vehicle's network and
packs and reads every frame.

Usage: bridge_zenoh.py SCENARIO --mavstack BIN

Topology: pymavlink peer (or `mavstack vehicle`) --udp--> router --zenoh--> this process.
Keys as docs/contracts/fleet-keys.md gives them. Exit 0 with "<scenario>: ... ok", or 1
with FAIL lines. Never skipped: without eclipse-zenoh it fails.

Scenarios:
  telemetry  a pymavlink vehicle sends MAVLink 2, MAVLink 1, signed MAVLink 2 frames and a frame
             of an id no dialect knows; a subscriber on mav/F/V/** gets each on
             mav/F/V/{sysid}/{compid}/{pymavlink's message name} (the number for the unknown
             id), byte for byte, signature and all
  inbound    frames put on mav/F/V/in (pymavlink-packed COMMAND_LONG, a MAVLink 1 HEARTBEAT, a
             signed frame) reach the vehicles' UDP sockets byte for byte, none put back
  command    `mavstack vehicle` behind the router: a Zenoh query on mav/F/V/1/1/@cmd with a
             COMMAND_LONG as its payload gets one reply, the vehicle's COMMAND_ACK frame
             (pymavlink decodes it); a query to a system nobody has seen gets the error reply
             `timeout` after the resends; a key that does not match the frame's target gets
             the error `target_mismatch: ...` at once
  alive      the liveliness token mav/F/V/@alive is there while the router runs (a late
             subscriber with history sees it), goes on SIGTERM, and goes on SIGKILL (the
             session's end)
  ground     bridge_interop.py's ground scenario over Zenoh: two vehicle routers whose vehicles
             are both system 1 and a ground router on vid=* (a liveliness subscriber with
             history and a subscriber on the fleet's frames): seen as systems 1 and 2, a
             command to 2 reaches the second vehicle as pymavlink's packing of it to 1
  restart    this script's Zenoh router closed for 2 s and opened again on the same port: the
             link's session reconnects by itself and frames reach the new subscriber
  peer       the link as an in-process Zenoh peer (zenoh:?...&listen=tcp/127.0.0.1:P) and this
             script's session a peer connected to it: frames reach the subscriber byte for
             byte, and a frame put on `in` reaches the vehicle
"""

import os
import signal
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import bridge_interop  # noqa: E402
from router_interop import KEY, M, V1, Peer, heartbeat, start_router  # noqa: E402
import scenario  # noqa: E402
from scenario import check, free_port  # noqa: E402

try:
    import zenoh
except ImportError as e:  # a missing peer is a failure, never a skip
    print("FAIL: eclipse-zenoh is not installed (%s); run scripts/setup-peers.sh" % e, file=sys.stderr)
    sys.exit(1)

FLEET, VID = "fleet1", "veh-7"
PREFIX = "mav/%s/%s" % (FLEET, VID)


class Session:
    """This script's Zenoh session: a router listening on a free loopback port (or a peer
    connecting to `connect`), recording every sample of its subscriptions."""

    def __init__(self, connect=None, port=None):
        conf = zenoh.Config()
        conf.insert_json5("scouting/multicast/enabled", "false")
        if connect:
            conf.insert_json5("mode", '"peer"')
            conf.insert_json5("connect/endpoints", '["%s"]' % connect)
            self.port = None
        else:
            self.port = port or free_port()
            conf.insert_json5("mode", '"router"')
            conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:%d"]' % self.port)
        self.s = zenoh.open(conf)
        self.got = []  # (key, payload, kind, monotonic time)
        self.lock = threading.Lock()
        self.decl = []

    def url(self, extra=""):
        return "zenoh://127.0.0.1:%d?fleet=%s&vid=%s%s" % (self.port, FLEET, VID, extra)

    def _record(self, sample):
        with self.lock:
            self.got.append((str(sample.key_expr), bytes(sample.payload.to_bytes()), sample.kind, time.monotonic()))

    def subscribe(self, key):
        self.decl.append(self.s.declare_subscriber(key, self._record))

    def watch_alive(self, key):
        self.decl.append(self.s.liveliness().declare_subscriber(key, self._record, history=True))

    def samples(self, pred=lambda k, p: True):
        with self.lock:
            return [g for g in self.got if pred(g[0], g[1])]

    def wait(self, pred, timeout=5.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            m = self.samples(pred)
            if m:
                return m[0]
            time.sleep(0.02)
        return None

    def close(self):
        for d in self.decl:
            d.undeclare()
        self.s.close()


def wait_subscribed(session, key, timeout=5.0):
    """Until the link's subscription to `key` reached this router (a put there is matched)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        pub = session.s.declare_publisher(key)
        matched = pub.matching_status.matching
        pub.undeclare()
        if matched:
            return True
        time.sleep(0.05)
    return False


def vehicle_router(bin_):
    """This script's Zenoh router subscribed to the vehicle's keys, and a `mavstack router`
    with a UDP link for the vehicle and the Zenoh link: (session, router or None, UDP port)."""
    z = Session()
    z.subscribe("%s/**" % PREFIX)
    port = free_port()
    router, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % port, z.url()])
    if router is None:
        z.close()
    return z, router, port


def telemetry(bin_):
    z, router, port = vehicle_router(bin_)
    if router is None:
        return None
    veh = Peer("vehicle", M, 1, 1, dest=port)
    signer = Peer("signed", M, 1, 2, dest=port, key=KEY, link_id=3)
    v1 = Peer("v1", V1, 2, 1, dest=port)
    try:
        check(wait_subscribed(z, "%s/in" % PREFIX), "the link never subscribed to %s/in" % PREFIX)
        sent = bridge_interop.send_telemetry(veh, signer, v1, PREFIX)
        for key, raw, _ in sent:
            got = z.samples(lambda k, p, raw=raw: p == raw)
            check(got, "%s: frame %s never reached the subscriber" % (key, raw.hex()))
            for k, *_ in got:
                check(k == key, "frame %s on %s, expected %s" % (raw.hex()[:40], k, key))
        signed = [p for k, p, *_ in z.samples() if len(p) > 12 and p[0] == 0xFD and p[2] & 1]
        check(signed and all(bridge_interop.mi_verify(p) for p in signed), "signed frames reached the subscriber and verify with the key")
        stats = router.stop()
        bridges = (stats or {}).get("bridges") or [{}]
        check(bridges[0].get("published", 0) >= len(sent) and bridges[0].get("connections") == 1,
              "the router's last stats line: bridge counters %r" % (bridges,))
        return "%d frames on their keys byte for byte (v1, v2, signed, unknown id), %d samples in all" % (
            len(sent), len(z.samples()))
    finally:
        for p in (veh, signer, v1):
            p.close()
        if router.running():
            router.stop()
        z.close()


def inbound(bin_):
    z = Session()
    z.subscribe("%s/**" % PREFIX)
    ports = (free_port(), free_port())
    router, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % ports[0],
                                            "udpin:127.0.0.1:%d?key=%s" % (ports[1], KEY.hex()), z.url()])
    if router is None:
        z.close()
        return None
    veh = Peer("vehicle", M, 1, 1, dest=ports[0])
    sveh = Peer("signed vehicle", M, 2, 1, dest=ports[1], key=KEY, link_id=4)
    plain, signed = bridge_interop.inbound_frames()
    try:
        check(wait_subscribed(z, "%s/in" % PREFIX), "the link never subscribed to %s/in" % PREFIX)
        veh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA), v1=True)
        sveh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        time.sleep(0.3)
        for raw in plain + signed:
            z.s.put("%s/in" % PREFIX, raw)
        want = [(veh, raw) for raw in plain] + [(sveh, raw) for raw in signed]
        bridge_interop.check_delivered(want)
        echoed = [k for k, p, *_ in z.samples() if p in plain + signed and not k.endswith("/in")]
        check(not echoed, "frames from Zenoh were put back on %s" % echoed)
        return "%d frames from mav/F/V/in reached the vehicles byte for byte (v2, v1, a signed one), none put back" % len(want)
    finally:
        veh.close()
        sveh.close()
        router.stop()
        z.close()


def query(z, key, raw, timeout=8.0):
    """A Zenoh query with `raw` as its payload: [(ok, payload bytes, attachment or None, seconds)]."""
    t0 = time.monotonic()
    out = []
    for r in z.s.get(key, payload=raw, timeout=timeout):
        if r.ok is not None:
            att = r.ok.attachment
            out.append((True, bytes(r.ok.payload.to_bytes()), att and bytes(att.to_bytes()), time.monotonic() - t0))
        else:
            out.append((False, bytes(r.err.payload.to_bytes()), None, time.monotonic() - t0))
    return out


def command(bin_):
    z = Session()
    vport = free_port()
    vehicle = subprocess.Popen([bin_, "vehicle", "udpout:127.0.0.1:%d" % vport], stdin=subprocess.DEVNULL,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    router, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % vport, z.url()])
    if router is None:
        vehicle.kill()
        z.close()
        return None
    gcs = M.MAVLink(None, srcSystem=255, srcComponent=190)
    summary = []
    try:
        check(wait_subscribed(z, "%s/in" % PREFIX), "the link never subscribed to %s/in" % PREFIX)
        time.sleep(1.5)  # the vehicle's first HEARTBEAT teaches the router its route
        arm = bytes(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs))
        replies = query(z, "%s/1/1/@cmd" % PREFIX, arm)
        check(len(replies) == 1 and replies[0][0], "one ok reply to the ARM query, got %r" % (replies,))
        if replies and replies[0][0]:
            msgs = M.MAVLink(None).parse_buffer(replies[0][1]) or []
            check(len(msgs) == 1 and msgs[0].get_type() == "COMMAND_ACK", "the reply is not one COMMAND_ACK frame: %s" %
                  replies[0][1].hex())
            if msgs and msgs[0].get_type() == "COMMAND_ACK":
                ack = msgs[0]
                check(ack.command == M.MAV_CMD_COMPONENT_ARM_DISARM and ack.result == M.MAV_RESULT_ACCEPTED,
                      "ACK command %d result %d, expected ARM_DISARM ACCEPTED" % (ack.command, ack.result))
                check(ack.get_srcSystem() == 1, "ACK from system %d" % ack.get_srcSystem())
                summary.append("ARM -> COMMAND_ACK ACCEPTED in %.0f ms" % (replies[0][3] * 1000))
        lost = bytes(M.MAVLink_command_long_message(9, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs))
        replies = query(z, "%s/9/1/@cmd" % PREFIX, lost)
        check(len(replies) == 1 and not replies[0][0] and replies[0][1] == b"timeout",
              "a command to nobody: one error reply b'timeout', got %r" % (replies,))
        if replies:
            check(1.5 <= replies[0][3] <= 4.0, "the timeout came after %.1f s (4 sends 0.5 s apart)" % replies[0][3])
            summary.append("no one -> timeout after %.1f s" % replies[0][3])
        replies = query(z, "%s/1/2/@cmd" % PREFIX, arm, timeout=3.0)
        check(len(replies) == 1 and not replies[0][0] and replies[0][1].startswith(b"target_mismatch"),
              "a key that does not match the target: %r" % (replies,))
        summary.append("mismatched key -> target_mismatch")
        return "; ".join(summary)
    finally:
        router.stop()
        vehicle.send_signal(signal.SIGINT)
        try:
            vehicle.wait(5)
        except subprocess.TimeoutExpired:
            vehicle.kill()
        z.close()


def alive(bin_):
    z = Session()
    key = "%s/@alive" % PREFIX
    try:
        router, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % free_port(), z.url()])
        if router is None:
            return None
        check(wait_subscribed(z, "%s/in" % PREFIX), "the link never subscribed")
        z.watch_alive(key)  # subscribed after the token was declared: history shows it
        on = z.wait(lambda k, p: k == key, 3)
        check(on is not None and on[2] == zenoh.SampleKind.PUT, "the liveliness token while running (history): %r" % (on,))
        router.stop()
        gone = None
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and gone is None:
            gone = next((g for g in z.samples() if g[0] == key and g[2] == zenoh.SampleKind.DELETE), None)
            time.sleep(0.05)
        check(gone is not None, "the token did not go within 5 s of SIGTERM")
        mark = len(z.samples())
        router2, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % free_port(), z.url()])
        if router2 is None:
            return None
        deadline = time.monotonic() + 5
        back = None
        while time.monotonic() < deadline and back is None:
            back = next((g for g in z.samples()[mark:] if g[0] == key and g[2] == zenoh.SampleKind.PUT), None)
            time.sleep(0.05)
        check(back is not None, "the second router's token never came")
        mark = len(z.samples())
        t0 = time.monotonic()
        router2.kill()
        dead = None
        while time.monotonic() < t0 + 15 and dead is None:
            dead = next((g for g in z.samples()[mark:] if g[0] == key and g[2] == zenoh.SampleKind.DELETE), None)
            time.sleep(0.05)
        check(dead is not None, "the token did not go within 15 s of SIGKILL")
        return "token while running -> gone on SIGTERM -> back -> gone %.1f s after SIGKILL" % (
            (dead[3] - t0) if dead else -1)
    finally:
        z.close()


def ground(bin_):
    z = Session()
    try:
        url = lambda vid: "zenoh://127.0.0.1:%d?fleet=%s&vid=%s" % (z.port, FLEET, vid)  # noqa: E731
        return bridge_interop.ground_through(bin_, url)
    finally:
        z.close()


def restart(bin_):
    z, router, port = vehicle_router(bin_)
    if router is None:
        return None
    veh = Peer("vehicle", M, 1, 1, dest=port)
    try:
        check(wait_subscribed(z, "%s/in" % PREFIX), "the link never subscribed")
        first = veh.send(M.MAVLink_attitude_message(1, 0, 0, 0, 0, 0, 0))
        check(z.wait(lambda k, p: p == first.raw, 3) is not None, "no frame before the restart")
        zport = z.port
        z.close()
        time.sleep(2.0)
        z = Session(port=zport)
        z.subscribe("%s/**" % PREFIX)
        back_at = time.monotonic()
        got = None
        n = 2
        while got is None and time.monotonic() < back_at + 10:
            f = veh.send(M.MAVLink_attitude_message(n, 0, 0, 0, 0, 0, 0))
            n += 1
            got = z.wait(lambda k, p, raw=f.raw: p == raw, 0.1)
        check(got is not None, "no frame within 10 s of the Zenoh router's restart")
        stats = router.stop()
        check(stats is not None, "the router's last stats line after the restart")
        return "Zenoh router stopped for 2 s: frames again %.2f s after it came back" % (
            (got[3] - back_at) if got else -1)
    finally:
        veh.close()
        if router.running():
            router.stop()
        z.close()


def peer(bin_):
    port, zport = free_port(), free_port()
    link = "zenoh:?fleet=%s&vid=%s&listen=tcp/127.0.0.1:%d" % (FLEET, VID, zport)
    router, _ = start_router(bin_, lambda: ["udpin:127.0.0.1:%d" % port, link])
    if router is None:
        return None
    z = Session(connect="tcp/127.0.0.1:%d" % zport)
    z.subscribe("%s/**" % PREFIX)
    veh = Peer("vehicle", M, 1, 1, dest=port)
    try:
        check(wait_subscribed(z, "%s/in" % PREFIX), "the peer link's subscription to in never reached this peer")
        time.sleep(0.3)  # our subscription reaches the link
        veh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        f = veh.send(M.MAVLink_attitude_message(1000, 0.1, -0.2, 0.3, 0.01, 0.02, 0.03))
        got = z.wait(lambda k, p: p == f.raw, 3)
        check(got is not None and got[0] == "%s/1/1/ATTITUDE" % PREFIX, "ATTITUDE through the peer link: %r" % (got,))
        gcs = M.MAVLink(None, srcSystem=255, srcComponent=190)
        raw = bytes(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(gcs))
        z.s.put("%s/in" % PREFIX, raw)
        arrived = veh.wait_for(lambda fr: fr.raw == raw, 3)
        check(arrived is not None, "a frame put on in through the peer link never reached the vehicle")
        return "zenoh: peer link: ATTITUDE on its key byte for byte, a frame on in reached the vehicle"
    finally:
        veh.close()
        router.stop()
        z.close()


SCENARIOS = {"telemetry": telemetry, "inbound": inbound, "command": command, "alive": alive, "ground": ground,
             "restart": restart, "peer": peer}


if __name__ == "__main__":
    scenario.main(SCENARIOS, __doc__)
