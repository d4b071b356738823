"""What the package's tests share: corpora written by pymavlink (tests-interop/make_corpus.py:
every message of the dialect with random values, MAVLink 1 and 2, signed frames, garbage,
unknown ids and bad checksums) and pymavlink's own reading of them, the expectation; tlogs
written from frames; and for the live tests, free ports, the simulated vehicle (`mavstack
vehicle`, the workspace's binary) and tests-interop/lossy_relay.py between it and a test."""

import math
import os
import struct
import subprocess
import sys
import time

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
INTEROP = os.path.join(ROOT, "tests-interop")
MAKE_CORPUS = os.path.join(INTEROP, "make_corpus.py")
KEY_HEX = "5c" * 16 + "a3" * 16
KEY = bytes.fromhex(KEY_HEX)

sys.path.insert(0, INTEROP)
# A free port of 127.0.0.1 for UDP and TCP alike, as the interop scripts pick them (outside the
# kernel's ephemeral range, so that no socket bound to port 0 takes it in between; at random).
from scenario import free_port  # noqa: E402


def vehicle_binary():
    """The workspace's `mavstack` binary ($MAVSTACK_BIN, else target/debug, else target/release);
    missing, the test fails."""
    env = os.environ.get("MAVSTACK_BIN")
    if env:
        return env
    for profile in ("debug", "release"):
        path = os.path.join(ROOT, "target", profile, "mavstack")
        if os.access(path, os.X_OK):
            return path
    pytest.fail("no mavstack binary in target/debug or target/release (cargo build -p mavstack-cli), "
                "nor $MAVSTACK_BIN: the simulated vehicle is needed")


class Vehicle:
    """`mavstack vehicle LINK ARGS...` (the simulated vehicle), stopped on exit."""

    def __init__(self, link, *args):
        self.proc = subprocess.Popen([vehicle_binary(), "vehicle", link, *args],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.proc.terminate()
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def wait_tcp_listening(port, proc, deadline=30.0):
    """Waits until a socket listens on TCP `port` (read from /proc/net/tcp and tcp6: a probe
    connection would be taken for a client), failing if `proc` exits or `deadline` passes."""
    local = ":%04X" % port
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        for table in ("/proc/net/tcp", "/proc/net/tcp6"):
            try:
                with open(table) as f:
                    rows = [r.split() for r in f.read().splitlines()[1:]]
            except FileNotFoundError:
                continue
            # Columns: sl, local_address (hex address:port), rem_address, st (0A: LISTEN), ...
            if any(len(r) > 3 and r[1].endswith(local) and r[3] == "0A" for r in rows):
                return
        if proc.poll() is not None:
            pytest.fail("the process exited (%s) before it listened on TCP port %d" % (proc.returncode, port))
        time.sleep(0.02)
    pytest.fail("nothing listened on TCP port %d within %.0f s" % (port, deadline))


class Lossy:
    """tests-interop/lossy_relay.py in front of `port`, dropping `loss` of the datagrams each
    way (seeded); entered, it gives the port to send to instead."""

    def __init__(self, port, loss=0.2, seed=5):
        from lossy_relay import LossyRelay
        self.relay = LossyRelay(("127.0.0.1", 0), ("127.0.0.1", port), loss=loss, seed=seed)

    def __enter__(self):
        self.relay.start()
        return self.relay.listen_port

    def __exit__(self, *exc):
        self.relay.stop()


def make_raw(tmp, name, dialect, seed, key=None, frames=2000, **fracs):
    """A raw capture written by pymavlink; returns its path (extension .raw)."""
    prefix = os.path.join(tmp, name)
    args = [sys.executable, MAKE_CORPUS, prefix, "--dialect", dialect, "--seed", str(seed),
            "--frames", str(frames)]
    if key:
        args += ["--key", key.hex()]
    for k, v in fracs.items():
        args += ["--" + k.replace("_", "-"), str(v)]
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    raw = prefix + ".raw"
    os.replace(prefix + ".bin", raw)
    return raw


def pymavlink_log(path, dialect, key=None, raw=False):
    """pymavlink's reader of `path`, verifying signatures with the key when given (it then
    rejects unsigned frames: their BAD_DATA is counted)."""
    from pymavlink import mavutil
    log = mavutil.mavlink_connection(path, dialect=dialect, notimestamps=raw)
    if key:
        log.setup_signing(bytes.fromhex(key) if isinstance(key, str) else key, sign_outgoing=False)
    return log


def reference(path, dialect, key=None, raw=False):
    """Our messages of `path` beside pymavlink's: [(ours, pymavlink's, from_reader)].

    pymavlink's own reader (mavlink_connection) is the reference; every message it returns
    must be ours too, in order. Where its reader loses frames (a BAD_DATA: after a short
    MAVLink 1 frame behind a MAVLink 2 one it reads into the next record; with a key it
    rejects unsigned frames), we may return more, at most one per BAD_DATA, and each of
    those is checked against pymavlink's decoder on the frame alone (from_reader False)."""
    import importlib
    import mavstack.mavutil
    keyb = bytes.fromhex(key) if isinstance(key, str) else key
    log = pymavlink_log(path, dialect, key, raw)
    theirs, bad, after_bad = [], 0, set()
    previous_bad = False
    while True:
        m = log.recv_msg()
        if m is None:
            break
        if m.get_type() == "BAD_DATA":
            bad += 1
            previous_bad = True
            continue
        if not m.get_type().startswith("UNKNOWN_"):
            if previous_bad:
                # Read right after its reader lost its place: timestamp and link suspect.
                after_bad.add(len(theirs))
            theirs.append(m)
        previous_bad = False
    mine = list(mavstack.mavutil.mavlink_connection(path, dialect=dialect, key=key))
    mod = importlib.import_module("pymavlink.dialects.v20." + dialect)
    plain = mod.MAVLink(None)
    plain.robust_parsing = True
    keyed = mod.MAVLink(None)
    keyed.robust_parsing = True
    keyed.signing.secret_key = keyb
    out, j, extras = [], 0, 0
    for m in mine:
        buf = bytes(m.get_msgbuf())
        if j < len(theirs) and bytes(theirs[j].get_msgbuf()) == buf:
            out.append((m, theirs[j], j not in after_bad))
            j += 1
            continue
        extras += 1
        signed = buf[0] == 0xFD and buf[2] & 1
        decoded = (keyed if keyb and signed else plain).parse_buffer(buf) or []
        assert len(decoded) == 1 and decoded[0].get_type() != "BAD_DATA", (m, decoded)
        out.append((m, decoded[0], False))
    assert j == len(theirs), "pymavlink's message %d (%s) is not among ours" % (j, theirs[j] if j < len(theirs) else None)
    assert extras <= bad, (extras, bad)
    return out


def pymavlink_messages(path, dialect, key=None, raw=False):
    """Every message pymavlink reads, without its BAD_DATA and UNKNOWN_ entries (counted, not
    returned, by mavstack)."""
    log = pymavlink_log(path, dialect, key, raw)
    out = []
    while True:
        m = log.recv_msg()
        if m is None:
            return out
        if m.get_type() == "BAD_DATA" or m.get_type().startswith("UNKNOWN_"):
            continue
        out.append(m)


def write_tlog(path, frames, t0_us=1_760_000_000_000_000, link_bits=True):
    """A tlog of `frames` (bytes), 10 ms apart; with link_bits, the low two bits of the
    timestamps cycle through MAVProxy's link numbers 0-3."""
    with open(path, "wb") as f:
        for i, frame in enumerate(frames):
            us = t0_us + i * 10_000 + (i * 7919) % 1000
            if link_bits:
                us = (us & ~3) | (i % 4)
            f.write(struct.pack(">Q", us) + bytes(frame))
    return path


def norm(v):
    """Values compared with NaN equal to NaN."""
    if isinstance(v, float) and math.isnan(v):
        return "NaN"
    if isinstance(v, list):
        return [norm(x) for x in v]
    if isinstance(v, dict):
        return {k: norm(x) for k, x in v.items()}
    return v


@pytest.fixture(scope="session")
def corpora(tmp_path_factory):
    """Raw captures and tlogs of ardupilotmega (signed) and all, with pymavlink's reading."""
    tmp = str(tmp_path_factory.mktemp("corpora"))
    out = {}
    apm = make_raw(tmp, "apm", "ardupilotmega", 11, key=KEY, frames=4000)
    alld = make_raw(tmp, "all", "all", 12, frames=2500)
    out["apm_raw"] = apm
    out["all_raw"] = alld
    # tlogs of the frames pymavlink found in the captures: every good frame, in order.
    good = pymavlink_messages(apm, "ardupilotmega", key=None, raw=True)
    assert len(good) == 4000
    out["apm_tlog"] = write_tlog(os.path.join(tmp, "apm.tlog"), [m.get_msgbuf() for m in good])
    good = pymavlink_messages(alld, "all", raw=True)
    out["all_tlog"] = write_tlog(os.path.join(tmp, "all.tlog"), [m.get_msgbuf() for m in good])
    out["tmp"] = tmp
    return out
