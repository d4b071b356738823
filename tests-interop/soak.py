#!/usr/bin/env python3
"""A soak run: `mavstack router` with seven links of mixed versions and signing under steady
traffic, with faults injected on three of them, and `mavstack vehicle` behind it serving a
pymavlink ground station's parameter, mission and command loops.

Usage:
  soak.py --mavstack BIN [--minutes 10] [--rate 1000] [--json OUT]

The router's links (all on loopback):
  vehicle  udpout to `mavstack vehicle` (system 1)                          healthy
  gcs      udpin, only system 1's frames out: a pymavlink ground station    healthy
           looping PARAM_SET/PARAM_REQUEST_READ, a 5-item mission upload
           and download, and REQUEST_MESSAGE(AUTOPILOT_VERSION)
  watch    udpin, trusted: system 250 sends ATTITUDE at --rate; counts       healthy
           what arrives from everyone
  signed   udpin with a key: system 4 sends signed ATTITUDE at --rate;       healthy
           counts what arrives (all of it must be signed by the router)
  legacy   udpin version=1: system 3 sends MAVLink 1 at --rate/2, floods     faults
           (as fast as it can for 5 s every minute), and corrupts 3 % and
           truncates 3 % of its datagrams; everything it gets must be MAVLink 1
  tcp      tcpin: system 5 sends at --rate/2 and is killed (RST) and         faults
           reconnects every 40 s
  serial   a pseudo-terminal (through a symlink): system 6 sends at          faults
           --rate/4; every 60 s the terminal disappears for 3 s and comes
           back as a new one

What must hold: nothing lost between the healthy links (ATTITUDE counters of system 4 seen
on watch, of system 250 seen on signed: every one arrives), every ground-station loop
succeeds, legacy gets MAVLink 1 only and signed gets signed frames only, both daemons stay
up, their RSS stays flat (reported every minute; the last at most 1.5x the first + 8 MB)
and they hold no more file descriptors at the end than a minute in (+2). Prints a report
and exits 1 on any failure.
"""
import argparse
import json
import multiprocessing as mp
import os
import pty
import random
import socket
import struct
import sys
import tempfile
import time
import tty

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from scenario import free_port  # noqa: E402
from gcs_common import Router, Vehicle  # noqa: E402
from pymavlink.dialects.v20 import common as M  # noqa: E402

KEY = bytes(range(32))
COUNTED = 1 << 22  # counters per source: enough for 60 minutes at 1,000 a second


def attitude(mav, n, v1=False):
    """ATTITUDE with counter n in time_boot_ms (the payload's first 4 bytes)."""
    return mav.attitude_encode(n, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0).pack(mav, force_mavlink1=v1)


def frames(data):
    """(magic, sysid, msgid, incompat, payload) of each frame in a datagram or stream piece."""
    i = 0
    while i + 8 <= len(data):
        magic = data[i]
        if magic == 0xFD and i + 12 <= len(data):
            n, inc = data[i + 1], data[i + 2]
            end = i + 12 + n + (13 if inc & 1 else 0)
            if end > len(data):
                return
            msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
            yield magic, data[i + 5], msgid, inc, data[i + 10:i + 10 + n]
            i = end
        elif magic == 0xFE:
            n = data[i + 1]
            end = i + 8 + n
            if end > len(data):
                return
            yield magic, data[i + 3], data[i + 5], 0, data[i + 6:i + 6 + n]
            i = end
        else:
            i += 1


class Counter:
    """What arrived on one link: frames per source system, ATTITUDE counters per source
    (for loss), frames of the wrong kind."""

    def __init__(self):
        self.per_sys = {}
        self.seen = {}
        self.v2 = 0
        self.unsigned = 0

    def add(self, data):
        for magic, sysid, msgid, inc, payload in frames(data):
            self.per_sys[sysid] = self.per_sys.get(sysid, 0) + 1
            if magic == 0xFD:
                self.v2 += 1
                if not inc & 1:
                    self.unsigned += 1
            if msgid == 30 and len(payload) >= 4:
                n = struct.unpack_from("<I", payload)[0]
                bits = self.seen.setdefault(sysid, bytearray(COUNTED // 8))
                if n < COUNTED:
                    bits[n >> 3] |= 1 << (n & 7)

    def missing(self, sysid, start, end):
        """The counters of `sysid` in [start, end) that did not arrive."""
        bits = self.seen.get(sysid, bytearray(COUNTED // 8))
        return [n for n in range(start, min(end, COUNTED)) if not bits[n >> 3] >> (n & 7) & 1]

    def result(self):
        return {"per_sys": self.per_sys, "v2": self.v2, "unsigned_v2": self.unsigned}


def pace(rate, start, sent):
    """Sleeps until the `sent`-th frame is due."""
    ahead = sent / rate - (time.monotonic() - start)
    if ahead > 0.001:
        time.sleep(ahead)


def udp_peer(role, port, sysid, rate, seconds, results, signed=False, v1=False, faults=False):
    """Sends ATTITUDE (counter in time_boot_ms) to the router's udpin `port` and counts what
    comes back, for `seconds`; reports (sent, counter, expected-counter totals)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=1)
    if signed:
        mav.signing.secret_key = KEY
        mav.signing.link_id = 1
        mav.signing.sign_outgoing = True
        mav.signing.timestamp = int((time.time() - 1420070400) * 100000)
    rng = random.Random(sysid)
    counter = Counter()
    start = time.monotonic()
    sent = extra = damaged = 0
    flood_until = 0.0
    while True:
        now = time.monotonic()
        if now - start >= seconds:
            break
        flooding = faults and now < flood_until
        if faults and not flooding and int(now - start) % 60 == 30 and now - start > 5:
            flood_until = now + 5
        frame = attitude(mav, sent, v1)
        if faults and rng.random() < 0.06:
            bad = bytearray(frame)
            if rng.random() < 0.5:
                bad = bad[:rng.randrange(1, len(bad))]
            else:
                bad[rng.randrange(len(bad))] ^= 0xFF
            frame = bytes(bad)
            damaged += 1
        try:
            sock.sendto(frame, ("127.0.0.1", port))
        except OSError:
            pass
        if flooding:
            extra += 1
        sent += 1
        for _ in range(64):
            try:
                counter.add(sock.recv(65536))
            except BlockingIOError:
                break
        if not flooding:
            pace(rate, start, sent - extra)
    drain(sock, counter)
    # What did not arrive of the healthy senders' frames (the first 2 s aside: a peer's
    # frames reach a udpin link's client only once that client has sent something).
    warm = 2 * rate
    missing = {s: counter.missing(s, warm, COUNTED) for s in (4, 250)}
    results.put((role, {"sent": sent, "damaged": damaged, "flood": extra, "warm": warm,
                        "counts": counter.result(), "missing": missing}))


def drain(sock, counter, seconds=1.5):
    sock.setblocking(True)
    sock.settimeout(0.2)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            counter.add(sock.recv(65536))
        except socket.timeout:
            pass


def tcp_peer(port, sysid, rate, seconds, results):
    """A TCP client of the router's tcpin link, killed (RST) and reconnected every 40 s."""
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=1)
    start = time.monotonic()
    sent = reconnects = 0
    got = 0
    while time.monotonic() - start < seconds:
        try:
            s = socket.create_connection(("127.0.0.1", port), timeout=2)
        except OSError:
            time.sleep(0.5)
            continue
        s.setblocking(False)
        opened = time.monotonic()
        while time.monotonic() - opened < 40 and time.monotonic() - start < seconds:
            try:
                s.sendall(attitude(mav, sent))
                sent += 1
            except (BlockingIOError, OSError):
                pass
            try:
                got += len(s.recv(65536))
            except (BlockingIOError, OSError):
                pass
            pace(rate, start, sent)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        s.close()
        reconnects += 1
        time.sleep(1)
    results.put(("tcp", {"sent": sent, "reconnects": reconnects, "bytes_received": got}))


def serial_peer(path, sysid, rate, seconds, results):
    """A pseudo-terminal behind `path`; every 60 s it disappears for 3 s (master closed,
    symlink removed) and comes back as a new terminal."""
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=1)
    start = time.monotonic()
    sent = outages = got = 0

    def open_tty():
        master, slave = pty.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        tmp = path + ".new"
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, path)
        return master, slave

    master, slave = open_tty()
    opened = time.monotonic()
    while time.monotonic() - start < seconds:
        if time.monotonic() - opened >= 60:
            os.unlink(path)
            os.close(master)
            os.close(slave)
            outages += 1
            time.sleep(3)
            master, slave = open_tty()
            opened = time.monotonic()
        try:
            os.write(master, attitude(mav, sent))
            sent += 1
        except OSError:
            pass
        try:
            got += len(os.read(master, 65536))
        except OSError:
            pass
        pace(rate, start, sent)
    results.put(("serial", {"sent": sent, "outages": outages, "bytes_received": got}))


def gcs_loops(port, seconds, results):
    """Parameter, mission and command loops against system 1 through the router."""
    from pymavlink import mavutil
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255,
                                      source_component=190)
    target = (1, 1)
    ok = {"param": 0, "mission": 0, "command": 0}
    failed = {"param": 0, "mission": 0, "command": 0}
    first_failures = []

    def recv(types, cond=lambda m: True, timeout=3.0):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            m = conn.recv_match(type=types, blocking=True, timeout=max(0.01, end - time.monotonic()))
            if m is not None and m.get_srcSystem() == target[0] and cond(m):
                return m
        return None

    def note(kind, good, why=""):
        (ok if good else failed)[kind] += 1
        if not good and len(first_failures) < 10:
            first_failures.append(f"{kind}: {why}")

    start = time.monotonic()
    while time.monotonic() - start < 10:
        conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        if recv("HEARTBEAT", timeout=1.0):
            break
    i = 0
    while time.monotonic() - start < seconds:
        i += 1
        conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        value = float(1000 + i % 500)
        conn.mav.param_set_send(*target, b"RTL_ALT", value, M.MAV_PARAM_TYPE_REAL32)
        m = recv("PARAM_VALUE", lambda m: m.param_id == "RTL_ALT" and m.param_value == value)
        note("param", m is not None, f"no PARAM_VALUE RTL_ALT={value} (loop {i})")
        count = 5
        conn.mav.mission_count_send(*target, count, 0)
        asked = set()
        ack = None
        while ack is None:
            m = recv(["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"])
            if m is None:
                break
            if m.get_type() == "MISSION_ACK":
                ack = m
                break
            asked.add(m.seq)
            conn.mav.mission_item_int_send(*target, m.seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                           M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                           -353632610 + m.seq * 100, 1491652300, 20 + i % 7, 0)
        good = ack is not None and ack.type == M.MAV_MISSION_ACCEPTED and len(asked) == count
        if good:
            conn.mav.mission_request_list_send(*target, 0)
            c = recv("MISSION_COUNT")
            items = 0
            for seq in range(c.count if c else 0):
                conn.mav.mission_request_int_send(*target, seq, 0)
                if recv("MISSION_ITEM_INT", lambda m, seq=seq: m.seq == seq):
                    items += 1
            conn.mav.mission_ack_send(*target, M.MAV_MISSION_ACCEPTED, 0)
            good = c is not None and c.count == count and items == count
        note("mission", good, f"upload/download of {count} items (loop {i})")
        conn.mav.command_long_send(*target, M.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0)
        a = recv("COMMAND_ACK", lambda m: m.command == M.MAV_CMD_REQUEST_MESSAGE)
        note("command", a is not None and a.result == M.MAV_RESULT_ACCEPTED,
             f"REQUEST_MESSAGE ack {a.result if a else None} (loop {i})")
    results.put(("gcs", {"ok": ok, "failed": failed, "first_failures": first_failures}))


def rss_kb(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def fds(pid):
    return len(os.listdir(f"/proc/{pid}/fd"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rate", type=int, default=1000, help="frames/s of the steady senders")
    ap.add_argument("--json", help="write the report here too")
    args = ap.parse_args()
    seconds = args.minutes * 60
    work = tempfile.mkdtemp(prefix="mavstack-soak-")
    tty_path = os.path.join(work, "tty")
    p = {name: free_port() for name in ("vehicle", "gcs", "watch", "signed", "legacy", "tcp")}
    ctx = mp.get_context("fork")
    results = ctx.Queue()
    # The terminal exists before the router opens it.
    serial = ctx.Process(target=serial_peer, args=(tty_path, 6, args.rate // 4, seconds + 5, results))
    serial.start()
    deadline = time.monotonic() + 5
    while not os.path.exists(tty_path) and time.monotonic() < deadline:
        time.sleep(0.05)
    vehicle = Vehicle(args.mavstack, f"udpin:127.0.0.1:{p['vehicle']}", workdir=work)
    links = [
        f"udpout:127.0.0.1:{p['vehicle']}?name=vehicle",
        f"udpin:127.0.0.1:{p['gcs']}?name=gcs&allow_src_sys_out=1",
        f"udpin:127.0.0.1:{p['watch']}?name=watch&trusted=true",
        f"udpin:127.0.0.1:{p['signed']}?name=signed&key={KEY.hex()}",
        f"udpin:127.0.0.1:{p['legacy']}?name=legacy&version=1",
        f"tcpin:127.0.0.1:{p['tcp']}?name=tcp",
        f"serial:{tty_path}:115200?name=serial",
    ]
    router = Router(args.mavstack, links, work, stats=60, name="soak-router")
    procs = [serial] + [ctx.Process(target=t, args=a) for t, a in [
        (gcs_loops, (p["gcs"], seconds, results)),
        (udp_peer, ("watch", p["watch"], 250, args.rate, seconds, results)),
        (udp_peer, ("signed", p["signed"], 4, args.rate, seconds, results, True)),
        (udp_peer, ("legacy", p["legacy"], 3, args.rate // 2, seconds, results, False, True, True)),
        (tcp_peer, (p["tcp"], 5, args.rate // 2, seconds, results)),
    ]]
    for pr in procs[1:]:
        pr.start()
    problems = []
    minutes = []
    started = time.monotonic()
    fd_start = None
    while time.monotonic() - started < seconds:
        time.sleep(min(60, max(1, seconds - (time.monotonic() - started))))
        for name, proc in (("router", router.proc), ("vehicle", vehicle.proc)):
            if proc.poll() is not None:
                problems.append(f"{name} exited ({proc.returncode})")
        if problems:
            break
        row = {"minute": round((time.monotonic() - started) / 60, 1),
               "router_rss_kb": rss_kb(router.proc.pid), "vehicle_rss_kb": rss_kb(vehicle.proc.pid),
               "router_fds": fds(router.proc.pid), "vehicle_fds": fds(vehicle.proc.pid)}
        if fd_start is None:
            fd_start = row
        minutes.append(row)
        print(json.dumps(row), flush=True)
    got = {}
    for _ in procs:
        try:
            role, res = results.get(timeout=30)
            got[role] = res
        except Exception:  # noqa: BLE001 - a peer that died reports nothing
            break
    for pr in procs:
        pr.join(5)
    fd_end = minutes[-1] if minutes else None
    stats = router.stop() if not problems else router.last_stats()
    vehicle.stop()

    # Judgement.
    for role in ("gcs", "watch", "signed", "legacy", "tcp", "serial"):
        if role not in got:
            problems.append(f"peer {role} reported nothing")
    loss = {}
    for src, dst in ((4, "watch"), (250, "signed")):
        sender = "signed" if src == 4 else "watch"
        if sender in got and dst in got:
            sent, warm = got[sender]["sent"], got[sender]["warm"]
            missing = [n for n in got[dst]["missing"][src] if n < sent]
            loss[f"{sender}->{dst}"] = {"sent": sent - warm, "lost": len(missing),
                                        "first_lost": missing[:20]}
            if missing:
                problems.append(f"{sender} -> {dst}: {len(missing)} of {sent - warm} lost "
                                f"(counters {missing[:10]}...)")
    if "gcs" in got:
        g = got["gcs"]
        if any(g["failed"].values()) or not all(g["ok"].values()):
            problems.append(f"ground-station loops: ok {g['ok']} failed {g['failed']}: "
                            f"{g['first_failures']}")
    if "legacy" in got and got["legacy"]["counts"]["v2"]:
        problems.append(f"legacy (version=1) got {got['legacy']['counts']['v2']} MAVLink 2 frames")
    if "signed" in got and got["signed"]["counts"]["unsigned_v2"]:
        problems.append(f"signed got {got['signed']['counts']['unsigned_v2']} unsigned frames")
    if "watch" in got:
        for src, name in ((3, "legacy"), (5, "tcp"), (6, "serial"), (1, "vehicle")):
            if not got["watch"]["counts"]["per_sys"].get(src):
                problems.append(f"nothing from the {name} link reached watch")
    if len(minutes) >= 2:
        for who in ("router", "vehicle"):
            first, last = minutes[0][f"{who}_rss_kb"], minutes[-1][f"{who}_rss_kb"]
            if last > first * 1.5 + 8192:
                problems.append(f"{who} RSS grew from {first} kB to {last} kB")
            if fd_end[f"{who}_fds"] > fd_start[f"{who}_fds"] + 2:
                problems.append(f"{who} file descriptors {fd_start[who + '_fds']} -> {fd_end[who + '_fds']}")
    report = {"minutes": args.minutes, "rate": args.rate, "loss": loss, "peers": got,
              "rss_and_fds": minutes, "router_final_stats": stats, "problems": problems}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)
    print(json.dumps({k: report[k] for k in ("loss", "problems")}))
    for role, res in got.items():
        print(role, json.dumps({k: v for k, v in res.items() if k != "missing"})[:400])
    if problems:
        print("FAIL: " + "\n      ".join(problems), file=sys.stderr)
        print(router.log(2000), file=sys.stderr)
        sys.exit(1)
    print(f"soak: {args.minutes} min ok")


if __name__ == "__main__":
    main()
