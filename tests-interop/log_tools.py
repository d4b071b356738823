#!/usr/bin/env python3
"""The operator tools against pymavlink 2.4.50 and Debian's chromium: `mavstack log summary`,
`log filter`, `log plot`, and the `--http` status page of `mavstack router`.

Usage: log_tools.py SCENARIO --mavstack BIN [--artifacts DIR]
       log_tools.py make --seconds N --out FILE.tlog   (the same flight, N s long: a big log)

The logs are written by pymavlink (its MAVLink 1 and 2 packing and signing; tlog records as
MAVProxy writes them: a big-endian microsecond timestamp before each frame), and every
expectation is pymavlink's reading of the same file: its own tools mavloss.py (frames and loss
per source) and mavsummarize.py (duration), and mavutil's tlog reader (counts per type,
framing, timestamps and bytes). Exit 0 with "<scenario>: ... ok", or 1 with FAIL lines.

Scenarios:
  summary      a 60 s tlog: a MAVLink 2 vehicle 1/1 (HEARTBEAT, ATTITUDE 10 Hz,
               GLOBAL_POSITION_INT 5 Hz, SYS_STATUS; 2 % of its frames never written), a MAVLink
               1 vehicle 2/1 (1 % lost) and a signed ground station 255/190: `log summary
               --json` agrees with mavloss (frames and lost per source), mavsummarize (duration)
               and mavutil (counts per type, MAVLink 1/2 and signed frames); a copy with 5
               damaged records and 40 bytes of garbage loses exactly those 5 frames and skips
               exactly their bytes and the garbage; the table form names every source
  filter       `log filter --types ATTITUDE,HEARTBEAT --sysid 1 --from 10 --to 20` into a tlog
               and a raw file: mavutil reads back exactly the frames it selects itself from the
               input (same bytes, same timestamps); an unknown type is a usage error (exit 2)
  plot         `log plot ATTITUDE.roll GLOBAL_POSITION_INT.relative_alt` of both vehicles into a
               PNG of the size asked (read back here: its IHDR and pixels; each series' colour
               drawn, one series per field and source, as many points as mavutil counts) and an
               SVG (one polyline per series); bad fields are usage errors naming the field
  status_page  `mavstack router` with a version=1 link, an auto link and a signed link, a
               pymavlink peer on each, `--http`: headless chromium (through chromedriver's
               WebDriver API) loads the page, which shows each link's version (1, 2, signed),
               a rate in and frame counts that change between two reads (the auto link's peer
               goes from 10 to 40 frames/s in between), and the systems heard; `/api/status`
               has the `--stats` object's shape and the same links, routes and systems
"""

import argparse
import base64
import collections
import hashlib
import json
import math
import os
import random
import shutil
import struct
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v10 import ardupilotmega as A1  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as A2  # noqa: E402

from scenario import check, fail, failures, free_port, signing_now  # noqa: E402

KEY = hashlib.sha256(b"mavstack operator tools").digest()
T0 = 1_760_000_000.0  # the log's first timestamp, Unix seconds
SCRIPTS = os.path.dirname(sys.executable)  # pymavlink's tools sit beside the venv's python


class Writer:
    """Collects tlog records (timestamp µs, frame bytes) from pymavlink MAVLink objects."""

    def __init__(self):
        self.records = []

    def add(self, t, mav, msg, lose=False):
        buf = msg.pack(mav)
        mav.seq = (mav.seq + 1) % 256
        if not lose:
            self.records.append((int(round(t * 1e6)), bytes(buf)))

    def write(self, path):
        self.records.sort(key=lambda r: r[0])
        with open(path, "wb") as f:
            for ts, frame in self.records:
                f.write(struct.pack(">Q", ts) + frame)


def make_tlog(path, seconds=60):
    rng = random.Random(7)
    w = Writer()
    v1 = A2.MAVLink(None, srcSystem=1, srcComponent=1)
    v2 = A1.MAVLink(None, srcSystem=2, srcComponent=1)
    gcs = A2.MAVLink(None, srcSystem=255, srcComponent=190)
    gcs.signing.secret_key = KEY
    gcs.signing.link_id = 3
    gcs.signing.sign_outgoing = True
    gcs.signing.timestamp = signing_now()
    for tick in range(seconds * 10 + 1):
        s = tick / 10.0
        t = T0 + s
        if tick % 10 == 0:
            # The first and last frames of the log: vehicle 1's HEARTBEAT, never lost.
            w.add(t, v1, A2.MAVLink_heartbeat_message(2, 3, 0x81 if s > 5 else 0x01, 4, 4, 3))
            w.add(t + 0.001, v1, A2.MAVLink_sys_status_message(0, 0, 0, 500, 12000, -1, 80, 0, 0, 0, 0, 0, 0),
                  lose=rng.random() < 0.02)
            w.add(t + 0.003, v2, A1.MAVLink_heartbeat_message(1, 3, 0x01, 0, 3, 3), lose=rng.random() < 0.01)
            w.add(t + 0.004, gcs, A2.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
        if tick == seconds * 10:
            break
        w.add(t + 0.005, v1, A2.MAVLink_attitude_message(int(s * 1000), 0.5 * math.sin(s), 0.2 * math.cos(s), s / 10, 0, 0, 0),
              lose=rng.random() < 0.02)
        if tick % 2 == 0:
            w.add(t + 0.006, v1, A2.MAVLink_global_position_int_message(
                int(s * 1000), -353632620, 1491652370, 584000 + int(s * 100), int(s * 1000), 0, 0, 0, 0),
                lose=rng.random() < 0.02)
        if tick % 5 == 0:
            w.add(t + 0.007, v2, A1.MAVLink_attitude_message(int(s * 1000), -0.3 * math.sin(s / 2), 0, 0, 0, 0, 0),
                  lose=rng.random() < 0.01)
    w.write(path)
    return w.records


def run(bin_, *args, code=0):
    p = subprocess.run([bin_, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=120)
    out, err = p.stdout.decode(), p.stderr.decode()
    check(p.returncode == code, "mavstack %s: exit %s, expected %s; stderr: %s" % (" ".join(args), p.returncode, code, err.strip()))
    return out, err


def pymavlink_frames(path, raw=False):
    """Every message pymavlink's mavutil reads from the file: (timestamp s or None, msg)."""
    m = mavutil.mavlink_connection(path, dialect="ardupilotmega", notimestamps=raw)
    out = []
    while True:
        msg = m.recv_match()
        if msg is None:
            break
        if msg.get_type() == "BAD_DATA":
            continue
        out.append((None if raw else msg._timestamp, msg))
    return out


def peer_script(name, path):
    p = subprocess.run([sys.executable, os.path.join(SCRIPTS, name), path], stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, timeout=300)
    check(p.returncode == 0, "%s failed: %s" % (name, p.stdout.decode()[-500:]))
    return p.stdout.decode()


def mavloss_table(text):
    """mavloss.py's per-source rows: {(sysid, compid): (packets, lost)}."""
    rows = {}
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 5 and parts[0].isdigit() and parts[1].isdigit():
            rows[(int(parts[0]), int(parts[1]))] = (int(parts[2]), int(parts[3]))
    return rows


def summary(bin_, tmp):
    path = os.path.join(tmp, "flight.tlog")
    records = make_tlog(path)
    out, _ = run(bin_, "log", "summary", path, "--json")
    try:
        s = json.loads(out)
    except ValueError:
        fail("log summary --json printed no JSON object: %r" % out[:300])
        return "no summary"
    ours = {(e["sysid"], e["compid"]): e for e in s["systems"]}

    # mavloss: frames and loss per source.
    loss = mavloss_table(peer_script("mavloss.py", path))
    check(len(loss) == 3, "mavloss saw %d sources, expected 3: %s" % (len(loss), loss))
    for src, (packets, lost) in loss.items():
        e = ours.get(src)
        if check(e is not None, "summary has no system %s/%s, mavloss does" % src):
            check((e["frames"], e["lost"]) == (packets, lost),
                  "%s/%s: summary frames/lost %s/%s, mavloss %s/%s" % (src + (e["frames"], e["lost"], packets, lost)))
    check(set(ours) == set(loss), "systems %s, mavloss's %s" % (sorted(ours), sorted(loss)))
    check(sum(l for _, l in loss.values()) > 0, "the log was meant to have losses")

    # mavsummarize: the duration, as mm:ss.
    text = peer_script("mavsummarize.py", path)
    line = next((l for l in text.splitlines() if l.startswith("Total time (mm:ss):")), "")
    want = line[len("Total time (mm:ss):"):].strip().replace(" ", "") if line else None
    d = s["duration_s"]
    got = "%.0f:%02.0f" % (d / 60, d % 60) if d is not None else None
    check(want is not None and got == want, "duration %s s (%s), mavsummarize says %r" % (d, got, want))
    check(abs(d - 60.0) < 0.01, "duration %s s, the log spans 60 s" % d)

    # mavutil: counts per type and source, framing, signatures.
    frames = pymavlink_frames(path)
    counts = collections.Counter((m.get_srcSystem(), m.get_srcComponent(), m.get_type()) for _, m in frames)
    for (sysid, compid, name), n in counts.items():
        got = ours.get((sysid, compid), {}).get("types", {}).get(name, {})
        check(got.get("count") == n, "%s from %d/%d: summary counts %s, mavutil %d" % (name, sysid, compid, got.get("count"), n))
        if name == "ATTITUDE" and sysid == 1:
            check(abs(got.get("rate_hz", 0) - n / d) < 1e-3, "ATTITUDE rate %s Hz, expected %s" % (got.get("rate_hz"), n / d))
    ntypes = sum(len(e["types"]) for e in ours.values())
    check(ntypes == len(counts), "summary lists %d (source, type) pairs, mavutil %d" % (ntypes, len(counts)))
    v1 = sum(1 for _, m in frames if m.get_msgbuf()[0] == 0xFE)
    signed = sum(1 for _, m in frames if m.get_msgbuf()[0] == 0xFD and m.get_msgbuf()[2] & 1)
    check(s["frames"] == len(frames) == len(records), "frames %s, mavutil %d, written %d" % (s["frames"], len(frames), len(records)))
    check(s["versions"] == {"1": v1, "2": len(frames) - v1}, "versions %s, mavutil 1: %d 2: %d" % (s["versions"], v1, len(frames) - v1))
    check(s["signed_frames"] == signed and signed > 0, "signed %s, mavutil %d" % (s["signed_frames"], signed))
    check((s["bad_frames"], s["skipped_bytes"]) == (0, 0), "a clean log: bad %s, skipped %s" % (s["bad_frames"], s["skipped_bytes"]))
    check(abs(s["start_unix_s"] - T0) < 1e-6, "start %s, expected %s" % (s["start_unix_s"], T0))

    # A damaged copy: 5 records with a flipped payload byte, 40 bytes of garbage.
    data = bytearray()
    damaged = set(range(100, 600, 100))
    skipped = 0
    for i, (ts, frame) in enumerate(records):
        rec = bytearray(struct.pack(">Q", ts) + frame)
        if i in damaged:
            rec[8 + 12] ^= 0x55
            skipped += len(rec)
        if i == 50:
            data += bytes(40)
            skipped += 40
        data += rec
    bad_path = os.path.join(tmp, "damaged.tlog")
    with open(bad_path, "wb") as f:
        f.write(data)
    out, _ = run(bin_, "log", "summary", bad_path, "--json")
    b = json.loads(out)
    check(b["frames"] == len(records) - len(damaged), "damaged log: %s frames, expected %d" % (b["frames"], len(records) - len(damaged)))
    check(b["skipped_bytes"] == skipped, "damaged log: %s bytes skipped, expected %d" % (b["skipped_bytes"], skipped))
    check(b["bad_frames"] >= len(damaged), "damaged log: %s bad frames, expected at least %d" % (b["bad_frames"], len(damaged)))

    table, _ = run(bin_, "log", "summary", path)
    for sysid, compid in loss:
        check("system %d component %d:" % (sysid, compid) in table, "the table names no system %d/%d:\n%s" % (sysid, compid, table))
    check("duration     60.0 s (1:00)" in table, "the table's duration:\n%s" % table)
    return "%d frames from %d sources, loss %s as mavloss, duration %s as mavsummarize" % (
        s["frames"], len(loss), {"%d/%d" % k: v[1] for k, v in loss.items()}, want)


def filter_(bin_, tmp):
    path = os.path.join(tmp, "flight.tlog")
    make_tlog(path)
    frames = pymavlink_frames(path)
    t_first = frames[0][0]
    want = [(t, m.get_msgbuf()) for t, m in frames
            if m.get_type() in ("ATTITUDE", "HEARTBEAT") and m.get_srcSystem() == 1 and 10 - 1e-9 <= t - t_first <= 20 + 1e-9]
    args = ["--types", "attitude,HEARTBEAT", "--sysid", "1", "--from", "10", "--to", "20"]
    out_tlog = os.path.join(tmp, "cut.tlog")
    run(bin_, "log", "filter", path, out_tlog, *args)
    got = [(t, m.get_msgbuf()) for t, m in pymavlink_frames(out_tlog)]
    check(len(got) == len(want) and len(want) > 100, "filtered tlog: %d frames, expected %d" % (len(got), len(want)))
    check(all(abs(a[0] - b[0]) < 1e-6 and a[1] == b[1] for a, b in zip(got, want)), "filtered tlog: frames or timestamps differ")
    out_raw = os.path.join(tmp, "cut.raw")
    run(bin_, "log", "filter", path, out_raw, *args)
    raw = [m.get_msgbuf() for _, m in pymavlink_frames(out_raw, raw=True)]
    check(raw == [b for _, b in want], "filtered raw file: %d frames, expected %d, or bytes differ" % (len(raw), len(want)))
    with open(out_raw, "rb") as f:
        check(f.read() == b"".join(b for _, b in want), "the raw file holds more than the frames")
    _, err = run(bin_, "log", "filter", path, out_tlog, "--types", "NO_SUCH_MESSAGE", code=2)
    check("NO_SUCH_MESSAGE" in err, "unknown type error: %r" % err)
    run(bin_, "log", "filter", out_raw, os.path.join(tmp, "x.tlog"), code=2)
    return "%d frames selected as mavutil selects them (tlog and raw)" % len(want)


def read_png(path):
    """(width, height, RGB bytes) of an 8-bit RGB or RGBA PNG, decoded here."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG")
    pos, idat, w, h, ctype = 8, b"", 0, 0, 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
            if depth != 8 or ctype not in (2, 6):
                raise ValueError("PNG depth %d colour type %d" % (depth, ctype))
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    bpp = 3 if ctype == 2 else 4
    raw = zlib.decompress(idat)
    stride = w * bpp
    out = bytearray()
    prev = bytearray(stride)
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out += line if bpp == 3 else bytes(v for i, v in enumerate(line) if i % 4 != 3)
        prev = line
    return w, h, bytes(out)


def series_lines(out):
    series = []
    for line in out.splitlines():
        if line.startswith("series "):
            parts = line.split()
            kv = dict(p.split("=", 1) for p in parts[2:])
            series.append((parts[1], int(kv["sysid"]), int(kv["compid"]), int(kv["points"]), kv["colour"].lower()))
    return series


def plot(bin_, tmp, artifacts):
    path = os.path.join(tmp, "flight.tlog")
    make_tlog(path)
    frames = pymavlink_frames(path)
    counts = collections.Counter((m.get_type(), m.get_srcSystem(), m.get_srcComponent()) for _, m in frames)
    fields = ["ATTITUDE.roll", "GLOBAL_POSITION_INT.relative_alt"]
    want = sorted((f, s, c, n) for (t, s, c), n in counts.items() for f in fields if f.split(".")[0] == t)
    png = os.path.join(artifacts or tmp, "plot.png")
    out, _ = run(bin_, "log", "plot", path, *fields, "--out", png, "--width", "900", "--height", "500")
    series = series_lines(out)
    check(sorted(s[:4] for s in series) == want, "series %s, expected (field, sysid, compid, points) %s" % (series, want))
    try:
        w, h, rgb = read_png(png)
    except (OSError, ValueError, zlib.error) as e:
        fail("cannot read the PNG back: %s" % e)
        return "no PNG"
    check((w, h) == (900, 500), "PNG is %dx%d, asked 900x500" % (w, h))
    pixels = collections.Counter(zip(rgb[0::3], rgb[1::3], rgb[2::3]))
    colours = {s[4] for s in series}
    check(len(colours) == len(series), "series share colours: %s" % series)
    for name, sysid, compid, _, colour in series:
        rgb_ = tuple(int(colour[i:i + 2], 16) for i in (1, 3, 5))
        check(pixels.get(rgb_, 0) >= 200, "series %s %d/%d: %d pixels of its colour %s" % (name, sysid, compid, pixels.get(rgb_, 0), colour))
    # The palette's next colour, unused: absent.
    check(pixels.get((0x94, 0x67, 0xBD), 0) == 0, "a fourth series colour drawn")
    svg = os.path.join(artifacts or tmp, "plot.svg")
    out, _ = run(bin_, "log", "plot", path, *fields, "--out", svg, "--sysid", "1")
    series1 = series_lines(out)
    check(sorted(s[:4] for s in series1) == [x for x in want if x[1] == 1], "--sysid 1: %s" % series1)
    with open(svg) as f:
        text = f.read().lower()
    check('width="1200"' in text and 'height="600"' in text, "SVG size is not the default 1200x600")
    for s in series1:
        check(text.count('<polyline') >= len(series1) and ('stroke="%s"' % s[4]) in text, "SVG has no polyline of colour %s" % s[4])
    _, err = run(bin_, "log", "plot", path, "ATTITUDE.rol", "--out", png, code=2)
    check("ATTITUDE.rol" in err and "roll" in err, "a misspelt field's error names it and the fields: %r" % err)
    _, err = run(bin_, "log", "plot", path, "ATTITUDE.roll", "--out", os.path.join(tmp, "x.gif"), code=2)
    check(".png or .svg" in err, "a bad extension's error: %r" % err)
    return "%d series (fields x systems), each drawn in its colour, %dx%d as asked" % (len(series), w, h)


# --------------------------------------------------------------------------------------------
# The status page in chromium


class Driver:
    """Headless chromium through chromedriver's W3C WebDriver HTTP API (stdlib only)."""

    def __init__(self, tmp):
        chromium = shutil.which("chromium") or "/usr/bin/chromium"
        driver = shutil.which("chromedriver") or "/usr/bin/chromedriver"
        for exe in (chromium, driver):
            if not os.access(exe, os.X_OK):
                raise RuntimeError("%s not found: install Debian's chromium and chromium-driver (.ci/run does)" % exe)
        self.port = free_port()
        self.proc = subprocess.Popen([driver, "--port=%d" % self.port], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.base = "http://127.0.0.1:%d" % self.port
        deadline = time.monotonic() + 20
        while True:
            try:
                if self._call("GET", "/status").get("ready"):
                    break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError("chromedriver did not become ready")
            time.sleep(0.2)
        args = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-quic",
                "--no-first-run", "--disable-background-networking", "--disable-component-update",
                "--disable-sync", "--window-size=1400,1000", "--user-data-dir=%s" % os.path.join(tmp, "chromium")]
        caps = {"capabilities": {"alwaysMatch": {"browserName": "chrome",
                                                 "goog:chromeOptions": {"binary": chromium, "args": args}}}}
        self.session = self._call("POST", "/session", caps)["sessionId"]

    def _call(self, method, path, body=None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method,
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=60) as r:
            return json.loads(r.read() or b"{}").get("value", {})

    def go(self, url):
        self._call("POST", "/session/%s/url" % self.session, {"url": url})

    def script(self, js):
        return self._call("POST", "/session/%s/execute/sync" % self.session, {"script": js, "args": []})

    def screenshot(self, path):
        png = self._call("GET", "/session/%s/screenshot" % self.session)
        with open(path, "wb") as f:
            f.write(base64.b64decode(png))

    def close(self):
        try:
            self._call("DELETE", "/session/%s" % self.session)
        except OSError:
            pass
        self.proc.terminate()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()


READ_PAGE = """
return [...document.querySelectorAll('#links tr[data-name]')].map(tr => ({
  name: tr.dataset.name, peer: tr.dataset.peer,
  version: tr.querySelector('.version').textContent,
  rx_rate: tr.querySelector('.rx-rate').textContent,
  rx: tr.querySelector('.rx').textContent,
})).concat([...document.querySelectorAll('#systems tr[data-sysid]')].map(tr => ({
  system: tr.dataset.sysid + '/' + tr.dataset.compid, text: tr.textContent})));
"""


class Peer(threading.Thread):
    """A pymavlink peer sending HEARTBEAT and ATTITUDE to a router link at `rate` frames/s."""

    def __init__(self, port, mav, mod):
        super().__init__(daemon=True)
        import socket
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect(("127.0.0.1", port))
        self.mav, self.mod, self.rate, self.stop = mav, mod, 10.0, False

    def run(self):
        n = 0
        while not self.stop:
            if n % 10 == 0:
                msg = self.mod.MAVLink_heartbeat_message(2, 3, 0x81, 4, 4, 3)
            else:
                msg = self.mod.MAVLink_attitude_message(n, 0.1, 0.2, 0.3, 0, 0, 0)
            try:
                self.sock.send(msg.pack(self.mav))
            except OSError:
                pass
            self.mav.seq = (self.mav.seq + 1) % 256
            n += 1
            time.sleep(1.0 / self.rate)


def shape(v):
    """The keys of a JSON value, recursively (lists by their first element)."""
    if isinstance(v, dict):
        return {k: shape(x) for k, x in v.items() if k not in ("dropped", "conversions")}
    if isinstance(v, list):
        return [shape(v[0])] if v else []
    return type(v).__name__ if v is not None else "null"


def status_page(bin_, tmp, artifacts):
    from router_interop import start_router  # the router harness (stats lines, ready, stop)

    http = free_port()
    links = lambda: ["udpin:127.0.0.1:%d?version=1&name=legacy" % free_port(),  # noqa: E731
                     "udpin:127.0.0.1:%d?name=plain" % free_port(),
                     "udpin:127.0.0.1:%d?key=%s&name=signed" % (free_port(), KEY.hex())]
    router, specs = start_router(bin_, links, extra=["--http", "127.0.0.1:%d" % http])
    if router is None:
        return "no router"
    ports = [int(s.split(":")[2].split("?")[0]) for s in specs]
    legacy = Peer(ports[0], A1.MAVLink(None, srcSystem=11, srcComponent=1), A1)
    plain = Peer(ports[1], A2.MAVLink(None, srcSystem=12, srcComponent=1), A2)
    signer = A2.MAVLink(None, srcSystem=13, srcComponent=1)
    signer.signing.secret_key, signer.signing.link_id = KEY, 1
    signer.signing.sign_outgoing, signer.signing.timestamp = True, signing_now()
    signed = Peer(ports[2], signer, A2)
    peers = [legacy, plain, signed]
    for p in peers:
        p.start()
    driver = None
    try:
        driver = Driver(tmp)
        driver.go("http://127.0.0.1:%d/" % http)

        def read(want_rows=3, timeout=20):
            deadline = time.monotonic() + timeout
            rows = []
            while time.monotonic() < deadline:
                rows = driver.script(READ_PAGE)
                links_ = [r for r in rows if "name" in r and r["peer"]]
                if len(links_) >= want_rows and all(r["rx_rate"] not in ("–", "") for r in links_):
                    return rows
                time.sleep(0.3)
            fail("the page did not show %d links with rates within %d s: %s" % (want_rows, timeout, rows))
            return rows

        first = read()
        plain.rate = 40.0
        time.sleep(5.0)  # longer than the page's 3 s rate window
        second = read()
        if artifacts:
            driver.screenshot(os.path.join(artifacts, "status-page.png"))
        by = lambda rows: {r["name"]: r for r in rows if "name" in r and r["peer"]}  # noqa: E731
        a, b = by(first), by(second)
        want_versions = {"legacy": "1", "plain": "2", "signed": "signed"}
        for name, version in want_versions.items():
            if not check(name in a and name in b, "the page shows no link %s: %s" % (name, second)):
                continue
            check(b[name]["version"] == version, "link %s shows version %r, expected %r" % (name, b[name]["version"], version))
            check(int(b[name]["rx"]) > int(a[name]["rx"]), "link %s: frames in did not grow (%s, %s)" % (name, a[name]["rx"], b[name]["rx"]))
            check(float(b[name]["rx_rate"]) > 0, "link %s: rate in %s" % (name, b[name]["rx_rate"]))
        if "plain" in a and "plain" in b:
            ra, rb = float(a["plain"]["rx_rate"]), float(b["plain"]["rx_rate"])
            # Causality, not timing: the rate shown rose with the peer's and lies in a broad band
            # around it (a loaded machine delays the peer's sends and the router's reads).
            check(rb > 1.5 * ra and 20 < rb < 60, "plain's rate in went %s → %s; its peer went 10 → 40 frames/s" % (ra, rb))
        systems = {r["system"]: r["text"] for r in second if "system" in r}
        for sysid in (11, 12, 13):
            text = systems.get("%d/1" % sysid, "")
            check("quadrotor" in text and "ArduPilot" in text and "armed" in text,
                  "the page's system %d/1: %r" % (sysid, text))

        # /api/status: the --stats object's shape, the same links, routes and systems.
        with urllib.request.urlopen("http://127.0.0.1:%d/api/status" % http, timeout=10) as r:
            api = json.loads(r.read())
        stats = router.stats()
        last = stats[-1][1] if stats else {}
        # /api/status adds the web service's `vehicles` and `web` to the --stats object.
        api_stats = {k: v for k, v in api.items() if k not in ("vehicles", "web")}
        check(shape(api_stats) == shape(last), "/api/status has another shape than --stats:\n%s\n%s" % (shape(api_stats), shape(last)))
        ident = lambda o: (sorted((l["name"], l["peer"], l["version"]) for l in o.get("links", [])),  # noqa: E731
                           sorted((r["sysid"], r["compid"], r["link"]) for r in o.get("routes", [])),
                           sorted((s["sysid"], s["compid"], s["type"], s["autopilot"], s["armed"], s["link"]) for s in o.get("systems", [])))
        check(ident(api) == ident(last), "/api/status and --stats differ:\n%s\n%s" % (ident(api), ident(last)))
        check(api["t_s"] >= last.get("t_s", 1e9), "/api/status is older than the last --stats line")
    except (OSError, RuntimeError, ValueError, KeyError) as e:
        fail("status page: %s: %s" % (type(e).__name__, e))
    finally:
        for p in peers:
            p.stop = True
        if driver:
            driver.close()
        router.stop()
    rates = ", ".join("%s %s" % (n, r["rx_rate"]) for n, r in sorted(by(second).items())) if failures == [] else ""
    return "versions 1/2/signed shown in chromium, rates in per s: %s" % rates


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario", choices=["summary", "filter", "plot", "status_page", "make"])
    ap.add_argument("--mavstack", help="the mavstack binary (every scenario but make)")
    ap.add_argument("--seconds", type=int, default=60, help="make: the flight's length (60,000 s: about 50 MB)")
    ap.add_argument("--out", help="make: the tlog to write")
    ap.add_argument("--artifacts", help="keep the images (plot, status page screenshot) here")
    a = ap.parse_args()
    if a.scenario == "make":
        if not a.out:
            ap.error("make needs --out FILE.tlog")
        n = len(make_tlog(a.out, a.seconds))
        print("make: %d frames, %d bytes in %s" % (n, os.path.getsize(a.out), a.out))
        return
    if not a.mavstack:
        ap.error("--mavstack BIN is needed")
    if a.artifacts:
        os.makedirs(a.artifacts, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        if a.scenario == "summary":
            what = summary(a.mavstack, tmp)
        elif a.scenario == "filter":
            what = filter_(a.mavstack, tmp)
        elif a.scenario == "plot":
            what = plot(a.mavstack, tmp, a.artifacts)
        else:
            what = status_page(a.mavstack, tmp, a.artifacts)
    if failures:
        print("%s: %d failures" % (a.scenario, len(failures)))
        sys.exit(1)
    print("%s: %s ok" % (a.scenario, what))


if __name__ == "__main__":
    main()
