#!/usr/bin/env python3
"""RTK corrections: `mavstack rtk` against pymavlink as the vehicle.

    rtk_interop.py --mavstack target/debug/mavstack

pymavlink 2.4.50 plays the vehicle (HEARTBEAT of a PX4 quadrotor, system 1 component 1) on
loopback UDP, records every GPS_RTCM_DATA that `mavstack rtk udpout:...` sends, and puts the
messages back together with its own reading of common.xml (fragment id in flags bits 1-2,
sequence id in bits 3-7; a message is whole when every fragment before the first one shorter
than 180 bytes is there, or four full ones are; another sequence id starts over). The RTCM3
stream is made here (CRC-24Q computed here, bitwise):

1. file: frames of 9, 180, 181, 360, 540 and 720 bytes with garbage, a damaged frame and a
   frame of 808 bytes between them, forwarded from a file: every good frame up to 720 bytes
   arrives whole and in order, byte for byte; the 360- and 540-byte ones end with an empty
   fragment, the 720-byte one with four full ones; sequence ids go up by one per message;
   the 808-byte frame (too long for GPS_RTCM_DATA) and the damaged one never arrive;
   mavstack's summary counts them.
2. tcp: the same stream from a TCP server here that sends it in pieces of 1 to 97 bytes and
   closes: the same messages arrive.
3. garbage: 20 kB of random bytes: mavstack exits 1 saying no frame was found, and not one
   GPS_RTCM_DATA reaches the vehicle.

One `ok ...` or `FAIL ...` line per check and a summary; exit status 1 if anything failed.
"""

import argparse
import json
import os
import random
import socket
import subprocess
import sys
import tempfile
import threading
import time

os.environ["MAVLINK20"] = "1"
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from interop_checks import Results, free_port  # noqa: E402
from pymavlink import mavutil  # noqa: E402

R = Results()
FRAGMENT = 180


def crc24q(data):
    crc = 0
    for b in data:
        crc ^= b << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= 0x1864CFB
    return crc & 0xFFFFFF


def frame(payload):
    head = bytes([0xD3, (len(payload) >> 8) & 3, len(payload) & 0xFF]) + payload
    return head + crc24q(head).to_bytes(3, "big")


def rtcm_payload(rng, number, length):
    """A payload of `length` bytes whose first 12 bits are the message number."""
    head = bytes([number >> 4, ((number & 15) << 4) | rng.randrange(16)])
    return head + bytes(rng.randrange(256) for _ in range(length - 2))


def stream(rng):
    """The stream of scenario 1 and the good frames of up to 720 bytes it holds, in order."""
    good = []
    out = bytearray(b"\x00\xffNMEA,$GPGGA,garbage\r\n")
    for number, total in [(1005, 9), (1074, 180), (1084, 181), (1077, 360), (1087, 540),
                          (1097, 720)]:
        f = frame(rtcm_payload(rng, number, total - 6))
        assert len(f) == total
        good.append(f)
        out += f
        if number == 1084:
            damaged = bytearray(frame(rtcm_payload(rng, 1094, 100)))
            damaged[40] ^= 0x10
            out += damaged
        if number == 1087:
            out += frame(rtcm_payload(rng, 1127, 802))  # 808 bytes: too long
            out += bytes(rng.randrange(256) for _ in range(50))
    return bytes(out), good


class Vehicle(threading.Thread):
    """pymavlink as the vehicle: HEARTBEAT twice a second, every GPS_RTCM_DATA recorded."""

    def __init__(self):
        super().__init__(daemon=True)
        self.port = free_port(socket.SOCK_DGRAM)
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.port}",
                                               source_system=1, source_component=1)
        self.raw = []
        self.stop = threading.Event()

    def run(self):
        next_beat = 0.0
        while not self.stop.is_set():
            now = time.monotonic()
            if now >= next_beat:
                self.conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_QUADROTOR,
                                             mavutil.mavlink.MAV_AUTOPILOT_PX4, 0, 0, 3)
                next_beat = now + 0.5
            m = self.conn.recv_match(type="GPS_RTCM_DATA", blocking=True, timeout=0.05)
            if m is not None:
                self.raw.append((m.flags, bytes(m.data[:m.len])))

    def close(self):
        self.stop.set()
        self.join(5)
        self.conn.close()


def reassemble(raw):
    """Whole messages from GPS_RTCM_DATA (flags, bytes), as common.xml describes."""
    out, held, seq = [], {}, None
    for flags, data in raw:
        if not flags & 1:
            out.append(data)
            continue
        fid, s = (flags >> 1) & 3, flags >> 3
        if seq is not None and (s != seq or fid in held):
            held = {}
        seq = s
        held[fid] = data
        short = next((i for i in sorted(held) if len(held[i]) < FRAGMENT), None)
        if short is not None:
            whole = all(i in held for i in range(short + 1))
            count = short + 1
        else:
            whole = len(held) == 4
            count = 4
        if whole:
            out.append(b"".join(held[i] for i in range(count)))
            held, seq = {}, None
    return out


def run_rtk(bin_, port, source, wait=60):
    cmd = [bin_, "rtk", f"udpout:127.0.0.1:{port}", "--from", source, "--json",
           "--timeout", "10"]
    return subprocess.run(cmd, capture_output=True, timeout=wait, check=False)


def settle(vehicle, want):
    """Waits (up to 10 s) until `want` GPS_RTCM_DATA have come, then a little more for strays."""
    end = time.monotonic() + 10
    while len(vehicle.raw) < want and time.monotonic() < end:
        time.sleep(0.05)
    time.sleep(0.3)


def expected_parts(good):
    parts = 0
    for f in good:
        if len(f) <= FRAGMENT:
            parts += 1
        else:
            parts += (len(f) + FRAGMENT - 1) // FRAGMENT + (1 if len(f) % FRAGMENT == 0
                                                            and len(f) < 720 else 0)
    return parts


def check_delivery(name, vehicle, good, proc):
    summary = None
    lines = proc.stdout.decode(errors="replace").strip().splitlines()
    if lines:
        summary = json.loads(lines[-1])
    R.check(f"{name}: mavstack rtk exits 0", proc.returncode == 0,
            f"exit {proc.returncode}: {proc.stderr.decode(errors='replace')[-400:]}")
    settle(vehicle, expected_parts(good))
    got = reassemble(vehicle.raw)
    R.check(f"{name}: {len(good)} messages whole, in order, byte for byte", got == good,
            f"got {[len(g) for g in got]}, want {[len(g) for g in good]}")
    R.check(f"{name}: {expected_parts(good)} GPS_RTCM_DATA in all",
            len(vehicle.raw) == expected_parts(good), f"{len(vehicle.raw)}")
    # Per message: the lengths of its fragments and its sequence id.
    messages, current = [], []
    for flags, data in vehicle.raw:
        current.append((flags, len(data)))
        if not flags & 1 or len(data) < FRAGMENT or len(current) == 4:
            messages.append(current)
            current = []
    lens = [[n for _, n in m] for m in messages]
    R.check(f"{name}: 360 and 540 bytes end with an empty fragment, 720 with four full ones",
            [180, 180, 0] in lens and [180, 180, 180, 0] in lens and [180] * 4 in lens
            and [180] in lens, f"{lens}")
    seqs = [m[0][0] >> 3 for m in messages]
    R.check(f"{name}: one sequence id per message, going up by one",
            all((b - a) % 32 == 1 for a, b in zip(seqs, seqs[1:]))
            and all(len({f >> 3 for f, _ in m}) == 1 for m in messages), f"{seqs}")
    R.check(f"{name}: the 360-byte message's fragments are ids 0, 1, 2",
            any([(f >> 1) & 3 for f, _ in m] == [0, 1, 2] and [n for _, n in m] == [180, 180, 0]
                for m in messages), f"{messages}")
    if summary is not None:
        R.check(f"{name}: mavstack counts 6 frames sent, 1 too long, 1 damaged",
                (summary.get("sent"), summary.get("too_long"), summary.get("damaged"),
                 summary.get("frames")) == (6, 1, 1, 7), f"{summary}")
    else:
        R.fail(f"{name}: mavstack's summary", "no JSON line")


def serve_tcp(data, rng):
    """A TCP server sending `data` in pieces to its first client, then closing; its port."""
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]

    def serve():
        conn, _ = server.accept()
        with conn:
            at = 0
            while at < len(data):
                n = rng.randrange(1, 98)
                conn.sendall(data[at:at + n])
                at += n
                time.sleep(0.001)
        server.close()

    threading.Thread(target=serve, daemon=True).start()
    return port


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mavstack", required=True)
    args = ap.parse_args()
    t0 = time.monotonic()
    rng = random.Random(41)
    data, good = stream(rng)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "base.rtcm3")
        with open(path, "wb") as f:
            f.write(data)

        v = Vehicle()
        v.start()
        try:
            proc = run_rtk(args.mavstack, v.port, path)
            check_delivery("1 file", v, good, proc)
        finally:
            v.close()

        v = Vehicle()
        v.start()
        try:
            port = serve_tcp(data, rng)
            proc = run_rtk(args.mavstack, v.port, f"tcp:127.0.0.1:{port}")
            check_delivery("2 tcp", v, good, proc)
        finally:
            v.close()

        garbage = os.path.join(tmp, "garbage.bin")
        with open(garbage, "wb") as f:
            f.write(bytes(rng.randrange(256) for _ in range(20_000)))
        v = Vehicle()
        v.start()
        try:
            proc = run_rtk(args.mavstack, v.port, garbage)
            err = proc.stderr.decode(errors="replace")
            R.check("3 garbage: mavstack rtk exits 1 saying no frame was found",
                    proc.returncode == 1 and "no RTCM3 frame in 20000 bytes" in err,
                    f"exit {proc.returncode}: {err[-300:]}")
            time.sleep(0.5)
            R.check("3 garbage: no GPS_RTCM_DATA reached the vehicle", not v.raw, f"{v.raw[:3]}")
        finally:
            v.close()
    return R.summary("rtk_interop", t0)


if __name__ == "__main__":
    sys.exit(main())
