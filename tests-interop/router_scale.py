#!/usr/bin/env python3
"""1,000 UDP links on one router (not in CI: about a minute, and it wants the machine).

    cargo build --release -p mavstack-cli
    .venv/bin/python tests-interop/router_scale.py --mavstack target/release/mavstack \\
        [--peers 1000] [--rate 20] [--seconds 30] [--procs 4]

A drone show's ground side: every drone sends to one port of the router, and one ground
station gets all of it. The router runs as such a fleet would configure it:

    mavstack router 'udpin:127.0.0.1:FLEET?name=fleet&max_peers=PEERS&isolate_peers=true'
                    'udpout:127.0.0.1:GCS?name=gcs&pack=true' --stats 5

(`--stats` every 5 s, or a quarter of a shorter measurement.)

- One server port for the whole fleet: every drone is set up alike (the router's address and
  port), and each drone (a source port) becomes a router link of its own, so replies and
  commands go to that drone only. `max_peers` (64 by default) is raised to the fleet's size.
- `isolate_peers=true`: the drones do not hear each other. Without it a broadcast (HEARTBEAT
  and every telemetry message has no target) goes to every other link, and 1,000 drones at
  20 frames/s would make 20 million datagrams a second to the other drones.
- `pack=true` on the ground station's link: its 20 k frames a second travel in full
  datagrams (every MAVLink parser reads several frames from one).

Peers: --procs processes share --peers UDP sockets, each its own source port and identity
(MAVLink has 255 system ids, so a fleet of 1,000 is told apart by system and component id:
peer i is system 1 + i % 250, component 1 + i // 250). Each sends --rate frames a second, a
second's cycle of HEARTBEAT, 10 ATTITUDE, 5 GLOBAL_POSITION_INT, 2 SYS_STATUS and 2 VFR_HUD
(for --rate 20), its sequence number counting up; the frames are pymavlink's (each message
packed once by pymavlink, the sequence number and checksum then set per frame, checked
against pymavlink's own packing at the start). The ground station sends a HEARTBEAT a second
(a broadcast: every drone must get it) and, once the measurement has started, one
COMMAND_LONG to each drone (it must reach that drone and no other).

Checked (counts, no timing): every frame each peer sent reached the ground station
(pymavlink parses a sample of the datagrams; every frame is counted by its header), no drone
got a frame of another drone, every drone got its command and no other, and the ground
station's HEARTBEATs; the `--stats` objects show one link, one route and one system per
drone (and the ground station's route), whatever the run's length; the router's resident
memory does not grow over the measurement. Reported: the router's CPU (from /proc, utime +
stime) over the measurement, per link and per frame, and its memory before the fleet, with it,
and at the end, per link. Exit 1 on a failed check.
"""

import argparse
import json
import multiprocessing
import os
import selectors
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

os.environ.setdefault("MAVLINK20", "1")
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from scenario import check, failures, free_port  # noqa: E402

mp = multiprocessing.get_context("fork")
GCS_SYS, GCS_COMP = 255, 190
CLK_TCK = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")


def mav():
    from pymavlink.dialects.v20 import ardupilotmega as m
    return m


def identity(i):
    return 1 + i % 250, 1 + i // 250


def peer_of(sysid, compid):
    return (compid - 1) * 250 + (sysid - 1)


def cycle(rate):
    """The kinds of one second's frames: a HEARTBEAT, then telemetry (10:5:2:2 of 19)."""
    base = ["att"] * 10 + ["gpi"] * 5 + ["sys"] * 2 + ["vfr"] * 2
    kinds = ["hb"] + [base[(k * len(base)) // max(1, rate - 1)] for k in range(rate - 1)]
    return kinds


def messages(m, i):
    """The messages of peer i, by kind (values differ per peer)."""
    return {
        "hb": m.MAVLink_heartbeat_message(type=2, autopilot=3, base_mode=0x51, custom_mode=4,
                                          system_status=4, mavlink_version=3),
        "att": m.MAVLink_attitude_message(time_boot_ms=i, roll=0.01, pitch=-0.02, yaw=1.5 + i * 1e-3,
                                          rollspeed=0.001, pitchspeed=-0.002, yawspeed=0.003),
        "gpi": m.MAVLink_global_position_int_message(time_boot_ms=i, lat=473977420 + i * 100,
                                                     lon=85455940 + i * 100, alt=488000,
                                                     relative_alt=10000 + i, vx=12, vy=-3, vz=0,
                                                     hdg=27000),
        "sys": m.MAVLink_sys_status_message(onboard_control_sensors_present=0x1236c0f,
                                            onboard_control_sensors_enabled=0x1236c0f,
                                            onboard_control_sensors_health=0x1236c0f, load=500,
                                            voltage_battery=12600, current_battery=1520,
                                            battery_remaining=87, drop_rate_comm=0, errors_comm=0,
                                            errors_count1=0, errors_count2=0, errors_count3=0,
                                            errors_count4=0),
        "vfr": m.MAVLink_vfr_hud_message(airspeed=3.0, groundspeed=3.1, heading=270, throttle=40,
                                         alt=48.8, climb=0.1),
    }


def pack(m, msg, sysid, compid, seq):
    link = m.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    link.seq = seq & 0xFF
    return bytes(msg.pack(link))


class SeqPatch:
    """Sets a MAVLink 2 frame's sequence number and checksum: the checksum is linear in the
    bytes it covers, so changing byte 4 from 0 to `seq` changes it by the checksum (from a
    zero start) of `seq` followed by as many zeros as bytes follow it (CRC_EXTRA included)."""

    def __init__(self):
        from pymavlink.generator.mavcrc import x25crc
        self.crc = x25crc
        self.tables = {}

    def table(self, after):
        t = self.tables.get(after)
        if t is None:
            t = []
            for seq in range(256):
                c = self.crc()
                c.crc = 0
                c.accumulate(bytes([seq]) + bytes(after))
                t.append(c.crc)
            self.tables[after] = t
        return t

    def prepare(self, frame0):
        """frame0 is packed with seq 0: its bytes before the checksum and the delta table."""
        n = len(frame0)
        after = n - 2 - 5 + 1  # bytes after the seq byte up to the checksum, plus CRC_EXTRA
        crc0 = struct.unpack("<H", frame0[-2:])[0]
        return bytearray(frame0), crc0, self.table(after)

    @staticmethod
    def frame(prepared, seq):
        buf, crc0, table = prepared
        buf[4] = seq
        struct.pack_into("<H", buf, len(buf) - 2, crc0 ^ table[seq])
        return bytes(buf)


def self_check(m, peers):
    """The patched frames are pymavlink's packing at that sequence number."""
    patch = SeqPatch()
    for i in (0, 1, peers // 2, peers - 1):
        sysid, compid = identity(i)
        for kind, msg in messages(m, i).items():
            prepared = patch.prepare(pack(m, msg, sysid, compid, 0))
            for seq in (0, 1, 77, 255):
                if SeqPatch.frame(prepared, seq) != pack(m, msg, sysid, compid, seq):
                    raise SystemExit("self-check: patched %s of peer %d at seq %d differs from pymavlink"
                                     % (kind, i, seq))


def peer_proc(first, count, rate, router_port, start_at, stop_at, out):
    """Peers first..first+count-1: each sends `rate` frames a second from its own socket and
    counts what it receives."""
    m = mav()
    patch = SeqPatch()
    kinds = cycle(rate)
    socks, prepared = [], []
    sel = selectors.DefaultSelector()
    for j in range(count):
        i = first + j
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.bind(("127.0.0.1", 0))
        s.setblocking(False)
        sel.register(s, selectors.EVENT_READ, j)
        socks.append(s)
        sysid, compid = identity(i)
        msgs = messages(m, i)
        prepared.append({k: patch.prepare(pack(m, msgs[k], sysid, compid, 0)) for k in set(kinds)})
    sent = [0] * count
    got = [dict(hb=0, cmd=0, wrong_cmd=0, other=0, foreign=0, stray=0) for _ in range(count)]
    mine = [identity(first + j) for j in range(count)]
    router = ("127.0.0.1", router_port)
    period = 1.0 / rate
    while time.time() < start_at:
        time.sleep(0.01)
    t0 = time.monotonic()
    end = t0 + (stop_at - time.time())
    send_errors = 0
    # Peer j sends its k-th frame at t0 + k * period + j * period / count: spread evenly.
    k = 0
    while True:
        now = time.monotonic()
        if now >= end:
            break
        due = t0 + k * period
        for j in range(count):
            at = due + j * period / count
            if at > now:
                # read while waiting for the next send
                drain(sel, socks, got, mine, router)
                now = time.monotonic()
                if at > now:
                    time.sleep(at - now)
            try:
                socks[j].sendto(SeqPatch.frame(prepared[j][kinds[k % rate]], sent[j] & 0xFF), router)
                sent[j] += 1
            except (BlockingIOError, OSError):
                send_errors += 1
        k += 1
    # What is still on its way.
    quiet_until = time.monotonic() + 3.0
    while time.monotonic() < quiet_until:
        drain(sel, socks, got, mine, router)
        time.sleep(0.05)
    out.put({"first": first, "sent": sent, "got": got, "send_errors": send_errors})


def drain(sel, socks, got, mine, router):
    for key, _ in sel.select(timeout=0):
        j = key.data
        while True:
            try:
                data, addr = socks[j].recvfrom(4096)
            except (BlockingIOError, InterruptedError):
                break
            if addr != router:
                # Not the router's doing: on a busy machine another test's link may still be
                # sending to a port this socket was given after that test let it go.
                got[j]["stray"] += 1
                continue
            for sysid, compid, msgid, payload in frames(data):
                g = got[j]
                if (sysid, compid) != (GCS_SYS, GCS_COMP):
                    g["foreign"] += 1
                elif msgid == 0:
                    g["hb"] += 1
                elif msgid == 76:
                    # COMMAND_LONG's target_system, target_component follow its 7 floats and u16.
                    t = (payload[30], payload[31]) if len(payload) >= 32 else (0, 0)
                    if t == mine[j]:
                        g["cmd"] += 1
                    else:
                        g["wrong_cmd"] += 1
                else:
                    g["other"] += 1


def frames(data):
    """(sysid, compid, msgid, payload) of each MAVLink 2 frame of a datagram (by its header)."""
    p, n = 0, len(data)
    while p + 12 <= n and data[p] == 0xFD:
        plen = data[p + 1]
        signed = data[p + 2] & 1
        msgid = data[p + 7] | (data[p + 8] << 8) | (data[p + 9] << 16)
        yield data[p + 5], data[p + 6], msgid, data[p + 10:p + 10 + plen]
        p += 12 + plen + (13 if signed else 0)


def gcs_proc(sock, peers, start_at, cmd_at, stop_at, out):
    """The ground station: counts every frame per peer, parses a sample with pymavlink, sends a
    HEARTBEAT a second and one COMMAND_LONG to each peer."""
    m = mav()
    link = m.MAVLink(None, srcSystem=GCS_SYS, srcComponent=GCS_COMP)
    parser = m.MAVLink(None)
    parser.robust_parsing = True
    counts = [0] * peers
    strangers = strays = 0
    datagrams = 0
    sampled = sampled_frames = sample_bad = 0
    router = None
    sock.settimeout(0.05)
    next_hb = start_at
    cmds_sent = 0
    end = stop_at + 4.0
    while time.time() < end:
        try:
            data, addr = sock.recvfrom(65536)
        except socket.timeout:
            data = None
        now = time.time()
        if data is not None and router is None and any(
                0 <= peer_of(sy, co) < peers and identity(peer_of(sy, co)) == (sy, co)
                for sy, co, _, _ in frames(data)):
            router = addr
        if data is not None and addr != router:
            # Not from the router (see drain): counted, not judged.
            strays += 1
            data = None
        if data is not None:
            datagrams += 1
            n = 0
            for sysid, compid, msgid, _ in frames(data):
                n += 1
                i = peer_of(sysid, compid)
                if 0 <= i < peers and identity(i) == (sysid, compid):
                    counts[i] += 1
                else:
                    strangers += 1
            if datagrams % 64 == 1:
                sampled += 1
                msgs = parser.parse_buffer(data) or []
                sampled_frames += n
                sample_bad += n - len([x for x in msgs if x.get_type() != "BAD_DATA"])
        if router is not None and now >= next_hb and now < stop_at:
            sock.sendto(m.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(link), router)
            next_hb += 1.0
        if router is not None and now >= cmd_at and cmds_sent < peers and now < stop_at:
            # A thousand commands over about a second.
            due = min(peers, int((now - cmd_at) * peers) + 1)
            while cmds_sent < due:
                sysid, compid = identity(cmds_sent)
                msg = m.MAVLink_command_long_message(sysid, compid, 511, 0, 33, 100000, 0, 0, 0, 0, 0)
                sock.sendto(msg.pack(link), router)
                cmds_sent += 1
    out.put({"counts": counts, "strangers": strangers, "strays": strays, "datagrams": datagrams, "sampled": sampled,
             "sampled_frames": sampled_frames, "sample_bad": sample_bad, "cmds_sent": cmds_sent,
             "hb_sent": int(min(stop_at, time.time()) - start_at)})


def proc_cpu(pid):
    with open("/proc/%d/stat" % pid) as f:
        rest = f.read().rsplit(")", 1)[1].split()
    return (int(rest[11]) + int(rest[12])) / CLK_TCK


def proc_rss(pid):
    with open("/proc/%d/statm" % pid) as f:
        return int(f.read().split()[1]) * PAGE


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--peers", type=int, default=1000)
    ap.add_argument("--rate", type=int, default=20, help="frames a second per peer")
    ap.add_argument("--seconds", type=float, default=30.0, help="the measurement, after a 5 s start")
    ap.add_argument("--procs", type=int, default=4, help="processes the peers are spread over")
    ap.add_argument("--no-isolate", action="store_true", help="leave isolate_peers off (the drones hear each other)")
    a = ap.parse_args()
    if not 1 <= a.peers <= 250 * 255 or a.rate < 2:
        ap.error("--peers 1-63750, --rate from 2")
    m = mav()
    self_check(m, a.peers)

    fleet, gcs_port = free_port(), free_port()
    gcs_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs_sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 16 << 20)
    gcs_sock.bind(("127.0.0.1", gcs_port))
    opts = "name=fleet&max_peers=%d" % a.peers + ("" if a.no_isolate else "&isolate_peers=true")
    cmd = [a.mavstack, "router", "udpin:127.0.0.1:%d?%s" % (fleet, opts),
           "udpout:127.0.0.1:%d?name=gcs&pack=true" % gcs_port,
           "--stats", "%g" % max(0.5, min(5.0, a.seconds / 4))]
    print("router:", " ".join(cmd), flush=True)
    router = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stats = []
    threading.Thread(target=lambda: [stats.append(json.loads(ln)) for ln in router.stdout if ln.startswith("{")],
                     daemon=True).start()
    err_tail = []
    threading.Thread(target=lambda: [err_tail.append(ln) for ln in router.stderr], daemon=True).start()
    try:
        deadline = time.time() + 30
        while not err_tail and time.time() < deadline and router.poll() is None:
            time.sleep(0.05)
        time.sleep(0.5)
        rss_idle = proc_rss(router.pid)
        warm = 5.0
        start_at = time.time() + 1.0
        measure_at = start_at + warm
        stop_at = measure_at + a.seconds
        q = mp.Queue()
        per = [a.peers // a.procs + (1 if p < a.peers % a.procs else 0) for p in range(a.procs)]
        procs, first = [], 0
        for n in per:
            procs.append(mp.Process(target=peer_proc, args=(first, n, a.rate, fleet, start_at, stop_at, q)))
            first += n
        gq = mp.Queue()
        gcs = mp.Process(target=gcs_proc, args=(gcs_sock, a.peers, start_at, measure_at + 1.0, stop_at, gq))
        for p in procs + [gcs]:
            p.start()
        samples = []
        while time.time() < measure_at:
            time.sleep(0.1)
        cpu0, rss0, t0 = proc_cpu(router.pid), proc_rss(router.pid), time.monotonic()
        stats_at_start = len(stats)
        while time.time() < stop_at:
            time.sleep(0.5)
            samples.append(proc_rss(router.pid))
        cpu1, rss1, t1 = proc_cpu(router.pid), proc_rss(router.pid), time.monotonic()
        results = [q.get(timeout=120) for _ in procs]
        g = gq.get(timeout=120)
        for p in procs + [gcs]:
            p.join(timeout=30)
        stats_in_run = stats[stats_at_start:]
    finally:
        if router.poll() is None:
            router.send_signal(signal.SIGTERM)
            try:
                router.wait(timeout=30)
            except subprocess.TimeoutExpired:
                router.kill()
        gcs_sock.close()

    sent = [0] * a.peers
    foreign = hb = cmd_ok = wrong = other = send_errors = strays = 0
    missing_cmd = missing_hb = 0
    for r in results:
        send_errors += r["send_errors"]
        for j, (s, gt) in enumerate(zip(r["sent"], r["got"])):
            sent[r["first"] + j] = s
            foreign += gt["foreign"]
            strays += gt["stray"]
            hb += gt["hb"]
            cmd_ok += gt["cmd"]
            wrong += gt["wrong_cmd"]
            other += gt["other"]
            missing_cmd += gt["cmd"] != 1
            missing_hb += gt["hb"] < g["hb_sent"] - 1
    lost = [s - c for s, c in zip(sent, g["counts"])]
    total_sent = sum(sent)
    window = t1 - t0
    fwd_per_s = total_sent / (stop_at - start_at)
    cpu = (cpu1 - cpu0) / window

    print()
    print("peers %d x %d frames/s, measured %.0f s after a %.0f s start, %d peer processes"
          % (a.peers, a.rate, window, warm, a.procs))
    print("frames sent by the peers   %d (%d send errors)" % (total_sent, send_errors))
    print("reached the ground station %d in %d datagrams (%.1f frames each); lost %d, duplicated %d"
          % (sum(g["counts"]), g["datagrams"], sum(g["counts"]) / max(1, g["datagrams"]),
             sum(x for x in lost if x > 0), -sum(x for x in lost if x < 0)))
    print("pymavlink sample           %d datagrams, %d frames, %d not parsed"
          % (g["sampled"], g["sampled_frames"], g["sample_bad"]))
    print("drones got                 %d ground-station HEARTBEATs (sent %d each), %d of %d commands,"
          " %d misrouted, %d frames of other drones"
          % (hb, g["hb_sent"], cmd_ok, g["cmds_sent"], wrong, foreign))
    print("router CPU                 %.3f cores = %.1f us per second per link, %.2f us per frame in"
          % (cpu, cpu * 1e6 / a.peers, cpu * 1e6 / fwd_per_s))
    print("router memory (RSS)        idle %.1f MiB, fleet on %.1f MiB (%.1f KiB per link), end %.1f MiB,"
          " peak %.1f MiB" % (rss_idle / 2**20, rss0 / 2**20, (rss0 - rss_idle) / 1024 / a.peers,
                              rss1 / 2**20, max(samples + [rss1]) / 2**20))
    if strays or g["strays"]:
        print("not from the router        %d datagrams at the drones, %d at the ground station (ignored)"
              % (strays, g["strays"]))
    for s in stats_in_run[-1:]:
        fleet_links = [x for x in s["links"] if x["name"] == "fleet" and x.get("peer")]
        print("--stats                    %d links (%d of the fleet), %d routes, %d systems"
              % (len(s["links"]), len(fleet_links), len(s["routes"]), len(s["systems"])))

    check(send_errors == 0, "%d sends failed at the peers" % send_errors)
    check(all(x == 0 for x in lost),
          "frames lost or duplicated on the way to the ground station: %d peers, e.g. %s"
          % (sum(1 for x in lost if x), [(i, x) for i, x in enumerate(lost) if x][:5]))
    check(g["strangers"] == 0, "%d frames of unknown sources at the ground station" % g["strangers"])
    check(g["sample_bad"] == 0, "pymavlink did not parse %d frames of the sample" % g["sample_bad"])
    check(g["cmds_sent"] == a.peers, "the ground station sent %d commands of %d" % (g["cmds_sent"], a.peers))
    check(missing_cmd == 0 and wrong == 0,
          "%d drones did not get exactly their command; %d commands reached the wrong drone" % (missing_cmd, wrong))
    check(missing_hb == 0, "%d drones missed ground-station HEARTBEATs" % missing_hb)
    if not a.no_isolate:
        check(foreign == 0, "drones got %d frames of other drones (isolate_peers)" % foreign)
    check(other == 0, "drones got %d other frames of the ground station" % other)
    check(len(stats_in_run) >= 2, "fewer than two --stats objects during the measurement")
    for s in stats_in_run:
        fleet_links = [x for x in s["links"] if x["name"] == "fleet" and x.get("peer")]
        check(len(fleet_links) == a.peers, "--stats at %.0f s: %d fleet links, not %d"
              % (s["t_s"], len(fleet_links), a.peers))
        check(len(s["routes"]) == a.peers + 1, "--stats at %.0f s: %d routes, not %d"
              % (s["t_s"], len(s["routes"]), a.peers + 1))
        check(len(s["systems"]) == a.peers + 1, "--stats at %.0f s: %d systems, not %d"
              % (s["t_s"], len(s["systems"]), a.peers + 1))
    check(rss1 <= rss0 + 16 * 2**20,
          "the router's memory grew during the measurement: %.1f -> %.1f MiB" % (rss0 / 2**20, rss1 / 2**20))
    if failures:
        print("router stderr (last lines):", "".join(err_tail[-10:]), file=sys.stderr)
        sys.exit(1)
    print("ok")


if __name__ == "__main__":
    main()
