#!/usr/bin/env python3
"""Load test of the web API on a busy router (not in CI: about a minute, and it wants the
machine to itself).

    cargo build --release -p mavstack-cli
    .venv/bin/python tests-interop/web_load.py --mavstack target/release/mavstack [--rate 20000] [--seconds 10]

`mavstack router udpin:…?name=in udpout:…?name=out --http 127.0.0.1:PORT` carries a stream of
SYSTEM_TIME frames (each numbered in `time_boot_ms`) from a sender process to a receiver
process at --rate frames a second. Three phases of --seconds each, a fresh router for each:

  plain    no --http
  idle     --http, no client
  clients  --http and 50 WebSocket clients on /ws/mavlink: 45 read everything as fast as
           they can, 5 never read (their receive buffers 4 KiB: the server's sends to them
           stall at once)

Measured per phase: frames received / sent, the forwarding rate (frames received over the
time between the first and the last), the latency from the sender's send to the receiver's
read (p50, p99, max; both processes read CLOCK_MONOTONIC), the router's CPU seconds and its
resident memory (sampled every 0.2 s: at a quarter of the run, at its end, the peak), and for
`clients` the web counters (`frames`, `ws_dropped`) and the bytes the reading clients got.
Prints one table; exit 1 when the clients phase loses more frames than the plain one by over
0.5 % of those sent, or its memory at the end exceeds the quarter-way mark by over 64 MiB
(memory that grows with the run instead of staying bounded).
"""

import argparse
import json
import multiprocessing
import os
import socket
import struct
import subprocess
import sys
import threading
import time
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from ws_min import WebSocket  # noqa: E402

# The sender and receiver inherit the frames and the bound socket: fork, on every Python.
mp = multiprocessing.get_context("fork")
MSG_ID = 2  # SYSTEM_TIME: time_unix_usec u64, time_boot_ms u32
CRC_EXTRA = 137


def x25(data, crc=0xFFFF):
    for b in data:
        tmp = b ^ (crc & 0xFF)
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def frame(i):
    """MAVLink 2 SYSTEM_TIME from 7/1, numbered i (time_boot_ms), never truncated."""
    payload = struct.pack("<QI", 0x0102030405060708, i)
    header = struct.pack("<BBBBBBB", len(payload), 0, 0, i & 0xFF, 7, 1, MSG_ID) + b"\x00\x00"
    crc = x25(bytes([CRC_EXTRA]), x25(header + payload))
    return b"\xfd" + header + payload + struct.pack("<H", crc)


def free_port(kind=socket.SOCK_DGRAM):
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def sender(port, frames, rate, out):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.connect(("127.0.0.1", port))
    sent = [0] * len(frames)
    burst = max(1, rate // 1000)
    start = time.monotonic_ns()
    for k in range(0, len(frames), burst):
        due = start + (k * 1_000_000_000) // rate
        while time.monotonic_ns() < due:
            pass
        for i in range(k, min(k + burst, len(frames))):
            sent[i] = time.monotonic_ns()
            try:
                s.send(frames[i])
            except OSError:
                pass
    out.put(sent)


def receiver(sock, n, out, ready):
    sock.settimeout(3.0)
    got = {}
    buf = bytearray(2048)
    ready.set()
    while len(got) < n:
        try:
            size = sock.recv_into(buf)
        except OSError:
            break
        t = time.monotonic_ns()
        if size >= 22 and buf[7] == MSG_ID:
            (i,) = struct.unpack_from("<I", buf, 18)
            got.setdefault(i, t)
    out.put(got)


def sample(pid, stop, samples):
    while not stop.is_set():
        try:
            with open("/proc/%d/status" % pid) as f:
                rss = next(int(l.split()[1]) for l in f if l.startswith("VmRSS"))
            samples.append((time.monotonic(), rss))
        except (OSError, StopIteration):
            break
        time.sleep(0.2)


def cpu_seconds(pid):
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Reader(threading.Thread):
    def __init__(self, ws):
        super().__init__(daemon=True)
        self.ws, self.bytes, self.stop = ws, 0, False

    def run(self):
        try:
            while not self.stop:
                chunk = self.ws.sock.recv(1 << 16)
                if not chunk:
                    break
                self.bytes += len(chunk)
        except OSError:
            pass


def stalled_client(port):
    """A WebSocket client that never reads, with a 4 KiB receive buffer."""
    ws = WebSocket.__new__(WebSocket)
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    key = "dGhlIHNhbXBsZSBub25jZQ=="
    sock.sendall(("GET /ws/mavlink HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nUpgrade: websocket\r\n"
                  "Connection: Upgrade\r\nSec-WebSocket-Key: %s\r\nSec-WebSocket-Version: 13\r\n\r\n"
                  % (port, key)).encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(1)
    assert b" 101 " in head.split(b"\r\n")[0], head
    ws.sock = sock
    return ws


def phase(bin_, name, rate, seconds, frames):
    in_port, http = free_port(), free_port(socket.SOCK_STREAM)
    recv_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    recv_sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    recv_sock.bind(("127.0.0.1", 0))
    out_port = recv_sock.getsockname()[1]
    args = [bin_, "router", "udpin:127.0.0.1:%d?name=in" % in_port, "udpout:127.0.0.1:%d?name=out" % out_port]
    if name != "plain":
        args += ["--http", "127.0.0.1:%d" % http]
    router = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    while "ready" not in router.stderr.readline():
        pass
    readers, stalled = [], []
    if name == "clients":
        for _ in range(45):
            r = Reader(WebSocket("127.0.0.1", http, "/ws/mavlink"))
            r.start()
            readers.append(r)
        for _ in range(5):
            stalled.append(stalled_client(http))
    q_send, q_recv = mp.Queue(), mp.Queue()
    ready = mp.Event()
    rx = mp.Process(target=receiver, args=(recv_sock, len(frames), q_recv, ready))
    rx.start()
    ready.wait(10)
    stop = threading.Event()
    samples = []
    sampler = threading.Thread(target=sample, args=(router.pid, stop, samples), daemon=True)
    sampler.start()
    cpu0 = cpu_seconds(router.pid)
    tx = mp.Process(target=sender, args=(in_port, frames, rate, q_send))
    tx.start()
    sent = q_send.get()
    got = q_recv.get()
    tx.join()
    rx.join()
    cpu = cpu_seconds(router.pid) - cpu0
    stop.set()
    sampler.join()
    web = {}
    if name != "plain":
        with urllib.request.urlopen("http://127.0.0.1:%d/api/status" % http, timeout=10) as r:
            web = json.loads(r.read())["web"]
    for r in readers:
        r.stop = True
    for ws in [r.ws for r in readers] + stalled:
        ws.sock.close()
    router.terminate()
    router.wait(10)
    lat = sorted((got[i] - sent[i]) / 1000 for i in got if sent[i])
    span = (max(got.values()) - min(got.values())) / 1e9 if len(got) > 1 else 0
    pct = lambda p: lat[min(len(lat) - 1, int(p * len(lat)))] if lat else float("nan")  # noqa: E731
    rss = [kb for _, kb in samples]
    quarter = rss[len(rss) // 4] if rss else 0
    return {
        "phase": name, "sent": len(frames), "received": len(got),
        "rate": len(got) / span if span else 0, "p50_us": pct(0.50), "p99_us": pct(0.99), "max_us": lat[-1] if lat else 0,
        "cpu_s": cpu, "rss_quarter_mib": quarter / 1024, "rss_end_mib": (rss[-1] if rss else 0) / 1024,
        "rss_peak_mib": max(rss or [0]) / 1024, "web": web,
        "client_bytes": sum(r.bytes for r in readers),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--rate", type=int, default=20000)
    ap.add_argument("--seconds", type=float, default=10.0)
    a = ap.parse_args()
    frames = [frame(i) for i in range(int(a.rate * a.seconds))]
    results = [phase(a.mavstack, name, a.rate, a.seconds, frames) for name in ("plain", "idle", "clients")]
    print("%-8s %8s %8s %9s %8s %8s %8s %6s %8s %8s %8s" % (
        "phase", "sent", "recv", "rate/s", "p50 µs", "p99 µs", "max µs", "cpu s", "rss¼ MiB", "rss end", "rss max"))
    for r in results:
        print("%-8s %8d %8d %9.0f %8.0f %8.0f %8.0f %6.2f %8.1f %8.1f %8.1f" % (
            r["phase"], r["sent"], r["received"], r["rate"], r["p50_us"], r["p99_us"], r["max_us"], r["cpu_s"],
            r["rss_quarter_mib"], r["rss_end_mib"], r["rss_peak_mib"]))
    c = results[2]
    print("clients: web %s; the 45 reading clients got %.1f MiB" % (json.dumps(c["web"]), c["client_bytes"] / 2**20))
    failures = []
    plain_lost = results[0]["sent"] - results[0]["received"]
    clients_lost = c["sent"] - c["received"]
    if clients_lost - plain_lost > 0.005 * c["sent"]:
        failures.append("with clients the router lost %d frames, %d without --http" % (clients_lost, plain_lost))
    if c["rss_end_mib"] - c["rss_quarter_mib"] > 64:
        failures.append("memory grew from %.1f to %.1f MiB" % (c["rss_quarter_mib"], c["rss_end_mib"]))
    for f in failures:
        print("FAIL", f)
    print("web_load: %s" % ("ok" if not failures else "%d failures" % len(failures)))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
