#!/usr/bin/env python3
"""Log download (LOG_*) interoperability: mavstack's log server and client against
independent peers.

    log_interop.py --mavstack target/debug/mavstack [--big-kib 1024] [--steps abcde]

The logs are files of 1, 90, 91 bytes and --big-kib KiB (random, seeded) served by
`mavstack vehicle tcpin:... --log-dir DIR` as ids 1 to 4 (name order). Empty logs are not
tried: ArduPilot never lists one.

a. MAVProxy 1.8.75's log module (headless, in a pseudo-terminal, `--default-modules=log`):
   `log list` shows the four logs with their sizes, `log download ID FILE` writes each, and
   the files equal the originals (MAVProxy asks for 0xFFFFFFFF bytes from 0 and, when the
   stream has gone quiet for 0.7 s, for the gaps or the rest: the 90-byte log ends with the
   count-0 chunk it gets for asking beyond the end).
b. pymavlink 2.4.50 doing the protocol itself: LOG_REQUEST_LIST (num_logs, last_log_num,
   ids, sizes), LOG_REQUEST_DATA of every log (gaps asked for again after 1 s of quiet);
   the server's answers to a range (95, 100 bytes: chunks at 95 and 185), to a request at the
   end (one chunk of count 0), to an id it does not have (nothing), to LOG_REQUEST_END in the
   middle of a stream (it stops); every LOG_DATA has count <= 90 and zeros after its bytes.
c. MAVSDK 4.1.0's log_files plugin (the native binding): get_entries, download_log_file of
   every log, the files compared.
d. `mavstack log download --all --via log` against a log server written here with pymavlink
   (HEARTBEAT as an ArduPilot copter, LOG_ENTRY per log, LOG_DATA streamed for each
   LOG_REQUEST_DATA, a new request replacing the old, LOG_REQUEST_END stopping it) that drops
   20 % of its LOG_DATA (seeded): every gap must be asked for again, the files equal.
e. `mavstack log list` and `mavstack log download --all` against `mavstack vehicle`, by
   LOG_REQUEST_DATA (`--via log`) and over MAVFTP (`--via ftp`, `/APM/LOGS/0000000N.BIN`),
   and `--via auto` choosing LOG_REQUEST_DATA first.

One `ok ...` or `FAIL ...` line per check, a `throughput` line per download (bytes, seconds,
KiB/s) and a summary; exit status 1 if anything failed. A peer that cannot be imported or
run is a FAIL, never a skip.
"""

import argparse
import asyncio
import json
import os
import random
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback

os.environ["MAVLINK20"] = "1"
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from interop_checks import (  # noqa: E402
    Proc, Results, diff_bytes, free_port, quiet_mavsdk, read, show_mavsdk_log,
)

CHUNK = 90


# ---------------------------------------------------------------- results

R = Results()


def make_logs(base, big_kib, seed=11):
    """The log directory: ids 1-4 in name order. Returns (dir, {id: bytes})."""
    rng = random.Random(seed)
    d = os.path.join(base, "logs")
    os.makedirs(d)
    files = [("1-one.bin", b"\x5a"),
             ("2-ninety.bin", rng.randbytes(90)),
             ("3-ninety-one.bin", rng.randbytes(91)),
             ("4-big.bin", rng.randbytes(int(big_kib * 1024)))]
    logs = {}
    for i, (name, data) in enumerate(files, start=1):
        with open(os.path.join(d, name), "wb") as f:
            f.write(data)
        logs[i] = data
    return d, logs


# ---------------------------------------------------------------- processes

def start_vehicle(binary, port, logdir, work):
    cmd = [binary, "vehicle", f"tcpin:127.0.0.1:{port}", "--log-dir", logdir,
           "--start-mavlink2", "-v"]
    v = Proc(cmd, os.path.join(work, "vehicle.log"))
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        if not v.alive():
            raise RuntimeError(f"vehicle exited {v.p.returncode}: {v.tail()}")
        try:
            with socket.create_connection(("127.0.0.1", port), 0.5):
                return v
        except OSError:
            time.sleep(0.1)
    raise RuntimeError(f"vehicle not listening on {port}: {v.tail()}")


# ---------------------------------------------------------------- a: MAVProxy

def mavproxy_steps(port, logs, work):
    tag = "a mavproxy→mavstack"
    try:
        import pexpect
    except Exception as e:  # noqa: BLE001
        R.fail(f"{tag}: import pexpect", f"{type(e).__name__}: {e}")
        return
    exe = os.path.join(os.path.dirname(sys.executable), "mavproxy.py")
    if not R.check(f"{tag}: MAVProxy installed", os.path.exists(exe), f"no {exe}"):
        return
    state = os.path.join(work, "mavproxy-state")
    os.makedirs(state)
    out_path = os.path.join(work, "mavproxy.out")
    out = open(out_path, "w")  # noqa: SIM115
    env = dict(os.environ, HOME=work, TERM="dumb", PYTHONUNBUFFERED="1")
    args = [exe, f"--master=tcp:127.0.0.1:{port}", f"--state-basedir={state}",
            "--aircraft=gcs", "--default-modules=log"]
    p = pexpect.spawn(sys.executable, args, cwd=work, env=env, encoding="utf-8",
                      codec_errors="replace", timeout=30, maxread=65536,
                      searchwindowsize=None)
    p.logfile_read = out

    def tail():
        out.flush()
        return read(out_path).decode(errors="replace")[-2000:]

    def expect(pattern, timeout, what):
        try:
            p.expect(pattern, timeout=timeout)
            return p.match
        except (pexpect.TIMEOUT, pexpect.EOF) as e:
            raise RuntimeError(f"{what}: MAVProxy did not print /{pattern}/ within "
                               f"{timeout} s ({type(e).__name__}); its output: {tail()}") \
                from None

    try:
        expect(r"Detected vehicle 1:1", 30, "connect")
        R.ok(f"{tag}: MAVProxy connected over TCP")
        p.sendline("log list")
        listed = {}
        while len(listed) < len(logs):
            m = expect(r"Log (\d+)\s+numLogs (\d+) lastLog (\d+) size (\d+)", 30, "log list")
            listed[int(m.group(1))] = (int(m.group(2)), int(m.group(3)), int(m.group(4)))
        want = {i: (len(logs), len(logs), len(d)) for i, d in logs.items()}
        R.check(f"{tag}: log list (id: num_logs, last_log, size)", listed == want,
                f"got {listed}, want {want}")
        for i, data in logs.items():
            path = os.path.join(work, f"mavproxy-log{i}.bin")
            name = f"{tag}: log download {i} ({len(data)} bytes)"
            t = time.monotonic()
            p.sendline(f"log download {i} {path}")
            m = expect(rf"Finished downloading {re.escape(path)} \((\d+) bytes ([\d.]+) seconds, "
                       rf"([\d.]+) kbyte/sec (\d+) retries\)", 60 + len(data) / 20_000, name)
            dt = time.monotonic() - t
            got = read(path) if os.path.exists(path) else None
            if R.check(name, got == data, diff_bytes(got, data)):
                R.rate(f"{tag} log {i} ({len(data)} bytes, {m.group(4)} MAVProxy retries)",
                       len(data), dt)
    finally:
        if p.isalive():
            p.terminate(force=True)
        out.close()


# ---------------------------------------------------------------- b: pymavlink by hand

def pymavlink_steps(port, logs):
    tag = "b pymavlink→mavstack"
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=255,
                                   source_component=190)
    try:
        hb = m.wait_heartbeat(timeout=15)
        if not R.check(f"{tag}: heartbeat", hb is not None, "none in 15 s"):
            return
        chunks_seen = []

        def recv(kind, timeout):
            msg = m.recv_match(type=kind, blocking=True, timeout=timeout)
            if msg is not None and msg.get_type() == "LOG_DATA":
                chunks_seen.append(msg)
            return msg

        def drain(seconds):
            got = []
            end = time.monotonic() + seconds
            while True:
                left = end - time.monotonic()
                if left <= 0:
                    return got
                msg = recv("LOG_DATA", left)
                if msg is not None:
                    got.append(msg)

        # The list.
        m.mav.log_request_list_send(1, 1, 0, 0xFFFF)
        entries = {}
        deadline = time.monotonic() + 10
        while len(entries) < len(logs) and time.monotonic() < deadline:
            e = recv("LOG_ENTRY", 1.0)
            if e is not None:
                entries[e.id] = (e.num_logs, e.last_log_num, e.size)
        want = {i: (len(logs), len(logs), len(d)) for i, d in logs.items()}
        R.check(f"{tag}: LOG_ENTRY per log (num_logs, last_log_num, size)", entries == want,
                f"got {entries}, want {want}")

        # Every log, asked whole; after 1 s of quiet the first missing byte onwards.
        for i, data in logs.items():
            name = f"{tag}: LOG_REQUEST_DATA log {i} ({len(data)} bytes)"
            got = {}
            have = 0
            asks = 1
            t = time.monotonic()
            m.mav.log_request_data_send(1, 1, i, 0, 0xFFFFFFFF)
            while have < len(data):
                msg = recv("LOG_DATA", 1.0)
                if msg is None:
                    first = next(o for o in range(0, len(data), CHUNK) if o not in got)
                    asks += 1
                    if asks > 20:
                        break
                    m.mav.log_request_data_send(1, 1, i, first, len(data) - first)
                    continue
                if msg.id != i or msg.ofs in got or msg.count == 0:
                    continue
                got[msg.ofs] = bytes(msg.data[:msg.count])
                have += msg.count
            dt = time.monotonic() - t
            joined = b"".join(got[o] for o in sorted(got))
            if R.check(name, joined == data, f"{diff_bytes(joined, data)} after {asks} requests"):
                R.rate(f"{tag} log {i} ({len(data)} bytes, {asks} requests)", len(data), dt)
            drain(0.2)

        big_id = max(logs, key=lambda k: len(logs[k]))
        big = logs[big_id]
        # A range: chunks at 95 (90 bytes) and 185 (10 bytes), nothing after.
        m.mav.log_request_data_send(1, 1, big_id, 95, 100)
        got = [(x.ofs, x.count, bytes(x.data[:x.count])) for x in drain(0.5)]
        R.check(f"{tag}: a range (95, 100) comes as chunks at 95 and 185",
                got == [(95, 90, big[95:185]), (185, 10, big[185:195])],
                f"got {[(o, c) for o, c, _ in got]}")
        # At the end: one chunk of count 0.
        m.mav.log_request_data_send(1, 1, big_id, len(big), 90)
        got = [(x.id, x.ofs, x.count) for x in drain(0.5)]
        R.check(f"{tag}: a request at the end gets one chunk of count 0",
                got == [(big_id, len(big), 0)], f"got {got}")
        # An id the vehicle does not have: nothing.
        m.mav.log_request_data_send(1, 1, 99, 0, 0xFFFFFFFF)
        got = drain(1.0)
        R.check(f"{tag}: an unknown id gets nothing", not got, f"got {len(got)} LOG_DATA")
        # LOG_REQUEST_END stops a stream: what was on the way still comes (the vehicle's
        # queue, the sockets' buffers), then a second of silence, well before the rest of
        # the log (over 11,000 chunks, 6 s at the vehicle's pace) could have come.
        m.mav.log_request_data_send(1, 1, big_id, 0, 0xFFFFFFFF)
        first = [x for x in (recv("LOG_DATA", 2.0) for _ in range(20)) if x is not None]
        m.mav.log_request_end_send(1, 1)
        after = 0
        quiet = False
        until = time.monotonic() + 4.0
        while time.monotonic() < until:
            if recv("LOG_DATA", 1.0) is None:
                quiet = True
                break
            after += 1
        rest = (len(big) + CHUNK - 1) // CHUNK - len(first)
        R.check(f"{tag}: LOG_REQUEST_END stops the stream",
                len(first) == 20 and quiet and after < rest // 4,
                f"{len(first)} before, {after} after (quiet: {quiet}) of {rest} left")
        bad = [(x.ofs, x.count) for x in chunks_seen
               if x.count > CHUNK or any(x.data[x.count:])]
        R.check(f"{tag}: every LOG_DATA ({len(chunks_seen)}) has count <= 90, zeros after",
                not bad, f"bad: {bad[:5]}")
    finally:
        m.close()


# ---------------------------------------------------------------- c: MAVSDK



async def mavsdk_steps(port, logs, work):
    tag = "c mavsdk→mavstack"
    try:
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
        from mavsdk.asyncio.plugins.log_files import LogFilesAsync
    except Exception as e:  # noqa: BLE001
        R.fail(f"{tag}: import mavsdk log_files", f"{type(e).__name__}: {e}")
        return
    cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    mav = Mavsdk(cfg)
    try:
        await mav.add_any_connection(f"tcpout://127.0.0.1:{port}")
        system = await mav.first_autopilot(timeout_s=15)
        if not R.check(f"{tag}: first_autopilot", system is not None, "none within 15 s"):
            return
        R.ok(f"{tag}: MAVSDK {await mav.version()}")
        lf = LogFilesAsync(system)
        entries = await asyncio.wait_for(lf.get_entries(), 30)
        got = {e.id: e.size_bytes for e in entries}
        want = {i: len(d) for i, d in logs.items()}
        R.check(f"{tag}: get_entries (id: size)", got == want, f"got {got}, want {want}")
        for e in entries:
            data = logs.get(e.id)
            if data is None:
                continue
            path = os.path.join(work, f"mavsdk-log{e.id}.bin")
            name = f"{tag}: download_log_file {e.id} ({len(data)} bytes)"
            t = time.monotonic()

            async def run(entry=e, path=path):
                last = None
                async for result, progress in lf.download_log_file(entry, path):
                    last = (result, progress)
                return last

            try:
                await asyncio.wait_for(run(), 60 + len(data) / 20_000)
            except Exception as ex:  # noqa: BLE001
                R.fail(name, f"{type(ex).__name__}: {ex}")
                continue
            dt = time.monotonic() - t
            got = read(path) if os.path.exists(path) else None
            if R.check(name, got == data, diff_bytes(got, data)):
                R.rate(f"{tag} log {e.id} ({len(data)} bytes)", len(data), dt)
        lf.destroy()
    finally:
        mav.destroy()


# ---------------------------------------------------------------- d: a pymavlink log server

class LossyLogServer(threading.Thread):
    """A vehicle (1/1, ArduPilot copter) on `udpin:127.0.0.1:PORT` serving `logs` per the
    protocol, dropping `drop` of its LOG_DATA."""

    def __init__(self, port, logs, drop=0.2, seed=5):
        super().__init__(daemon=True)
        from pymavlink import mavutil

        self.mavutil = mavutil
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1,
                                               source_component=1)
        self.logs = logs
        self.drop = drop
        self.rng = random.Random(seed)
        self.stopping = threading.Event()
        self.entries = []  # LOG_ENTRY left to send
        self.sending = None  # [id, next, end]
        self.stats = {"requests": 0, "lists": 0, "ends": 0, "data_sent": 0, "data_dropped": 0}
        self.error = None

    def stop(self):
        self.stopping.set()
        self.join(5)
        self.conn.close()

    def handle(self, msg):
        kind = msg.get_type()
        if kind in ("LOG_REQUEST_LIST", "LOG_REQUEST_DATA", "LOG_REQUEST_END", "LOG_ERASE") \
                and msg.target_system not in (0, 1):
            return
        if kind == "LOG_REQUEST_LIST":
            self.stats["lists"] += 1
            ids = sorted(self.logs)
            self.sending = None
            self.entries = [i for i in ids if msg.start <= i <= msg.end]
        elif kind == "LOG_REQUEST_DATA":
            self.stats["requests"] += 1
            self.entries = []
            data = self.logs.get(msg.id)
            if data is None:
                self.sending = None
                return
            end = min(len(data), msg.ofs + msg.count)
            self.sending = [msg.id, msg.ofs, max(end, msg.ofs)]
        elif kind == "LOG_REQUEST_END":
            self.stats["ends"] += 1
            self.sending = None
            self.entries = []

    def send_some(self, budget):
        mav = self.conn.mav
        while budget > 0 and self.entries:
            i = self.entries.pop(0)
            mav.log_entry_send(i, len(self.logs), max(self.logs), 1_700_000_000 + i,
                               len(self.logs[i]))
            budget -= 1
        while budget > 0 and self.sending is not None:
            i, at, end = self.sending
            data = self.logs[i]
            piece = data[at:min(end, at + CHUNK)]
            nxt = at + len(piece)
            last = len(piece) < CHUNK or nxt >= end
            self.sending = None if last else [i, nxt, end]
            budget -= 1
            if self.rng.random() < self.drop:
                self.stats["data_dropped"] += 1
                continue
            self.stats["data_sent"] += 1
            mav.log_data_send(i, at, len(piece), piece.ljust(CHUNK, b"\0"))

    def run(self):
        mavutil = self.mavutil
        last_hb = 0.0
        try:
            while not self.stopping.is_set():
                now = time.monotonic()
                if now - last_hb >= 1.0:
                    last_hb = now
                    try:
                        self.conn.mav.heartbeat_send(
                            mavutil.mavlink.MAV_TYPE_QUADROTOR,
                            mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0,
                            mavutil.mavlink.MAV_STATE_STANDBY)
                    except OSError:
                        pass  # no peer yet (udpin learns it from the first datagram)
                while True:
                    msg = self.conn.recv_match(blocking=False)
                    if msg is None:
                        break
                    self.handle(msg)
                try:
                    self.send_some(40)
                except OSError:
                    pass
                time.sleep(0.002)
        except Exception as e:  # noqa: BLE001
            self.error = f"{type(e).__name__}: {e}"


def mavstack_client_vs_lossy_server(binary, logs, work):
    tag = "d mavstack→pymavlink server (20 % LOG_DATA lost)"
    port = free_port(socket.SOCK_DGRAM)
    server = LossyLogServer(port, logs)
    server.start()
    out_dir = os.path.join(work, "d-out")
    try:
        cmd = [binary, "log", "download", f"udpout:127.0.0.1:{port}", "--all", "--via", "log",
               "--out", out_dir, "--json", "--timeout", "15"]
        t = time.monotonic()
        p = subprocess.run(cmd, capture_output=True, timeout=600, check=False)
        dt = time.monotonic() - t
        err = p.stderr.decode(errors="replace")
        if not R.check(f"{tag}: mavstack log download exits 0", p.returncode == 0,
                       f"exit {p.returncode}: {err.strip()[-800:]}"):
            return
        results = {}
        for line in p.stdout.decode(errors="replace").splitlines():
            if line.strip():
                o = json.loads(line)
                results[o["id"]] = o
        for i, data in logs.items():
            path = os.path.join(out_dir, f"log_{i}.bin")
            got = read(path) if os.path.exists(path) else None
            name = f"{tag}: log {i} ({len(data)} bytes)"
            if R.check(name, got == data, diff_bytes(got, data)) and i in results:
                R.rate(f"{tag} log {i} ({len(data)} bytes)", len(data), results[i]["seconds"])
        st = server.stats
        R.check(f"{tag}: gaps were asked for again",
                st["data_dropped"] > 0 and st["requests"] > len(logs),
                f"server: {st}")
        R.check(f"{tag}: the server ran without error", server.error is None, server.error)
        print(f"      server: {json.dumps(st)}; whole command {dt:.2f} s", flush=True)
    finally:
        server.stop()


# ---------------------------------------------------------------- e: mavstack against mavstack

def mavstack_steps(binary, port, logs, work):
    tag = "e mavstack→mavstack"
    conn = f"tcp:127.0.0.1:{port}"
    p = subprocess.run([binary, "log", "list", conn, "--json"], capture_output=True,
                       timeout=60, check=False)
    if R.check(f"{tag}: log list exits 0", p.returncode == 0,
               f"exit {p.returncode}: {p.stderr.decode(errors='replace')[-400:]}"):
        got = {}
        for line in p.stdout.decode().splitlines():
            o = json.loads(line)
            got[o["id"]] = o["size"]
        want = {i: len(d) for i, d in logs.items()}
        R.check(f"{tag}: log list --json (id: size)", got == want, f"got {got}")
    for via, shows in (("log", "log"), ("ftp", "ftp"), ("auto", "log")):
        out_dir = os.path.join(work, f"e-{via}")
        cmd = [binary, "log", "download", conn, "--all", "--via", via, "--out", out_dir,
               "--json"]
        p = subprocess.run(cmd, capture_output=True, timeout=300, check=False)
        if not R.check(f"{tag}: log download --all --via {via} exits 0", p.returncode == 0,
                       f"exit {p.returncode}: {p.stderr.decode(errors='replace')[-600:]}"):
            continue
        results = {}
        for line in p.stdout.decode().splitlines():
            o = json.loads(line)
            results[o["id"]] = o
        for i, data in logs.items():
            path = os.path.join(out_dir, f"log_{i}.bin")
            got = read(path) if os.path.exists(path) else None
            name = f"{tag} --via {via}: log {i} ({len(data)} bytes)"
            how = results.get(i, {}).get("via")
            if R.check(name, got == data and how == shows,
                       f"{diff_bytes(got, data)}, via {how} (want {shows})"):
                R.rate(f"{tag} --via {via} log {i} ({len(data)} bytes)", len(data),
                       results[i]["seconds"])


# ---------------------------------------------------------------- main

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--big-kib", type=float, default=1024)
    ap.add_argument("--steps", default="abcde", help="which of steps a-e to run")
    args = ap.parse_args()
    binary = os.path.abspath(args.mavstack)
    t0 = time.monotonic()
    rc = subprocess.run([binary, "log", "download", "--help"], capture_output=True,
                        check=False).returncode
    if not R.check("mavstack log download exists", rc == 0, f"exits {rc}"):
        return R.summary("log_interop", t0)
    try:
        from pymavlink import mavutil  # noqa: F401
    except Exception as e:  # noqa: BLE001
        R.fail("import pymavlink", f"{type(e).__name__}: {e}")
        return R.summary("log_interop", t0)
    work = tempfile.mkdtemp(prefix="log-interop-")
    vehicle = None
    try:
        logdir, logs = make_logs(work, args.big_kib)
        before = {n: read(os.path.join(logdir, n)) for n in os.listdir(logdir)}
        if set(args.steps) & set("abce"):
            port = free_port()
            vehicle = start_vehicle(binary, port, logdir, work)
            if "a" in args.steps:
                R.guard("a mavproxy", mavproxy_steps, port, logs, work)
            if "b" in args.steps:
                R.guard("b pymavlink", pymavlink_steps, port, logs)
            if "c" in args.steps:
                quiet_mavsdk()
                R.guard("c mavsdk", asyncio.run, mavsdk_steps(port, logs, work))
            if "e" in args.steps:
                R.guard("e mavstack", mavstack_steps, binary, port, logs, work)
            R.check("vehicle still running", vehicle.alive(), vehicle.tail())
        if "d" in args.steps:
            R.guard("d lossy server", mavstack_client_vs_lossy_server, binary, logs, work)
        after = {n: read(os.path.join(logdir, n)) for n in os.listdir(logdir)}
        R.check("the log directory is unchanged", before == after)
    finally:
        if vehicle is not None:
            vehicle.stop()
        if R.failed:
            show_mavsdk_log()
            if vehicle is not None:
                print(f"      vehicle log: {vehicle.tail(20)}", flush=True)
            print(f"      (work directory kept: {work})", flush=True)
        else:
            shutil.rmtree(work, ignore_errors=True)
    return R.summary("log_interop", t0)


if __name__ == "__main__":
    sys.exit(main())
