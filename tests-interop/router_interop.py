#!/usr/bin/env python3
"""`mavstack router` between pymavlink 2.4.50 peers over loopback UDP: routing, version
conversion, signing boundaries, stats.

Usage: router_interop.py SCENARIO --mavstack BIN

Each scenario starts its own router (`mavstack router LINK ... --stats 1`, free ports, waits
for `mavstack router: ready` on stderr, always stopped at the end: SIGTERM (SIGINT in
v2_link), exit 0 expected, the last stats object read) and plays every peer with pymavlink.
The peers are raw UDP sockets driven by pymavlink MAVLink objects, so the exact bytes sent and
received are known (ground stations send a HEARTBEAT a second where a scenario waits long:
the router forgets a udpin client after about 10 s of silence):
MAVLink 2 peers use the dialect mavgen generates from our definitions (mavstack_dialect.py:
ardupilotmega + PROTOCOL_VERSION), MAVLink 1-only peers pymavlink's own v1.0 module
(`pymavlink.dialects.v10.ardupilotmega`, WIRE_PROTOCOL_VERSION 1.0: it packs nothing but
MAVLink 1 with base fields). Every expectation comes from pymavlink: a converted frame must
equal pymavlink's packing of the sender's values with the sender's sysid/compid/seq in the
target framing (and decode, with pymavlink, to the same field values); signatures are
verified by pymavlink's signing with the key; framing is read off the raw bytes (0xFE = MAVLink
1, 0xFD = MAVLink 2, incompat flag 0x01 = signed). Exit 0 with "<scenario>: ... ok", or 1 with
FAIL lines.

Scenarios:
  v1_peer         a MAVLink 1-only peer on a version=1 link, a MAVLink 2 vehicle on an auto link,
                  a silent observer on an auto udpout link: the v1 peer gets only 0xFE frames,
                  each pymavlink's v1 packing of the vehicle's base fields (same sysid/compid/
                  seq; SYS_STATUS and COMMAND_ACK extensions dropped; COMMAND_ACK routed by its
                  extension target_system), ids > 255 never; the vehicle gets the v1 peer's
                  frames converted to MAVLink 2 (its link switched on its first MAVLink 2
                  frame); the observer, whose peer never sent MAVLink 2, gets both byte for
                  byte; stats: versions 1/2/auto, converted > 0 and cannot_convert = 2 on the
                  v1 link
  v2_link         a MAVLink 1 sender on an auto link, a receiver on a version=2 udpout link:
                  pymavlink's MAVLink 2 packing (truncated, down to a 1-byte payload) of the
                  sender's values, same header; an auto observer gets the v1 bytes unchanged;
                  stopped with SIGINT (exit 0, a last stats object)
  signing         peers S (key=K&trusted=false&link_id=7) and S2 (key=K, link_id=8), plain P,
                  trusted T: S and S2 get only frames that pymavlink verifies with K (S2's and
                  S's byte for byte, T's signed by the router with the link's own link id and
                  rising timestamps), nothing of P (untrusted_to_signed); P and T get S's frames
                  without signature (flag 0, 12-byte trailer, same payload and header); S's
                  unsigned MAVLink 2 and MAVLink 1 frames, a frame signed with another key and
                  two replays are dropped (unsigned, bad_signature, replay); the key appears in
                  no output
  targeting       A (1/1), B (255/190), C (254/190) on three links: COMMAND_LONG to 1/1 and to
                  1/99 (component not seen) reach only A; to 77/1 nobody (unknown_target);
                  COMMAND_ACK with target_system 255 in its extension only B; A's broadcasts B
                  and C, never A; after C echoes one of A's HEARTBEATs byte for byte
                  (mavlink-router #452) B's command to 1/1 still reaches A
  handshake       `mavstack vehicle` on one link; a pymavlink ground station on a plain link
                  asks REQUEST_MESSAGE(300) in MAVLink 2: COMMAND_ACK ACCEPTED + PROTOCOL_VERSION,
                  every frame it gets MAVLink 2; the same from a version=1 link: only MAVLink 1
                  frames, no PROTOCOL_VERSION (cannot_convert); `mavstack probe` through a plain
                  link: handshake.result protocol_version, through a version=1 link: not
  own_heartbeat   --heartbeat --sysid 42: the router's own HEARTBEAT (an onboard controller's)
                  on a version=1 link only as MAVLink 1, on an auto link as MAVLink 1 until its
                  peer sends MAVLink 2 and as MAVLink 2 after, on a key= link signed with the
                  link's id so that pymavlink verifies it; each link its own consecutive
                  sequence numbers
  stats_and_exit  --stats 1: a JSON object about every second, an entry per link with its name
                  and version (1, 2, signed, auto; auto -> 2 when its peer sends MAVLink 2),
                  rx_frames/tx_frames equal to what the peers sent/received; SIGTERM -> exit 0
                  with a last stats object; the key never printed
"""

import hashlib
import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import mavstack_dialect  # noqa: E402

M = mavstack_dialect.install()  # MAVLink 2 (wire protocol 2.0), ardupilotmega + PROTOCOL_VERSION
import mavinterop as mi  # noqa: E402
from pymavlink.dialects.v10 import ardupilotmega as V1  # noqa: E402  (wire protocol 1.0)

V1_MAGIC, V2_MAGIC = 0xFE, 0xFD
KEY = hashlib.sha256(b"mavstack router interop").digest()
OTHER_KEY = hashlib.sha256(b"somebody else's key").digest()
REQUEST_MESSAGE = M.MAV_CMD_REQUEST_MESSAGE  # 512
PROTOCOL_VERSION_ID = M.MAVLINK_MSG_ID_PROTOCOL_VERSION  # 300
SETTLE = 0.4  # s for frames in flight through the router to arrive

import scenario  # noqa: E402
from scenario import check, fail, failures, free_port, signing_now  # noqa: E402


# --------------------------------------------------------------------------------------------
# Frames as pymavlink sees them


class Frame:
    """One frame off the wire (or put on it): raw bytes, header, pymavlink's decoding."""

    def __init__(self, raw, msg, t=None):
        self.t = time.monotonic() if t is None else t
        self.raw = bytes(raw)
        self.msg = msg
        self.type = msg.get_type() if msg is not None else "NONE"
        h = mi.frame_header(self.raw)
        self.version = h["version"]
        self.seq, self.sysid, self.compid, self.msgid = h["seq"], h["sysid"], h["compid"], h["msgid"]
        self.flags = h.get("incompat_flags", 0)
        self.signed = bool(self.flags & mi.IFLAG_SIGNED)
        hl = mi.V2_HEADER if self.version == 2 else mi.V1_HEADER
        self.payload = self.raw[hl:hl + self.raw[1]]
        self.link_id, self.timestamp = mi.signature_info(self.raw) if self.signed else (None, None)

    @property
    def src(self):
        return (self.sysid, self.compid)

    @property
    def key(self):
        """What identifies a frame across conversions: source, sequence, message id."""
        return (self.sysid, self.compid, self.seq, self.msgid)

    def tag(self):
        """The text of a STATUSTEXT, else None."""
        if self.type == "STATUSTEXT":
            return self.msg.text
        return None

    def __repr__(self):
        what = self.type
        if self.tag() is not None:
            what += "(%r)" % self.tag()
        h = self.raw.hex()
        return "%s v%d%s %d/%d seq %d [%s]" % (what, self.version, " signed" if self.signed else "", self.sysid,
                                               self.compid, self.seq, h if len(h) <= 120 else h[:120] + "...")


def parser(mod, key=None, rejected=None):
    mav = mod.MAVLink(None)
    mav.robust_parsing = True
    if key is not None:
        s = mav.signing
        s.secret_key = key
        s.timestamp = signing_now()

        def refuse(_mav, msg_id):
            if rejected is not None:
                rejected.append(msg_id)
            return False

        s.allow_unsigned_callback = refuse
    return mav


def decode(mod, raw):
    """pymavlink's decoding of one frame (no key: signatures not checked), or None."""
    msgs = parser(mod).parse_buffer(bytes(raw)) or []
    if len(msgs) != 1 or msgs[0].get_type() == "BAD_DATA":
        return None
    return msgs[0]


def zero_of(cls, name):
    lay = mi.layout(cls)
    f = lay.by_name[name]
    if f.array_len:
        return b"" if f.type == "char" else [0] * f.array_len
    return 0


def value_of(msg, name):
    raw = getattr(msg, "_%s_raw" % name, None)
    return raw if raw is not None else getattr(msg, name)


def repack(mod, msg, header):
    """pymavlink's packing, with module mod (v10: MAVLink 1 base fields; M: MAVLink 2,
    truncated), of msg's field values under header (sysid, compid, seq). Fields mod's class
    has and msg lacks are zero."""
    cls = mod.mavlink_map[msg.get_msgId()]
    have = set(msg.get_fieldnames())
    args = [value_of(msg, n) if n in have else zero_of(cls, n) for n in cls.fieldnames]
    m = cls(*args)
    sysid, compid, seq = header
    mav = mod.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.seq = seq
    return bytes(m.pack(mav))


def same_fields(got, want, names=None):
    """The fields (names, default: all of want's) whose decoded values differ."""
    names = want.get_fieldnames() if names is None else names
    return [(n, getattr(got, n, "<missing>"), getattr(want, n)) for n in names if getattr(got, n, "<missing>") != getattr(want, n)]


# --------------------------------------------------------------------------------------------
# Peers: a UDP socket, a pymavlink MAVLink object to pack with, one to parse with


class Peer:
    """A pymavlink peer on a raw UDP socket.

    dest: the router's udpin port it sends to (None: it waits on its own bound port for a
    router udpout link and answers the address the router sent from). mod: M (MAVLink 2) or
    V1 (MAVLink 1 only). key: pymavlink signing on both MAVLink objects (outgoing signed,
    incoming verified, unsigned refused).
    """

    def __init__(self, name, mod, sysid, compid, dest=None, key=None, link_id=0):
        self.name, self.mod = name, mod
        self.sysid, self.compid = sysid, compid
        self.key = key
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.addr = ("127.0.0.1", dest) if dest else None
        self.tx = mod.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.rejected = []  # ids of frames pymavlink's signing refused (unsigned or not verified)
        self.rx = parser(mod, key, self.rejected)
        if key is not None:
            s = self.tx.signing
            s.secret_key, s.link_id, s.sign_outgoing, s.timestamp = key, link_id, True, signing_now()
        self.sent = []  # Frame of every frame sent
        self.got = []  # Frame of every frame received (msg None or BAD_DATA when pymavlink refused it)
        self.bad = []  # (raw, reason) pymavlink refused
        self.datagrams = []
        self.lock = threading.Lock()
        self.send_lock = threading.Lock()
        self.stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    @property
    def port(self):
        return self.sock.getsockname()[1]

    def _run(self):
        while not self.stop:
            try:
                r, _, _ = select.select([self.sock], [], [], 0.05)
            except (OSError, ValueError):
                return
            if not r:
                continue
            try:
                data, addr = self.sock.recvfrom(65536)
            except OSError:
                continue
            t = time.monotonic()
            if self.addr is None:
                self.addr = addr
            frames, err = mi.split_frames(data)
            with self.lock:
                self.datagrams.append((t, data))
                if err:
                    fail("%s: a datagram from the router is not a sequence of frames (%s): %s" % (self.name, err, data.hex()))
                for _, raw in frames:
                    msgs = self.rx.parse_buffer(raw) or []
                    msg = msgs[0] if len(msgs) == 1 else None
                    if msg is None or msg.get_type() == "BAD_DATA":
                        self.bad.append((raw, getattr(msg, "reason", "no message")))
                        msg = None
                    self.got.append(Frame(raw, msg, t))

    def pack(self, msg, v1=False, sign=True, key=None, timestamp=None):
        """The frame this peer would send (its sequence number used). sign=False: unsigned
        even on a signing peer; key: signed with that key (and timestamp, if given) instead
        of the peer's, the peer's own signing timestamp left as it was."""
        s = self.tx.signing
        saved = (s.sign_outgoing, s.secret_key, s.timestamp)
        if not sign:
            s.sign_outgoing = False
        if key is not None:
            s.secret_key, s.sign_outgoing = key, True
            s.timestamp = timestamp if timestamp is not None else (s.timestamp or signing_now())
        try:
            raw = bytes(msg.pack(self.tx, force_mavlink1=v1))
        finally:
            s.sign_outgoing, s.secret_key = saved[:2]
            if key is not None:
                s.timestamp = saved[2]
        self.tx.seq = (self.tx.seq + 1) % 256
        return raw

    def send(self, msg, v1=False, sign=True, key=None, timestamp=None, pause=0.03):
        with self.send_lock:
            raw = self.pack(msg, v1=v1, sign=sign, key=key, timestamp=timestamp)
            self.write(raw, pause=0)
            f = Frame(raw, decode(self.mod, raw))
            self.sent.append(f)
        time.sleep(pause)
        return f

    def keep_alive(self, msg, v1=False, period=1.0):
        """Sends msg (a HEARTBEAT) every period s from now on, as a ground station does."""
        def run():
            while not self.stop:
                try:
                    self.send(msg, v1=v1, pause=0)
                except OSError:  # closed under it
                    return
                deadline = time.monotonic() + period
                while not self.stop and time.monotonic() < deadline:
                    time.sleep(0.05)
        threading.Thread(target=run, daemon=True).start()

    def write(self, raw, pause=0.03):
        if self.addr is None:
            fail("%s: no address to send to (the router never wrote to this peer)" % self.name)
            return
        self.sock.sendto(raw, self.addr)
        time.sleep(pause)

    def frames(self, since=0.0):
        with self.lock:
            return [f for f in self.got if f.t >= since]

    def from_(self, src, since=0.0):
        return [f for f in self.frames(since) if f.src == src]

    def wait_for(self, pred, timeout, since=0.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for f in self.frames(since):
                if f.msg is not None and pred(f):
                    return f
            time.sleep(0.02)
        return None

    def close(self):
        self.stop = True
        self.thread.join(1)
        self.sock.close()


def heartbeat(mav_type=M.MAV_TYPE_GCS, autopilot=M.MAV_AUTOPILOT_INVALID, custom_mode=0, mod=M):
    return mod.MAVLink_heartbeat_message(mav_type, autopilot, 0, custom_mode, M.MAV_STATE_ACTIVE, 3)


def statustext(text, mod=M):
    if mod is V1:
        return V1.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, text.encode())
    return M.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, text.encode(), 0, 0)


def cmd_long(target, command=M.MAV_CMD_DO_SET_MODE, p1=1.0, p2=0.0):
    return M.MAVLink_command_long_message(target[0], target[1], command, 0, p1, p2, 0, 0, 0, 0, 0)


def settle(seconds=SETTLE):
    time.sleep(seconds)


def arrived(peer, frame, what, timeout=3.0):
    """Waits until peer received frame (the same source, sequence and id, in any framing): the
    router has processed it, and what its sender's link learned from it."""
    got = peer.wait_for(lambda f: f.key == frame.key, timeout) or next((f for f in peer.frames() if f.key == frame.key), None)
    return check(got is not None, "%s: %s never reached %s within %.0f s" % (what, frame, peer.name, timeout))


# --------------------------------------------------------------------------------------------
# The router


class Router:
    """`mavstack router LINK ... --stats 1`: stdout (stats JSON lines) and stderr read by threads."""

    def __init__(self, bin_, links, extra=()):
        self.argv = [bin_, "router", *links, "--stats", "1", *extra]
        self.proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.out, self.err = [], []  # (monotonic time, line)
        self.threads = [threading.Thread(target=self._read, args=(self.proc.stdout, self.out), daemon=True),
                        threading.Thread(target=self._read, args=(self.proc.stderr, self.err), daemon=True)]
        for t in self.threads:
            t.start()
        self.stopped_at = None
        self.rc = None

    @staticmethod
    def _read(pipe, into):
        for line in iter(pipe.readline, b""):
            into.append((time.monotonic(), line.decode("utf-8", "replace").rstrip("\n")))

    def running(self):
        return self.proc.poll() is None

    def stderr(self, n=30):
        return "\n".join(l for _, l in self.err[-n:])

    def stdout(self):
        return "\n".join(l for _, l in self.out)

    def wait_ready(self, timeout=10.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(l.strip() == "mavstack router: ready" for _, l in self.err):
                return True
            if not self.running():
                time.sleep(0.1)  # the readers catch up with the last lines
                return False
            time.sleep(0.02)
        return False

    def stats(self, since=0.0):
        """Every stats object printed (after since), as (time, object); a line that is not a JSON
        object is a failure."""
        out = []
        for t, line in list(self.out):
            if t < since or not line.strip():
                continue
            try:
                obj = json.loads(line)
            except ValueError as e:
                fail("router stdout line is not JSON (%s): %r" % (e, line))
                continue
            if not isinstance(obj, dict):
                fail("router stdout line is not a JSON object: %r" % line)
                continue
            out.append((t, obj))
        return out

    def stop(self, sig=signal.SIGTERM):
        """Stops it as a user does: exit 0 expected. Returns the last stats object printed
        after the signal (None if none)."""
        if not self.running():
            fail("router exited by itself (%s) before it was stopped; stderr:\n%s" % (self.proc.returncode, self.stderr()))
            return None
        self.stopped_at = time.monotonic()
        self.proc.send_signal(sig)
        try:
            self.rc = self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.kill()
            fail("router did not exit within 5 s of %s" % signal.Signals(sig).name)
            return None
        for t in self.threads:
            t.join(2)
        check(self.rc == 0, "router exited %s on %s, expected 0; stderr:\n%s" % (self.rc, signal.Signals(sig).name, self.stderr()))
        after = self.stats(self.stopped_at)
        check(after, "router printed no stats object after %s (a last one is expected); stdout tail: %r" % (
            signal.Signals(sig).name, self.stdout()[-500:]))
        return after[-1][1] if after else None

    def kill(self):
        if self.running():
            self.proc.kill()
            self.proc.wait()


def start_router(bin_, make_links, extra=(), attempts=3):
    """Starts a router on links make_links() builds (fresh free ports each attempt); returns
    (router, links) once it printed its ready line, or (None, links) after a failure."""
    for attempt in range(attempts):
        links = make_links()
        r = Router(bin_, links, extra)
        if r.wait_ready():
            return r, links
        r.kill()
        if attempt + 1 < attempts and any("in use" in l.lower() for _, l in r.err):
            continue  # a port taken between free_port() and the router's bind: new ports
        fail("router did not print 'mavstack router: ready' within 10 s (%s); argv %s; stderr:\n%s" % (
            "running" if r.running() else "exited %s" % r.proc.returncode, r.argv, r.stderr()))
        return None, links
    return None, links


def link_entries(stats, name):
    """The stats entries of link `name`: the link itself and, for a udpin server, its clients
    (named NAME or NAME followed by the client's address)."""
    if not stats:
        return []
    return [e for e in stats.get("links", []) if isinstance(e, dict) and str(e.get("name", "")).startswith(name)]


def total(stats, name, field):
    return sum(int(e.get(field, 0) or 0) for e in link_entries(stats, name))


def dropped(stats, name, reason):
    return sum(int((e.get("dropped") or {}).get(reason, 0) or 0) for e in link_entries(stats, name))


def versions(stats, name):
    return sorted({e.get("version") for e in link_entries(stats, name)}, key=str)


def brief(stats):
    return json.dumps(stats, sort_keys=True) if stats is not None else "None"


def check_no_key(router, what):
    text = router.stdout() + "\n" + "\n".join(l for _, l in router.err)
    check(KEY.hex() not in text.lower(), "%s: the signing key appears in the router's output" % what)


def check_versions(stats, name, want, what):
    got = versions(stats, name)
    check(got == [want], "%s: link %s has stats version %s, expected %r (stats: %s)" % (what, name, got, want, brief(stats)))


# --------------------------------------------------------------------------------------------
# Scenarios


def v1_peer(bin_):
    obs = Peer("observer", M, 200, 1)  # router udpout target: never sends

    ports = []

    def links():
        ports[:] = [free_port(), free_port()]
        return ["udpin:127.0.0.1:%d?version=1&name=legacy" % ports[0],
                "udpin:127.0.0.1:%d?name=vehicle" % ports[1],
                "udpout:127.0.0.1:%d?name=observer" % obs.port]

    router, _ = start_router(bin_, links)
    if router is None:
        obs.close()
        return None
    leg = Peer("legacy", V1, 255, 190, dest=ports[0])
    veh = Peer("vehicle", M, 1, 1, dest=ports[1])
    try:
        # 1. The v1 peer first (the vehicle is not known yet): only the observer gets it.
        l_hb1 = leg.send(heartbeat(mod=V1))
        check(l_hb1.version == 1, "the v1.0 pymavlink module packed a MAVLink %d frame" % l_hb1.version)
        arrived(obs, l_hb1, "the v1 peer's first HEARTBEAT")
        # 2. The vehicle in MAVLink 2: its link is MAVLink 2 from this frame on.
        v_sent = [veh.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 5))]
        arrived(leg, v_sent[0], "the vehicle's first HEARTBEAT")
        # 3. The v1 peer again: the vehicle gets it converted to MAVLink 2.
        l_sent = [l_hb1, leg.send(heartbeat(mod=V1)), leg.send(statustext("legacy says hi", V1))]
        settle(0.2)
        v_sent += [
            veh.send(M.MAVLink_attitude_message(123456, 0.25, -0.5, 1.5, 0.01, -0.02, 0.03)),
            # SYS_STATUS with all three extension fields non-zero: a MAVLink 1 frame has none of them.
            veh.send(M.MAVLink_sys_status_message(0x20003F, 0x20002F, 0x20000F, 500, 12600, 1500, 87, 10, 3, 1, 2, 3, 4,
                                                  0x1, 0x1, 0x1)),
            # COMMAND_ACK to the v1 peer: its target is in the extension fields (routing reads
            # them; the MAVLink 1 frame has only command and result).
            veh.send(M.MAVLink_command_ack_message(M.MAV_CMD_COMPONENT_ARM_DISARM, M.MAV_RESULT_ACCEPTED, 100, 7, 255, 190)),
            # ids > 255: no MAVLink 1 framing can carry them.
            veh.send(M.MAVLink_protocol_version_message(200, 100, 200, [1] * 8, [2] * 8)),
            veh.send(M.MAVLink_uavcan_node_status_message(99, 1000, 0, 0, 0, 0x1234)),
            veh.send(statustext("vehicle status")),
        ]
        settle()
        stats = router.stop()

        # --- the v1 peer: MAVLink 1 only, pymavlink's v1 packing of the vehicle's base fields
        got = leg.frames()
        check(got, "v1 peer: received nothing")
        not_v1 = [f for f in got if f.version != 1]
        check(not not_v1, "v1 peer on a version=1 link received non-MAVLink 1 frames: %s" % not_v1[:5])
        by_key = {f.key: f for f in got if f.version == 1}
        ids_over_255 = [f for f in v_sent if f.msgid > 255]
        for s in v_sent:
            r = by_key.get(s.key)
            if s.msgid > 255:
                there = [f for f in got if f.msgid == s.msgid]
                check(not there, "v1 peer: %s (id %d > 255) arrived: %s" % (s.type, s.msgid, there))
                continue
            if not check(r is not None, "v1 peer: the vehicle's %s (seq %d) never arrived as MAVLink 1 (got %s)" % (s.type, s.seq, got[:8])):
                continue
            want = repack(V1, s.msg, (s.sysid, s.compid, s.seq))
            check(r.raw == want, "v1 peer: %s converted to %s, pymavlink's MAVLink 1 packing (base fields, same "
                  "sysid/compid/seq) is %s" % (s.type, r.raw.hex(), want.hex()))
            base = V1.mavlink_map[s.msgid].fieldnames
            if check(r.msg is not None, "v1 peer: pymavlink's v1 parser refused %r" % r):
                diff = same_fields(r.msg, s.msg, base)
                check(not diff, "v1 peer: %s decodes to other base-field values (field, got, sent): %s" % (s.type, diff))
            check(len(r.payload) == mi.layout(type(s.msg)).base_len,
                  "v1 peer: %s payload %d bytes, the base fields are %d" % (s.type, len(r.payload), mi.layout(type(s.msg)).base_len))
        from_veh = [f for f in got if f.src == (1, 1)]
        check(len(from_veh) == len(v_sent) - len(ids_over_255),
              "v1 peer: %d frames from the vehicle, expected %d (each once): %s" % (
                  len(from_veh), len(v_sent) - len(ids_over_255), from_veh[:8]))
        check(not [f for f in got if f.src == leg.sent[0].src], "v1 peer: got its own frames back")

        # --- the vehicle: the v1 peer's frames after its own first MAVLink 2 frame, as MAVLink 2
        vgot = veh.frames()
        check(not [f for f in vgot if f.version != 2], "vehicle (its link switched by its MAVLink 2 frames) received "
              "MAVLink 1 frames: %s" % [f for f in vgot if f.version != 2][:5])
        check(not [f for f in vgot if f.key == l_hb1.key],
              "vehicle: got the v1 peer's first HEARTBEAT, sent before the vehicle was seen")
        for s in l_sent[1:]:
            r = next((f for f in vgot if f.key == s.key), None)
            if not check(r is not None, "vehicle: the v1 peer's %s (seq %d) never arrived (got %s)" % (s.type, s.seq, vgot[:8])):
                continue
            want = repack(M, s.msg, (s.sysid, s.compid, s.seq))
            check(r.raw == want, "vehicle: the v1 peer's %s converted to %s, pymavlink's MAVLink 2 packing is %s" % (
                s.type, r.raw.hex(), want.hex()))
            if r.msg is not None:
                diff = same_fields(r.msg, s.msg)
                check(not diff, "vehicle: %s decodes to other values (field, got, sent): %s" % (s.type, diff))
        check(not [f for f in vgot if f.src == (1, 1)], "vehicle: got its own frames back")

        # --- the observer: an auto link whose peer never sent MAVLink 2 gets frames as they came
        ogot = obs.frames()
        for s in l_sent + v_sent:
            rs = [f for f in ogot if f.key == s.key]
            if s.type == "COMMAND_ACK":
                check(not rs, "observer: got the COMMAND_ACK targeted (extension target_system 255) at the v1 peer: %s" % rs)
                continue
            if check(len(rs) == 1, "observer: %d copies of %s from %d/%d seq %d, expected 1" % (len(rs), s.type, s.sysid, s.compid, s.seq)):
                check(rs[0].raw == s.raw, "observer (auto, peer never sent MAVLink 2): %s not byte for byte: sent %s, got %s" % (
                    s.type, s.raw.hex(), rs[0].raw.hex()))

        # --- stats
        if check(stats is not None, "no final stats"):
            check_versions(stats, "legacy", "1", "final stats")
            check_versions(stats, "vehicle", "2", "final stats (auto link after its peer's MAVLink 2 frames)")
            check_versions(stats, "observer", "auto", "final stats (auto link, peer silent)")
            conv = total(stats, "legacy", "converted")
            check(conv > 0, "stats: converted %d on the version=1 link, expected > 0: %s" % (conv, brief(stats)))
            cc = dropped(stats, "legacy", "cannot_convert")
            check(cc == len(ids_over_255), "stats: cannot_convert %d on the version=1 link, expected %d (the ids > 255 "
                  "the vehicle broadcast): %s" % (cc, len(ids_over_255), brief(stats)))
            rx = total(stats, "legacy", "rx_frames")
            check(rx == len(l_sent), "stats: rx_frames %d on the version=1 link, the peer sent %d" % (rx, len(l_sent)))
            tx = total(stats, "legacy", "tx_frames")
            check(tx == len(got), "stats: tx_frames %d on the version=1 link, the peer received %d" % (tx, len(got)))
        summary = "v1 peer got %d MAVLink 1 frames (pymavlink's packing), %d ids > 255 withheld; vehicle got %d MAVLink 2; " \
                  "legacy stats converted=%s dropped=%s" % (
                      len(got), len(ids_over_255), len(vgot), total(stats, "legacy", "converted"),
                      [e.get("dropped") for e in link_entries(stats, "legacy")])
    finally:
        router.kill()
        for p in (leg, veh, obs):
            p.close()
    return summary


def v2_link(bin_):
    rcv = Peer("receiver", M, 201, 1)  # version=2 udpout target
    watch = Peer("watcher", M, 202, 1)  # auto udpout target, silent

    ports = []

    def links():
        ports[:] = [free_port()]
        return ["udpin:127.0.0.1:%d?name=oldpeer" % ports[0],
                "udpout:127.0.0.1:%d?version=2&name=newpeer" % rcv.port,
                "udpout:127.0.0.1:%d?name=watcher" % watch.port]

    router, _ = start_router(bin_, links)
    if router is None:
        rcv.close()
        watch.close()
        return None
    old = Peer("oldpeer", V1, 40, 2, dest=ports[0])
    try:
        sent = [
            old.send(heartbeat(M.MAV_TYPE_GROUND_ROVER, M.MAV_AUTOPILOT_GENERIC, 0x1000, mod=V1)),
            # trailing zero fields: truncated in MAVLink 2
            old.send(V1.MAVLink_attitude_message(777, 0.5, -0.25, 2.0, 0.125, 0.0, 0.0)),
            # every byte zero: a 1-byte MAVLink 2 payload
            old.send(V1.MAVLink_attitude_message(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)),
            old.send(V1.MAVLink_sys_status_message(7, 7, 3, 250, 11100, -1, 50, 0, 0, 0, 0, 0, 0)),
            # a broadcast command whose last wire fields (targets, confirmation) are zero
            old.send(V1.MAVLink_command_long_message(0, 0, M.MAV_CMD_DO_SET_MODE, 0, 1.0, 4.0, 0, 0, 0, 0, 0)),
            old.send(statustext("short", V1)),
            old.send(V1.MAVLink_param_value_message(b"RTL_ALT", 1500.0, 9, 100, 5)),
        ]
        check(all(s.version == 1 for s in sent), "the v1.0 pymavlink module packed MAVLink 2 frames")
        settle()
        stats = router.stop(signal.SIGINT)
        got = rcv.frames()
        check(not [f for f in got if f.version != 2], "receiver on a version=2 link got non-MAVLink 2 frames: %s" % (
            [f for f in got if f.version != 2][:5]))
        truncated = 0
        for s in sent:
            rs = [f for f in got if f.key == s.key]
            if not check(len(rs) == 1, "receiver: %d copies of %s seq %d, expected 1 (got %s)" % (len(rs), s.type, s.seq, got[:8])):
                continue
            r = rs[0]
            want = repack(M, s.msg, (s.sysid, s.compid, s.seq))
            check(r.raw == want, "receiver: %s converted to %s, pymavlink's MAVLink 2 packing (truncated, same "
                  "sysid/compid/seq) is %s" % (s.type, r.raw.hex(), want.hex()))
            check(len(r.payload) == 1 or r.payload[-1] != 0, "receiver: %s payload ends in a zero byte: %s" % (s.type, r.payload.hex()))
            check(not r.signed and r.flags == 0, "receiver: %s has incompat flags 0x%02x" % (s.type, r.flags))
            if check(r.msg is not None, "receiver: pymavlink refused %r" % r):
                diff = same_fields(r.msg, s.msg)
                check(not diff, "receiver: %s decodes to other values (field, got, sent): %s" % (s.type, diff))
            truncated += len(r.payload) < len(s.payload)
        check(truncated >= 1, "receiver: no frame was shorter than its MAVLink 1 payload")
        zero = next((f for f in got if f.key == sent[2].key), None)
        if zero is not None:
            check(len(zero.payload) == 1, "receiver: an all-zero ATTITUDE has a %d-byte payload, expected 1" % len(zero.payload))
        wgot = watch.frames()
        for s in sent:
            rs = [f for f in wgot if f.key == s.key]
            if check(len(rs) == 1, "watcher (auto): %d copies of %s, expected 1" % (len(rs), s.type)):
                check(rs[0].raw == s.raw, "watcher (auto, peer silent): %s not byte for byte: sent %s, got %s" % (
                    s.type, s.raw.hex(), rs[0].raw.hex()))
        if check(stats is not None, "no final stats"):
            check_versions(stats, "newpeer", "2", "final stats")
            check_versions(stats, "oldpeer", "auto", "final stats (its peer sent only MAVLink 1)")
            check_versions(stats, "watcher", "auto", "final stats")
            check(total(stats, "newpeer", "converted") > 0, "stats: converted 0 on the version=2 link: %s" % brief(stats))
            check(total(stats, "newpeer", "tx_frames") == len(got), "stats: tx_frames %d on the version=2 link, the peer "
                  "received %d" % (total(stats, "newpeer", "tx_frames"), len(got)))
        summary = "%d MAVLink 1 frames arrived as pymavlink's MAVLink 2 packing (%d truncated), byte for byte on auto" % (
            len(got), truncated)
    finally:
        router.kill()
        for p in (old, rcv, watch):
            p.close()
    return summary


def signing(bin_):
    khex = KEY.hex()
    ports = []

    def links():
        ports[:] = [free_port() for _ in range(4)]
        return ["udpin:127.0.0.1:%d?key=%s&trusted=false&link_id=7&name=signed1" % (ports[0], khex),
                "udpin:127.0.0.1:%d?key=%s&link_id=8&name=signed2" % (ports[1], khex),
                "udpin:127.0.0.1:%d?name=plain" % ports[2],
                "udpin:127.0.0.1:%d?trusted=true&name=trusted" % ports[3]]

    router, _ = start_router(bin_, links)
    if router is None:
        return None
    S = Peer("signed1", M, 10, 1, dest=ports[0], key=KEY, link_id=3)
    S2 = Peer("signed2", M, 11, 1, dest=ports[1], key=KEY, link_id=4)
    P = Peer("plain", M, 20, 1, dest=ports[2])
    T = Peer("trusted", M, 30, 1, dest=ports[3])
    peers = (S, S2, P, T)
    try:
        # Everybody introduces itself, in this order (a udpin client is known from its first
        # frame on); the introductions are checked only where every receiver was known.
        S.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        arrived(S, S2.send(heartbeat(M.MAV_TYPE_FIXED_WING, M.MAV_AUTOPILOT_PX4)), "S2's HEARTBEAT")
        t_hb = T.send(heartbeat())
        arrived(S2, t_hb, "T's HEARTBEAT")
        arrived(T, P.send(heartbeat()), "P's HEARTBEAT")
        t_all = time.monotonic()  # from here on every link is known
        s1 = S.send(statustext("s signed 1"))
        S.send(statustext("s unsigned v2"), sign=False)
        S.send(statustext("s unsigned v1"), v1=True)
        # signed with another key, and a timestamp an hour ahead: must not move the stream on
        S.send(statustext("s forged"), key=OTHER_KEY, timestamp=signing_now() + 3600 * 100000)
        s2 = S.send(statustext("s signed 2"))  # genuine frames after the forgery still pass
        S.write(s2.raw)  # replays: the newest frame again, then an older one
        S.write(s1.raw)
        s3 = S.send(statustext("s signed 3"))
        S2.send(statustext("s2 signed"))
        T.send(statustext("t one"))
        T.send(statustext("t two"))
        P.send(statustext("p one"))
        P.send(statustext("p two"))
        settle()
        stats = router.stop()
        check_no_key(router, "signing")
        n = {}
        genuine = [s1, s2, s3]  # S's frames every other link must carry, once each
        t_frames_all = list(T.sent)  # S and S2 were known before T's HEARTBEAT
        after = lambda p: [f for f in p.sent if f.t >= t_all]  # noqa: E731

        # --- S and S2: only frames pymavlink verifies with K
        for me, other, lid, expect_other in ((S, S2, 7, S2.sent), (S2, S, 8, genuine)):
            got = me.frames()
            n[me.name] = len(got)
            check(got, "%s: received nothing" % me.name)
            bad = [(raw.hex(), why) for raw, why in me.bad]
            check(not bad, "%s (key link): pymavlink's signing refused frames (bytes, reason): %s" % (me.name, bad[:5]))
            check(not me.rejected, "%s: pymavlink refused unsigned/unverified frames, ids %s" % (me.name, me.rejected))
            check(all(f.version == 2 and f.signed for f in got), "%s: frames not signed MAVLink 2: %s" % (
                me.name, [f for f in got if not (f.version == 2 and f.signed)][:5]))
            check(me.rx.signing.goodsig_count == len(got), "%s: pymavlink verified %d signatures for %d frames" % (
                me.name, me.rx.signing.goodsig_count, len(got)))
            # The other signed peer's frames: byte for byte (already signed with K).
            for s in expect_other:
                rs = [f for f in got if f.key == s.key]
                if check(len(rs) == 1, "%s: %d copies of %s's %s, expected 1" % (me.name, len(rs), other.name, s.tag() or s.type)):
                    check(rs[0].raw == s.raw, "%s: %s's signed %s not byte for byte: sent %s, got %s" % (
                        me.name, other.name, s.type, s.raw.hex(), rs[0].raw.hex()))
            extra = [f for f in got if f.src == (other.sysid, other.compid) and not any(f.raw == s.raw for s in expect_other)]
            check(not extra, "%s: frames from %s beyond its genuine signed ones: %s" % (me.name, other.name, extra))
            # The trusted plain peer's frames: signed by the router with this link's link id.
            t_got = [f for f in got if f.src == (T.sysid, T.compid)]
            check(len(t_got) == len(t_frames_all), "%s: %d frames from the trusted peer, it sent %d" % (
                me.name, len(t_got), len(t_frames_all)))
            for s in t_frames_all:
                r = next((f for f in t_got if f.key == s.key), None)
                if not check(r is not None, "%s: the trusted peer's %s never arrived" % (me.name, s.tag() or s.type)):
                    continue
                check(r.link_id == lid, "%s: the router signed with link id %s, the link's link_id is %d" % (me.name, r.link_id, lid))
                hl = mi.V2_HEADER
                check(r.raw[:2] == s.raw[:2] and r.raw[3:hl + s.raw[1]] == s.raw[3:hl + s.raw[1]],
                      "%s: the signed copy of the trusted peer's %s changed header or payload: sent %s, got %s" % (
                          me.name, s.type, s.raw.hex(), r.raw.hex()))
                if r.msg is not None:
                    diff = same_fields(r.msg, s.msg)
                    check(not diff, "%s: trusted %s decodes to other values: %s" % (me.name, s.type, diff))
            ts = [f.timestamp for f in got if f.link_id == lid]
            check(ts == sorted(set(ts)), "%s: the router's signing timestamps do not rise: %s" % (me.name, ts))
            now = signing_now()
            check(all(abs(t - now) < 60 * 100000 for t in ts), "%s: the router's signing timestamps %s are not within a "
                  "minute of now (%d)" % (me.name, ts, now))
            untrusted = [f for f in got if f.src == (P.sysid, P.compid)]
            check(not untrusted, "%s (key link): got frames of the untrusted plain peer: %s" % (me.name, untrusted))

        # --- P and T: S's genuine frames without signature, nothing of the dropped ones
        for me in (P, T):
            got = me.frames()
            n[me.name] = len(got)
            check(not me.bad, "%s: pymavlink refused frames: %s" % (me.name, me.bad[:5]))
            signed = [f for f in got if f.signed]
            check(not signed, "%s (no key): received signed frames: %s" % (me.name, signed[:5]))
            for s in genuine + [f for f in S2.sent if f.t >= t_all]:
                rs = [f for f in got if f.key == s.key]
                if not check(len(rs) == 1, "%s: %d copies of %s's %s, expected 1 (replays dropped)" % (
                        me.name, len(rs), "S" if s.sysid == S.sysid else "S2", s.tag() or s.type)):
                    continue
                r = rs[0]
                hl = mi.V2_HEADER
                check(r.version == 2 and r.flags == 0 and len(r.raw) == hl + r.raw[1] + 2,
                      "%s: the signed %s arrived as %s, expected MAVLink 2 with incompat flags 0 and a 2-byte "
                      "trailer (no signature)" % (me.name, s.type, r.raw.hex()))
                check(r.raw[:2] == s.raw[:2] and r.raw[3:hl + s.raw[1]] == s.raw[3:hl + s.raw[1]],
                      "%s: the unsigned copy of %s changed header or payload: sent %s, got %s" % (
                          me.name, s.type, s.raw.hex(), r.raw.hex()))
                want = repack(M, s.msg, (s.sysid, s.compid, s.seq))
                check(r.raw == want, "%s: %s without signature is %s, pymavlink's unsigned packing is %s" % (
                    me.name, s.type, r.raw.hex(), want.hex()))
                if r.msg is not None:
                    diff = same_fields(r.msg, s.msg)
                    check(not diff, "%s: %s decodes to other values: %s" % (me.name, s.type, diff))
            tags = [f.tag() or f.type for f in got if f.src == (S.sysid, S.compid)]
            for t in ("s unsigned v2", "s unsigned v1", "s forged"):
                check(t not in tags, "%s: the signed link let %r through" % (me.name, t))
            check(len(tags) == len(genuine), "%s: %d frames from the signed peer, expected %d (%s)" % (
                me.name, len(tags), len(genuine), tags))
        for src, dst, frames in ((T, P, after(T)), (P, T, P.sent)):
            for s in frames:
                rs = [f for f in dst.frames() if f.key == s.key]
                if check(len(rs) == 1, "%s: %d copies of %s's %s, expected 1" % (dst.name, len(rs), src.name, s.tag() or s.type)):
                    check(rs[0].raw == s.raw, "%s: %s's %s not byte for byte: sent %s, got %s" % (
                        dst.name, src.name, s.type, s.raw.hex(), rs[0].raw.hex()))
        check(not [f for f in P.frames() if f.key == t_hb.key], "plain: got the trusted peer's HEARTBEAT sent before "
              "the plain peer was seen")

        # --- stats
        if check(stats is not None, "no final stats"):
            for name in ("signed1", "signed2"):
                check_versions(stats, name, "signed", "final stats")
                u = dropped(stats, name, "untrusted_to_signed")
                check(u == len(P.sent), "stats: untrusted_to_signed %d on %s, the untrusted peer broadcast %d frames "
                      "after %s was known: %s" % (u, name, len(P.sent), name, brief(stats)))
            for reason, want in (("unsigned", 2), ("bad_signature", 1), ("replay", 2)):
                got_n = dropped(stats, "signed1", reason)
                check(got_n == want, "stats: %s %d on signed1, expected %d: %s" % (reason, got_n, want, brief(stats)))
            rx = total(stats, "signed1", "rx_frames")
            check(rx == 1 + len(genuine), "stats: rx_frames %d on signed1, %d frames were genuine" % (rx, 1 + len(genuine)))
            for name, peer in (("signed1", S), ("signed2", S2), ("plain", P), ("trusted", T)):
                tx = total(stats, name, "tx_frames")
                check(tx == len(peer.frames()), "stats: tx_frames %d on %s, its peer received %d" % (tx, name, len(peer.frames())))
        summary = "frames received %s, all on key links verified with K; stats signed1 dropped %s" % (
            n, [e.get("dropped") for e in link_entries(stats, "signed1")])
    finally:
        router.kill()
        for p in peers:
            p.close()
    return summary


def targeting(bin_):
    ports = []

    def links():
        ports[:] = [free_port() for _ in range(3)]
        return ["udpin:127.0.0.1:%d?name=link_a" % ports[0],
                "udpin:127.0.0.1:%d?name=link_b" % ports[1],
                "udpin:127.0.0.1:%d?name=link_c" % ports[2]]

    router, _ = start_router(bin_, links)
    if router is None:
        return None
    A = Peer("A", M, 1, 1, dest=ports[0])
    B = Peer("B", M, 255, 190, dest=ports[1])
    C = Peer("C", M, 254, 190, dest=ports[2])
    peers = (A, B, C)
    notes = []

    def only(frame, receivers, what, byte_for_byte=True):
        for p in peers:
            rs = [f for f in p.frames() if f.key == frame.key]
            if p in receivers:
                if check(len(rs) == 1, "%s: %s got %d copies, expected 1" % (what, p.name, len(rs))) and byte_for_byte:
                    check(rs[0].raw == frame.raw, "%s: %s got %s, sent %s (not byte for byte)" % (
                        what, p.name, rs[0].raw.hex(), frame.raw.hex()))
            else:
                check(not rs, "%s: %s got it and must not" % (what, p.name))

    try:
        a_hb = A.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA))
        arrived(A, B.send(heartbeat()), "B's HEARTBEAT")
        arrived(B, C.send(heartbeat()), "C's HEARTBEAT")
        only(a_hb, [], "A's first HEARTBEAT (nobody else known yet)")
        checks = []
        checks.append((A.send(heartbeat(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 1)), [B, C], "A's HEARTBEAT (broadcast)"))
        checks.append((B.send(cmd_long((1, 1), p1=1.0)), [A], "B's COMMAND_LONG to 1/1"))
        checks.append((B.send(cmd_long((1, 99), p1=2.0)), [A], "B's COMMAND_LONG to 1/99 (component never seen: system's links)"))
        unknown = B.send(cmd_long((77, 1), p1=3.0))
        checks.append((unknown, [], "B's COMMAND_LONG to 77/1 (never seen)"))
        checks.append((A.send(M.MAVLink_command_ack_message(M.MAV_CMD_DO_SET_MODE, M.MAV_RESULT_ACCEPTED, 0, 0, 255, 190)), [B],
                       "A's COMMAND_ACK to 255/190 (target in the extension fields)"))
        checks.append((A.send(M.MAVLink_command_ack_message(M.MAV_CMD_DO_SET_MODE, M.MAV_RESULT_ACCEPTED, 0, 0, 0, 0)), [B, C],
                       "A's COMMAND_ACK with the target truncated away (broadcast)"))
        checks.append((A.send(cmd_long((0, 0), M.MAV_CMD_DO_SET_MODE, p1=4.0)), [B, C], "A's COMMAND_LONG to 0/0 (broadcast)"))
        checks.append((C.send(cmd_long((255, 190), p1=5.0)), [B], "C's COMMAND_LONG to 255/190"))
        settle()
        for f, receivers, what in checks:
            only(f, receivers, what)
        # mavlink-router #452: C echoes one of A's frames, byte for byte; the route to A must survive.
        echo_at = time.monotonic()
        C.write(a_hb.raw)
        settle(0.2)
        after = B.send(cmd_long((1, 1), p1=6.0))
        settle()
        ra = [f for f in A.frames(echo_at) if f.key == after.key]
        if check(len(ra) == 1, "after C echoed A's HEARTBEAT, B's COMMAND_LONG to 1/1 reached A %d times, expected once "
                 "(mavlink-router #452)" % len(ra)):
            check(ra[0].raw == after.raw, "after the echo: A got %s, B sent %s" % (ra[0].raw.hex(), after.raw.hex()))
        check(not [f for f in B.frames(echo_at) if f.key == after.key], "after the echo: B got its own command back")
        notes.append("after the echo C %s the command" % ("also got" if [f for f in C.frames(echo_at) if f.key == after.key] else "did not get"))
        notes.append("the echo itself reached %s" % (",".join(p.name for p in (A, B) if [f for f in p.frames(echo_at) if f.raw == a_hb.raw])
                                                       or "nobody"))
        stats = router.stop()
        for p in peers:
            check(not p.bad, "%s: pymavlink refused frames: %s" % (p.name, p.bad[:5]))
            own = [f for f in p.frames() if f.src == (p.sysid, p.compid) and f.raw != a_hb.raw]
            check(not own, "%s: its own frames came back: %s" % (p.name, own[:5]))
        if check(stats is not None, "no final stats"):
            ut = sum(dropped(stats, n_, "unknown_target") for n_ in ("link_a", "link_b", "link_c"))
            check(ut >= 1, "stats: no unknown_target drop counted for the command to 77/1: %s" % brief(stats))
            notes.append("unknown_target=%d (%s)" % (ut, ", ".join("%s:%d" % (n_, dropped(stats, n_, "unknown_target"))
                                                            for n_ in ("link_a", "link_b", "link_c"))))
        summary = "%d routing cases + the #452 echo; %s" % (len(checks) + 1, "; ".join(notes))
    finally:
        router.kill()
        for p in peers:
            p.close()
    return summary


def run_probe(bin_, port, sysid, timeout=5):
    proc = subprocess.Popen([bin_, "probe", "udpout:127.0.0.1:%d" % port, "--timeout", str(timeout), "--sysid", str(sysid)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        out, err = proc.communicate(timeout=40)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        fail("probe through the router did not finish within 40 s; stderr: %s" % err.decode("utf-8", "replace")[-500:])
        return None
    reports = []
    for line in out.decode("utf-8", "replace").splitlines():
        if not line.strip():
            continue
        try:
            reports.append(json.loads(line))
        except ValueError:
            fail("probe printed a line that is not JSON: %r" % line)
    rep = next((r for r in reports if isinstance(r, dict) and r.get("sysid") == 1), None)
    check(rep is not None, "probe (exit %s) reported no system 1 through the router: stdout %r, stderr %s" % (
        proc.returncode, out.decode("utf-8", "replace")[:500], err.decode("utf-8", "replace")[-500:]))
    if rep is not None:
        check(proc.returncode == 0, "probe found system 1 but exited %s" % proc.returncode)
    return rep


def handshake(bin_):
    ports = []

    def links():
        ports[:] = [free_port() for _ in range(5)]
        return ["udpin:127.0.0.1:%d?name=vehicle" % ports[0],
                "udpin:127.0.0.1:%d?name=gcs2" % ports[1],
                "udpin:127.0.0.1:%d?version=1&name=gcs1" % ports[2],
                "udpin:127.0.0.1:%d?name=probe2" % ports[3],
                "udpin:127.0.0.1:%d?version=1&name=probe1" % ports[4]]

    router, _ = start_router(bin_, links)
    if router is None:
        return None
    veh_log = tempfile.TemporaryFile()
    veh = subprocess.Popen([bin_, "vehicle", "udpout:127.0.0.1:%d" % ports[0], "-v"], stdin=subprocess.DEVNULL,
                           stdout=veh_log, stderr=subprocess.STDOUT)

    def veh_tail():
        veh_log.seek(0)
        return veh_log.read().decode("utf-8", "replace")[-1500:]

    g2 = Peer("gcs2", M, 255, 190, dest=ports[1])
    g1 = Peer("gcs1", M, 250, 190, dest=ports[2])
    notes = []
    try:
        # A MAVLink 2 ground station on a plain link (HEARTBEAT at 1 Hz, as ground stations do).
        g2.keep_alive(heartbeat())
        hb = g2.wait_for(lambda f: f.type == "HEARTBEAT" and f.src == (1, 1), 8)
        if not check(hb is not None, "gcs on a plain link: no HEARTBEAT of mavstack vehicle through the router within 8 s "
                     "(vehicle %s); vehicle log:\n%s" % ("running" if veh.poll() is None else "exited %s" % veh.returncode, veh_tail())):
            return None
        t0 = time.monotonic()
        g2.send(M.MAVLink_command_long_message(1, 1, REQUEST_MESSAGE, 0, PROTOCOL_VERSION_ID, 0, 0, 0, 0, 0, 0))
        ack = g2.wait_for(lambda f: f.type == "COMMAND_ACK" and f.msg.command == REQUEST_MESSAGE, 3, since=t0)
        pv = g2.wait_for(lambda f: f.type == "PROTOCOL_VERSION", 3, since=t0)
        if check(ack is not None, "gcs on a plain link: no COMMAND_ACK for REQUEST_MESSAGE(300)"):
            check(ack.msg.result == M.MAV_RESULT_ACCEPTED, "gcs on a plain link: COMMAND_ACK result %d, expected ACCEPTED" % ack.msg.result)
            check(ack.version == 2, "gcs on a plain link: COMMAND_ACK in MAVLink %d" % ack.version)
            check(ack.src == (1, 1), "gcs on a plain link: COMMAND_ACK from %d/%d" % ack.src)
        if check(pv is not None, "gcs on a plain link: no PROTOCOL_VERSION (300) through the router"):
            check(pv.version == 2 and pv.msgid == 300 and pv.src == (1, 1),
                  "gcs on a plain link: PROTOCOL_VERSION %r, expected MAVLink 2 id 300 from 1/1" % pv)
            check(pv.msg.version >= 200, "gcs on a plain link: PROTOCOL_VERSION.version %d" % pv.msg.version)
        wrong = [f for f in g2.frames() if f.version != 2]
        check(not wrong, "gcs on a plain link (it sent MAVLink 2 first): MAVLink 1 frames: %s" % wrong[:5])

        # The same from a version=1 link.
        g1.keep_alive(heartbeat(), v1=True)
        hb1 = g1.wait_for(lambda f: f.type == "HEARTBEAT" and f.src == (1, 1), 5)
        check(hb1 is not None, "gcs on a version=1 link: no HEARTBEAT of the vehicle within 5 s")
        t1 = time.monotonic()
        g1.send(M.MAVLink_command_long_message(1, 1, REQUEST_MESSAGE, 0, PROTOCOL_VERSION_ID, 0, 0, 0, 0, 0, 0))
        time.sleep(3)
        got1 = g1.frames()
        check(got1, "gcs on a version=1 link: received nothing")
        check(not [f for f in got1 if f.version != 1], "gcs on a version=1 link: non-MAVLink 1 frames: %s" % (
            [f for f in got1 if f.version != 1][:5]))
        check(not [f for f in got1 if f.msgid == PROTOCOL_VERSION_ID], "gcs on a version=1 link: PROTOCOL_VERSION arrived")
        ack1 = [f for f in g1.frames(t1) if f.type == "COMMAND_ACK" and f.msg.command == REQUEST_MESSAGE]
        for a in ack1:
            check(a.msg.result == M.MAV_RESULT_ACCEPTED, "gcs on a version=1 link: COMMAND_ACK result %d" % a.msg.result)
        notes.append("v1 gcs: %d frames, all MAVLink 1, no PROTOCOL_VERSION, COMMAND_ACK %s" % (
            len(got1), "ACCEPTED (v1)" if ack1 else "not delivered"))

        # mavstack probe through a plain link, then through a version=1 link.
        rep2 = run_probe(bin_, ports[3], 245)
        if rep2 is not None:
            res = (rep2.get("handshake") or {}).get("result")
            check(res == "protocol_version", "probe through a plain link: handshake.result %r, expected protocol_version "
                  "(report %s)" % (res, json.dumps(rep2)))
            notes.append("probe plain: %s" % res)
        rep1 = run_probe(bin_, ports[4], 246)
        if rep1 is not None:
            res = (rep1.get("handshake") or {}).get("result")
            check(res != "protocol_version", "probe through a version=1 link: handshake.result protocol_version, but the "
                  "router cannot carry PROTOCOL_VERSION in MAVLink 1 (report %s)" % json.dumps(rep1))
            notes.append("probe v1: %s" % res)
        stats = router.stop()
        if check(stats is not None, "no final stats"):
            check_versions(stats, "gcs1", "1", "final stats")
            check_versions(stats, "probe1", "1", "final stats")
            check_versions(stats, "gcs2", "2", "final stats")
            if ack1:
                cc = dropped(stats, "gcs1", "cannot_convert")
                check(cc >= 1, "stats: the vehicle answered gcs1's request, yet cannot_convert %d on gcs1: %s" % (cc, brief(stats)))
            notes.append("cannot_convert gcs1=%d probe1=%d" % (dropped(stats, "gcs1", "cannot_convert"),
                                                                dropped(stats, "probe1", "cannot_convert")))
        summary = "plain gcs: ACK + PROTOCOL_VERSION in MAVLink 2; " + "; ".join(notes)
    finally:
        router.kill()
        if veh.poll() is None:
            veh.send_signal(signal.SIGTERM)
            try:
                veh.wait(5)
            except subprocess.TimeoutExpired:
                veh.kill()
                veh.wait()
        for p in (g1, g2):
            p.close()
    return summary


def stats_and_exit(bin_):
    listener = Peer("listener", M, 203, 1)
    khex = KEY.hex()
    names = {"legacy": "1", "modern": "2", "secure": "signed", "peer": "auto", "listener": "auto"}
    ports = []

    def links():
        ports[:] = [free_port() for _ in range(4)]
        return ["udpin:127.0.0.1:%d?version=1&name=legacy" % ports[0],
                "udpin:127.0.0.1:%d?version=2&name=modern" % ports[1],
                "udpin:127.0.0.1:%d?key=%s&link_id=5&name=secure" % (ports[2], khex),
                "udpin:127.0.0.1:%d?name=peer" % ports[3],
                "udpout:127.0.0.1:%d?name=listener" % listener.port]

    router, _ = start_router(bin_, links)
    if router is None:
        listener.close()
        return None
    legacy = Peer("legacy", V1, 51, 1, dest=ports[0])
    modern = Peer("modern", M, 52, 1, dest=ports[1])
    secure = Peer("secure", M, 53, 1, dest=ports[2], key=KEY, link_id=2)
    peer = Peer("peer", V1, 50, 1, dest=ports[3])
    clients = {"legacy": legacy, "modern": modern, "secure": secure, "peer": peer}
    notes = []
    try:
        # No client yet: the objects come about once a second; the udpout link is listed.
        time.sleep(2.3)
        early = router.stats()
        check(len(early) >= 2, "--stats 1: %d stats objects within 2.3 s of ready, expected >= 2 (stdout %r)" % (
            len(early), router.stdout()[:500]))
        for _, st in early:
            check(isinstance(st.get("t_s"), (int, float)), "stats object without a numeric t_s: %s" % brief(st))
            ls = st.get("links")
            if not check(isinstance(ls, list), "stats object without a links list: %s" % brief(st)):
                continue
            for e in ls:
                for k in ("rx_frames", "tx_frames", "converted"):
                    check(isinstance(e.get(k), int) and not isinstance(e.get(k), bool),
                          "stats entry %s: %s is not an integer" % (e.get("name"), k))
                check(isinstance(e.get("dropped"), dict), "stats entry %s: dropped is not an object" % e.get("name"))
                check(isinstance(e.get("name"), str) and e.get("version") in ("1", "2", "signed", "auto"),
                      "stats entry with a bad name or version: %s" % json.dumps(e))
            check_versions(st, "listener", "auto", "stats before any traffic")
        if early:
            listed = [n_ for n_ in names if link_entries(early[-1][1], n_)]
            notes.append("before any client: %s listed" % ",".join(listed))
        ts = [st.get("t_s") for _, st in early]
        if len(ts) >= 2 and all(isinstance(t, (int, float)) for t in ts):
            gaps = [b - a for a, b in zip(ts, ts[1:])]
            check(all(0.5 <= g <= 1.6 for g in gaps), "--stats 1: t_s steps %s, expected about 1 s" % gaps)
            arrivals = [t for t, _ in early]
            agaps = [b - a for a, b in zip(arrivals, arrivals[1:])]
            check(all(0.5 <= g <= 1.6 for g in agaps), "--stats 1: objects printed %s s apart" % [round(g, 2) for g in agaps])
        # A client on every udpin link; three MAVLink 1 frames on the auto link.
        legacy.send(heartbeat(mod=V1))
        modern.send(heartbeat())
        secure.send(heartbeat())
        for _ in range(3):
            peer.send(heartbeat(mod=V1))
        sent = {"legacy": 1, "modern": 1, "secure": 1, "peer": 3}
        settle()
        t_v1 = time.monotonic()
        time.sleep(1.3)
        mid = router.stats(t_v1)
        if check(mid, "no stats object in the 1.3 s after the clients' frames"):
            st = mid[-1][1]
            for name, ver in names.items():
                if check(link_entries(st, name), "stats: no entry for link %s once it has a client: %s" % (name, brief(st))):
                    check_versions(st, name, ver, "stats after MAVLink 1 frames on the auto link")
            for name, n_ in sent.items():
                check(total(st, name, "rx_frames") == n_, "stats: %s rx_frames %d, its client sent %d (%s)" % (
                    name, total(st, name, "rx_frames"), n_, brief(st)))
            for name, p in list(clients.items()) + [("listener", listener)]:
                check(total(st, name, "tx_frames") == len(p.frames()), "stats: %s tx_frames %d, its peer received %d" % (
                    name, total(st, name, "tx_frames"), len(p.frames())))
        check(len(listener.from_((50, 1))) == 3, "listener: %d of the auto peer's 3 frames" % len(listener.from_((50, 1))))
        # The auto link's first MAVLink 2 frame (from the same socket, packed by a MAVLink 2
        # object with the peer's ids and sequence) makes it "2".
        mav2 = M.MAVLink(None, srcSystem=50, srcComponent=1)
        mav2.seq = peer.tx.seq
        peer.write(bytes(heartbeat().pack(mav2)))
        settle()
        t_v2 = time.monotonic()
        time.sleep(1.3)
        late = router.stats(t_v2)
        if check(late, "no stats object in the 1.3 s after the peer's MAVLink 2 frame"):
            st = late[-1][1]
            client_versions = [e.get("version") for e in link_entries(st, "peer") if e.get("rx_frames")]
            check(client_versions == ["2"], "stats: the auto link's client is %s after its peer's MAVLink 2 frame, "
                  "expected \"2\": %s" % (client_versions, brief(st)))
            check(total(st, "peer", "rx_frames") == 4, "stats: peer rx_frames %d, it sent 4" % total(st, "peer", "rx_frames"))
        n_before = len(router.stats())
        final = router.stop(signal.SIGTERM)
        check(len(router.stats()) > n_before, "no stats object printed on SIGTERM")
        check_no_key(router, "stats_and_exit")
        if final is not None:
            for name in names:
                check(link_entries(final, name), "final stats: no entry for %s" % name)
            for name, p in list(clients.items()) + [("listener", listener)]:
                check(total(final, name, "tx_frames") == len(p.frames()), "final stats: %s tx_frames %d, its peer received %d" % (
                    name, total(final, name, "tx_frames"), len(p.frames())))
        summary = "%d stats objects; %s; versions %s; exit %s on SIGTERM with a last object" % (
            len(router.stats()), "; ".join(notes), {n_: versions(final, n_) for n_ in names}, router.rc)
    finally:
        router.kill()
        for p in list(clients.values()) + [listener]:
            p.close()
    return summary


def tlog(bin_):
    """--log DIR: every accepted frame in a tlog that pymavlink's own reader reads, with the
    link number in the timestamps' low bits as MAVProxy writes it (msg._link)."""
    import glob
    import tempfile
    from pymavlink import mavutil
    d = tempfile.mkdtemp(prefix="mavstack-tlog-")
    ports = []

    def links():
        ports[:] = [free_port(), free_port()]
        return ["udpin:127.0.0.1:%d?name=zero" % ports[0], "udpin:127.0.0.1:%d?version=1&name=one" % ports[1]]

    router, _ = start_router(bin_, links, extra=("--log", d))
    if router is None:
        return None
    a = Peer("a", M, 61, 1, dest=ports[0])
    b = Peer("b", V1, 62, 1, dest=ports[1])
    sent = []
    try:
        for i in range(5):
            sent.append((0, a.send(heartbeat(custom_mode=i))))
            sent.append((1, b.send(heartbeat(custom_mode=100 + i, mod=V1))))
            time.sleep(0.05)
        settle()
    finally:
        router.stop()
        a.close()
        b.close()
    files = glob.glob(os.path.join(d, "*.tlog"))
    if not check(len(files) == 1, "--log %s: expected one tlog, found %r" % (d, files)):
        return None
    log = mavutil.mavlink_connection(files[0], dialect="common")
    got = []
    while True:
        m = log.recv_match(blocking=False)
        if m is None:
            break
        if m.get_type() != "BAD_DATA":
            got.append((m._link, m.get_srcSystem(), m.custom_mode, bytes(m.get_msgbuf())))
    want = [(link, f.raw[5] if f.raw[0] == 0xFD else f.raw[3], None, f.raw) for link, f in sent]
    check(len(got) == len(sent), "tlog: %d frames read by pymavlink, %d sent" % (len(got), len(sent)))
    for (link, _, _, raw), g in zip(want, got):
        check(g[3] == raw, "tlog: frame differs from what the peer sent: %s vs %s" % (g[3].hex(), raw.hex()))
        check(g[0] == link, "tlog: link bits %d, expected %d (link order)" % (g[0], link))
    return "%d frames, links 0 and 1, bytes as sent" % len(got)


def own_heartbeat(bin_):
    """--heartbeat --sysid 42: the router's own HEARTBEAT on three links, each framing it its
    own way, read by pymavlink."""
    ports = []

    def links():
        ports[:] = [free_port() for _ in range(3)]
        return ["udpin:127.0.0.1:%d?version=1&name=legacy" % ports[0],
                "udpin:127.0.0.1:%d?name=auto" % ports[1],
                "udpin:127.0.0.1:%d?key=%s&link_id=3&name=secure" % (ports[2], KEY.hex())]

    router, _ = start_router(bin_, links, extra=("--heartbeat", "--sysid", "42", "--compid", "191"))
    if router is None:
        return None
    leg = Peer("legacy", V1, 255, 190, dest=ports[0])
    auto = Peer("auto", M, 254, 190, dest=ports[1])
    sec = Peer("secure", M, 253, 190, dest=ports[2], key=KEY)
    peers = (leg, auto, sec)
    try:
        # Each peer makes itself known (a udpin link has no peer before it hears one).
        leg.send(heartbeat(mod=V1))
        auto.send(heartbeat(), v1=True)
        sec.send(heartbeat())
        time.sleep(2.6)

        def own(peer, since=0.0):
            with peer.lock:
                return [f for f in peer.got if f.src == (42, 191) and f.t >= since]

        for peer in peers:
            got = own(peer)
            check(len(got) >= 2, "%s: %d of the router's HEARTBEATs in 2.6 s, expected 2 or more" % (peer.name, len(got)))
            for f in got:
                check(f.msg is not None and f.type == "HEARTBEAT", "%s: the router's frame %r is not a HEARTBEAT pymavlink reads" % (peer.name, f))
                if f.msg is not None and f.type == "HEARTBEAT":
                    check((f.msg.type, f.msg.autopilot, f.msg.system_status) == (M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, M.MAV_STATE_ACTIVE),
                          "%s: the router's HEARTBEAT %s, expected an onboard controller's" % (peer.name, f.msg))
            seqs = [f.seq for f in got]
            check(all((b - a) % 256 == 1 for a, b in zip(seqs, seqs[1:])),
                  "%s: the router's sequence numbers on this link %s, expected consecutive" % (peer.name, seqs))
        check(all(f.version == 1 for f in own(leg)), "legacy (version=1): the router's frames %s, expected MAVLink 1 only" % own(leg))
        check(all(f.version == 1 for f in own(auto)),
              "auto link whose peer spoke only MAVLink 1: the router's frames %s, expected MAVLink 1" % own(auto))
        check(all(f.version == 2 and f.signed and f.link_id == 3 for f in own(sec)),
              "secure (key=): the router's frames %s, expected signed MAVLink 2 with link id 3" % own(sec))
        check(not sec.rejected and not sec.bad, "secure: pymavlink refused the router's frames (%s %s)" % (sec.rejected, sec.bad))
        # The auto link's peer speaks MAVLink 2: from then on, so does the router there.
        auto.send(heartbeat())
        switched = time.monotonic() + SETTLE
        time.sleep(2.6)
        after = own(auto, switched)
        check(after and all(f.version == 2 and not f.signed for f in after),
              "auto link after its peer's MAVLink 2 frame: the router's frames %s, expected unsigned MAVLink 2" % after)
        check(all(f.version == 1 for f in own(leg)), "legacy: MAVLink 2 from the router after the auto link switched: %s" % own(leg))
        stats = router.stop()
        check_versions(stats, "auto", "2", "own_heartbeat")
        check_versions(stats, "legacy", "1", "own_heartbeat")
        check_no_key(router, "own_heartbeat")
    finally:
        router.kill()
        for p in peers:
            p.close()
    return "the router's HEARTBEAT as 42/191: MAVLink 1 on version=1, MAVLink 1 then 2 on auto, signed (link id 3) on key=, consecutive sequence per link"


SCENARIOS = {
    "v1_peer": v1_peer,
    "v2_link": v2_link,
    "signing": signing,
    "targeting": targeting,
    "handshake": handshake,
    "stats_and_exit": stats_and_exit,
    "tlog": tlog,
    "own_heartbeat": own_heartbeat,
}


if __name__ == "__main__":
    scenario.main(SCENARIOS, __doc__)
