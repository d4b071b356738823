#!/usr/bin/env python3
"""`mavstack listen`, `record` and `replay` against pymavlink's mavutil over real sockets.

Usage: link_interop.py SCENARIO --mavstack BIN [--frames N]

Each scenario starts the mavstack command as a subprocess, runs pymavlink's mavutil (the
peer every MAVLink user knows) on the other end over 127.0.0.1, and checks the result
against what pymavlink itself sent or decoded: frames byte for byte, decoded fields with the
same comparison as compare_decode.py (floats as their wire type), tlog timestamps to the
microsecond. Exit 0 when everything matches, 1 with the differences otherwise.

Scenarios:
  udp_listen      pymavlink udpout  -> mavstack listen udpin       (JSON lines == pymavlink's decode)
  udp_replay      mavstack replay udpout -> pymavlink udpin        (bytes == the tlog's frames)
  udpin_reply     pymavlink udpout <-> mavstack replay udpin       (mavstack answers the peer's own address)
  tcp_listen      pymavlink tcpin   -> mavstack listen tcp         (client reconnects until the server is up)
  tcp_replay      mavstack replay tcpin -> pymavlink tcp           (bytes == the tlog's frames)
  record_tlog     pymavlink udpout  -> mavstack record; the tlog read by pymavlink's reader and
                  mavlogdump.py: same frames, same timestamps
  pymavlink_tlog  a tlog written by pymavlink's mavlogfile: `mavstack decode` gives the same
                  frames and timestamps; `mavstack replay` puts the same bytes on the wire
"""

import argparse
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

os.environ["MAVLINK20"] = "1"
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mavinterop as mi  # noqa: E402
import compare_decode as cd  # noqa: E402
from pymavlink import mavutil  # noqa: E402

DIALECT = "ardupilotmega"
MOD = mi.load_dialect(DIALECT)
failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL: " + msg, file=sys.stderr)


from scenario import free_port  # noqa: E402


def messages(mav, n, sysid=7):
    """n different messages (several types, both short and long, strings), packed by
    pymavlink with running sequence numbers; returns the frames' bytes."""
    out = []
    for i in range(n):
        k = i % 5
        if k == 0:
            m = MOD.MAVLink_heartbeat_message(2, 3, 81, i, 4, 3)
        elif k == 1:
            m = MOD.MAVLink_attitude_message(i, 0.1 * i, -0.2, 0.3, 1e-3 * i, 0.5, -0.6)
        elif k == 2:
            m = MOD.MAVLink_global_position_int_message(i, 473977420 + i, 85455940 - i, 500000, 1000, 1, -2, 3, i % 36000)
        elif k == 3:
            m = MOD.MAVLink_statustext_message(6, ("frame %d" % i).encode(), i, 0)
        else:
            m = MOD.MAVLink_param_value_message(("PARAM_%d" % i).encode(), i * 0.25, 9, n, i)
        out.append(bytes(m.pack(mav)))
        mav.seq = (mav.seq + 1) % 256
    return out


def expected_json(frames):
    """pymavlink's decode of frames, as mavstack's JSON objects."""
    data = b"".join(frames)
    objs = []
    for _off, kind, msg in mi.parse_stream(MOD, data):
        if kind != "msg":
            fail("pymavlink could not decode its own frame: %r" % msg)
            continue
        objs.append(mi.message_to_json(msg, False))
    return objs


def compare_lines(expected, actual_lines, what):
    actual = []
    for line in actual_lines:
        line = line.strip()
        if line:
            try:
                actual.append(json.loads(line))
            except ValueError as e:
                fail("%s: invalid JSON line %r: %s" % (what, line[:200], e))
    if len(actual) != len(expected):
        fail("%s: expected %d frames, got %d" % (what, len(expected), len(actual)))
    for i, (e, a) in enumerate(zip(expected, actual)):
        ts = a.pop("ts_us", None) if "ts_us" not in e else None
        del ts
        diffs = cd.compare_obj(MOD, e, a)
        if diffs:
            fail("%s: frame %d (%s): %s" % (what, i, cd.brief(e), "; ".join(diffs[:5])))
            return


def start(cmd, **kw):
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def finish(proc, what, timeout=20):
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        fail("%s: did not finish within %d s; stderr: %s" % (what, timeout, err.strip()[-500:]))
        return out, err
    if proc.returncode != 0:
        fail("%s: exit %d; stderr: %s" % (what, proc.returncode, err.strip()[-500:]))
    return out, err


def write_tlog(path, frames, t0_us, step_us):
    with open(path, "wb") as f:
        for i, fr in enumerate(frames):
            f.write(struct.pack(">Q", t0_us + i * step_us) + fr)


def recv_frames(conn, n, timeout):
    """The raw bytes of the next n messages pymavlink receives on conn."""
    got = []
    deadline = time.time() + timeout
    while len(got) < n and time.time() < deadline:
        m = conn.recv_match(blocking=True, timeout=0.2)
        if m is None or m.get_type() == "BAD_DATA":
            continue
        got.append(bytes(m.get_msgbuf()))
    return got


def udp_listen(bin_, n):
    port = free_port()
    frames = None
    proc = start([bin_, "listen", "udpin:127.0.0.1:%d" % port, "--count", str(n + 1), "--stats"])
    peer = mavutil.mavlink_connection("udpout:127.0.0.1:%d" % port, source_system=7, dialect=DIALECT)
    # Knock until mavstack is listening: a HEARTBEAT every 50 ms until the first line shows
    # (one line only, then the numbered frames).
    knock = bytes(MOD.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(peer.mav))
    os.set_blocking(proc.stdout.fileno(), False)
    first = ""
    deadline = time.time() + 10
    while not first and time.time() < deadline:
        peer.write(knock)
        time.sleep(0.05)
        first = proc.stdout.readline()
    os.set_blocking(proc.stdout.fileno(), True)
    if not first:
        proc.kill()
        fail("udp_listen: mavstack listen printed nothing within 10 s")
        return
    frames = messages(peer.mav, n)
    for fr in frames:
        peer.write(fr)
    out, err = finish(proc, "udp_listen")
    compare_lines(expected_json(frames), out.splitlines(), "udp_listen")
    stats = json.loads(err.strip().splitlines()[-1])
    if stats.get("bad_crc") or stats.get("skipped_bytes"):
        fail("udp_listen: unexpected counters %s" % stats)


def replay_to_pymavlink(bin_, n, peer_spec, our_spec, what, server):
    """mavstack replays a tlog onto our_spec; pymavlink receives on peer_spec."""
    frames = messages(MOD.MAVLink(None, srcSystem=9, srcComponent=1), n)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "in.tlog")
        write_tlog(path, frames, int(time.time() * 1e6), 1000)
        if server:
            # mavstack serves (tcpin): it waits for pymavlink to connect, then sends.
            proc = start([bin_, "replay", path, our_spec, "--speed", "0"])
            time.sleep(0.3)
            peer = connect_with_retry(peer_spec)
        else:
            peer = mavutil.mavlink_connection(peer_spec, dialect=DIALECT)
            proc = start([bin_, "replay", path, our_spec, "--speed", "0"])
        got = recv_frames(peer, n, 15)
        finish(proc, what)
        peer.close()
    if got != frames:
        same = sum(1 for a, b in zip(got, frames) if a == b)
        fail("%s: pymavlink received %d frames, %d equal to the tlog's (of %d)" % (what, len(got), same, n))


def connect_with_retry(spec, timeout=10):
    deadline = time.time() + timeout
    while True:
        try:
            return mavutil.mavlink_connection(spec, dialect=DIALECT, retries=0)
        except Exception:  # noqa: BLE001 (pymavlink raises bare Exceptions)
            if time.time() > deadline:
                raise
            time.sleep(0.1)


def udpin_reply(bin_, n):
    """mavstack serves udpin: pymavlink contacts it from its own port and gets the replay."""
    port = free_port()
    frames = messages(MOD.MAVLink(None, srcSystem=9, srcComponent=1), n)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "in.tlog")
        write_tlog(path, frames, int(time.time() * 1e6), 1000)
        proc = start([bin_, "replay", path, "udpin:127.0.0.1:%d" % port, "--speed", "0"])
        peer = mavutil.mavlink_connection("udpout:127.0.0.1:%d" % port, source_system=7, dialect=DIALECT)
        got = []
        deadline = time.time() + 10
        knock = bytes(MOD.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(peer.mav))
        while len(got) < n and time.time() < deadline:
            if not got:
                peer.write(knock)
            m = peer.recv_match(blocking=True, timeout=0.1)
            if m is not None and m.get_type() != "BAD_DATA":
                got.append(bytes(m.get_msgbuf()))
        finish(proc, "udpin_reply")
    if got != frames:
        fail("udpin_reply: pymavlink received %d frames, %d equal (of %d)" % (
            len(got), sum(1 for a, b in zip(got, frames) if a == b), n))


def tcp_listen(bin_, n):
    port = free_port(socket.SOCK_STREAM)
    server = mavutil.mavlink_connection("tcpin:127.0.0.1:%d" % port, source_system=7, dialect=DIALECT)
    proc = start([bin_, "listen", "tcp:127.0.0.1:%d" % port, "--count", str(n)])
    deadline = time.time() + 10
    while server.port is None and time.time() < deadline:
        server.recv()  # accepts the connection once mavstack's client is in
        time.sleep(0.02)
    if server.port is None:
        proc.kill()
        fail("tcp_listen: mavstack's client never connected: %s" % proc.communicate()[1].strip())
        return
    frames = messages(server.mav, n)
    for fr in frames:
        server.write(fr)
    out, _err = finish(proc, "tcp_listen")
    server.close()
    compare_lines(expected_json(frames), out.splitlines(), "tcp_listen")


def record_tlog(bin_, n):
    port = free_port()
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "rec.tlog")
        proc = start([bin_, "record", "udpin:127.0.0.1:%d" % port, path])
        # It says so on stderr once the socket is bound.
        started = proc.stderr.readline()
        if not started.startswith("recording"):
            fail("record: expected a 'recording ...' line, got %r" % started)
        peer = mavutil.mavlink_connection("udpout:127.0.0.1:%d" % port, source_system=7, dialect=DIALECT)
        frames = messages(peer.mav, n)
        sent_at = []
        for fr in frames:
            sent_at.append(time.time())
            peer.write(fr)
            time.sleep(0.002)
        # Stopped as a user stops it: SIGINT; everything must be in the file.
        time.sleep(0.3)
        proc.send_signal(signal.SIGINT)
        finish(proc, "record")
        # pymavlink's tlog reader (what mavlogdump uses): the same frames, and the
        # timestamps are when they arrived (within a second of sending).
        log = mavutil.mavlink_connection(path, dialect=DIALECT)
        got, stamps = [], []
        while True:
            m = log.recv_msg()
            if m is None:
                break
            if m.get_type() == "BAD_DATA":
                fail("record: pymavlink found bad data in our tlog: %r" % m)
                continue
            got.append(bytes(m.get_msgbuf()))
            stamps.append(m._timestamp)
        if got != frames:
            fail("record: pymavlink read %d frames back, %d equal to those sent (of %d)" % (
                len(got), sum(1 for a, b in zip(got, frames) if a == b), n))
        for i, (s, t) in enumerate(zip(sent_at, stamps)):
            if not (s - 0.001 <= t <= s + 1.0):
                fail("record: frame %d stamped %.6f, sent at %.6f" % (i, t, s))
                break
        # Our own reading of the tlog gives the same timestamps to the microsecond as the
        # raw records (pymavlink's _timestamp is a float of them).
        raw = open(path, "rb").read()
        dec = subprocess.run([bin_, "decode", path], capture_output=True, text=True, check=False)
        ours = [json.loads(l)["ts_us"] for l in dec.stdout.splitlines() if l.strip()]
        pos, records = 0, []
        for fr in got:
            records.append(struct.unpack(">Q", raw[pos:pos + 8])[0])
            pos += 8 + len(fr)
        if ours != records:
            fail("record: mavstack decode timestamps differ from the records")
        for i, (r, t) in enumerate(zip(records, stamps)):
            if abs(r / 1e6 - t) > 2e-6:
                fail("record: frame %d: record says %d us, pymavlink %.6f s" % (i, r, t))
                break
        # mavlogdump.py itself, as a user would run it.
        dump = subprocess.run([sys.executable, mavlogdump(), "--format", "json", "--dialect", DIALECT, path],
                              capture_output=True, text=True, check=False)
        lines = [l for l in dump.stdout.splitlines() if l.startswith("{")]
        if dump.returncode != 0 or len(lines) != n:
            fail("record: mavlogdump.py printed %d messages (of %d), exit %d: %s" % (
                len(lines), n, dump.returncode, dump.stderr.strip()[-300:]))
        else:
            for i, (line, r) in enumerate(zip(lines, records)):
                meta = json.loads(line)["meta"]
                if abs(meta["timestamp"] - r / 1e6) > 2e-6:
                    fail("record: mavlogdump frame %d timestamp %s, record %d" % (i, meta["timestamp"], r))
                    break


def mavlogdump():
    import pymavlink
    path = os.path.join(os.path.dirname(pymavlink.__file__), "tools", "mavlogdump.py")
    if not os.path.exists(path):
        for d in os.environ.get("PATH", "").split(os.pathsep) + [os.path.dirname(sys.executable)]:
            if os.path.exists(os.path.join(d, "mavlogdump.py")):
                return os.path.join(d, "mavlogdump.py")
    return path


def pymavlink_tlog(bin_, n):
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "py.tlog")
        # pymavlink writes tlogs as it receives (mavfile.recv_msg; its UDP class does not
        # log): a tcp connection with a logfile, fed by a plain TCP server socket.
        srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        srv.bind(("127.0.0.1", 0))
        srv.listen(1)
        logger = mavutil.mavlink_connection("tcp:127.0.0.1:%d" % srv.getsockname()[1], dialect=DIALECT)
        logger.setup_logfile(path)
        tx, _ = srv.accept()
        mav = MOD.MAVLink(None, srcSystem=5, srcComponent=1)
        frames = messages(mav, n)
        logged = 0
        for fr in frames:
            tx.sendall(fr)
            m = logger.recv_match(blocking=True, timeout=2)
            logged += m is not None
        tx.close()
        srv.close()
        logger.logfile.close()  # mavfile.close() leaves its logfile open and unflushed
        logger.close()
        if logged != n:
            fail("pymavlink_tlog: pymavlink logged %d of %d frames" % (logged, n))
        # pymavlink's own reading: the expectation.
        rd = mavutil.mavlink_connection(path, dialect=DIALECT)
        expect, stamps = [], []
        while True:
            m = rd.recv_msg()
            if m is None:
                break
            expect.append(mi.message_to_json(m, False))
            stamps.append(m._timestamp)
        if len(expect) != n:
            fail("pymavlink_tlog: pymavlink reads %d frames from its own tlog, not %d" % (len(expect), n))
        dec = subprocess.run([bin_, "decode", path], capture_output=True, text=True, check=False)
        if dec.returncode != 0:
            fail("pymavlink_tlog: mavstack decode exit %d: %s" % (dec.returncode, dec.stderr.strip()))
        lines = [json.loads(l) for l in dec.stdout.splitlines() if l.strip()]
        for i, (o, t) in enumerate(zip(lines, stamps)):
            if abs(o.get("ts_us", 0) / 1e6 - t) > 2e-6:
                fail("pymavlink_tlog: frame %d ts_us %s, pymavlink %.6f" % (i, o.get("ts_us"), t))
                break
        compare_lines(expect, [json.dumps(o) for o in lines], "pymavlink_tlog decode")
        # Replayed onto UDP, pymavlink receives the very same bytes.
        port = free_port()
        peer = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port, dialect=DIALECT)
        proc = start([bin_, "replay", path, "udpout:127.0.0.1:%d" % port, "--speed", "4"])
        got = recv_frames(peer, n, 15)
        finish(proc, "pymavlink_tlog replay")
        if got != frames:
            fail("pymavlink_tlog: replay delivered %d frames, %d equal (of %d)" % (
                len(got), sum(1 for a, b in zip(got, frames) if a == b), n))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenario")
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--frames", type=int, default=200)
    a = ap.parse_args()
    n = a.frames
    b = a.mavstack
    scenarios = {
        "udp_listen": lambda: udp_listen(b, n),
        "udp_replay": lambda: replay_to_pymavlink(b, n, "udpin:127.0.0.1:%d" % PORT[0], "udpout:127.0.0.1:%d" % PORT[0], "udp_replay", False),
        "udpin_reply": lambda: udpin_reply(b, n),
        "tcp_listen": lambda: tcp_listen(b, n),
        "tcp_replay": lambda: replay_to_pymavlink(b, n, "tcp:127.0.0.1:%d" % PORT[1], "tcpin:127.0.0.1:%d" % PORT[1], "tcp_replay", True),
        "record_tlog": lambda: record_tlog(b, n),
        "pymavlink_tlog": lambda: pymavlink_tlog(b, n),
    }
    if a.scenario not in scenarios:
        mi.die("unknown scenario %s (one of %s)" % (a.scenario, ", ".join(scenarios)))
    scenarios[a.scenario]()
    if failures:
        sys.exit(1)
    print("%s: %d frames, all equal" % (a.scenario, n))


PORT = (free_port(), free_port(socket.SOCK_STREAM))

if __name__ == "__main__":
    main()
