"""What the ground-station interop scripts (gcs_*.py) share: the vehicle process, ports, timing,
failures with a clear message, and the JSON summary."""

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import scenario

HOME = (-35.363261, 149.165230, 584.0)  # the vehicle's home: lat, lon, m AMSL


class Failure(Exception):
    """A check that did not pass: the message says what was expected and what happened."""


def fail(msg):
    raise Failure(msg)


def mavstack_bin(argv_bin=None):
    path = argv_bin or os.environ.get("MAVSTACK_BIN")
    if not path:
        fail("no mavstack binary: pass --mavstack PATH or set MAVSTACK_BIN")
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        fail(f"mavstack binary {path} is not an executable file")
    return path


def free_udp_port(host="127.0.0.1"):
    return scenario.free_port(host=host)


class Vehicle:
    """`mavstack vehicle CONN ARGS...`, its stderr in a file, stopped on exit."""

    def __init__(self, binary, conn, args=(), workdir=None):
        self.workdir = workdir or tempfile.mkdtemp(prefix="gcs-vehicle-")
        self.log_path = os.path.join(self.workdir, "vehicle.log")
        self.cmd = [binary, "vehicle", conn, *args, "-v"]
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            self.cmd, stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT
        )
        time.sleep(0.2)
        if self.proc.poll() is not None:
            fail(f"vehicle exited at once ({self.proc.returncode}): {' '.join(self.cmd)}\n{self.log()}")

    def log(self, tail=4000):
        try:
            with open(self.log_path, "rb") as f:
                return f.read().decode("utf-8", "replace")[-tail:]
        except OSError:
            return ""

    def check_alive(self):
        if self.proc.poll() is not None:
            fail(f"the vehicle died ({self.proc.returncode}): {' '.join(self.cmd)}\n{self.log()}")

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()


class Router:
    """`mavstack router LINK... --stats S` between the vehicle and a ground station (the
    `--via-router` runs): stdout (the stats JSON lines) and stderr in files of workdir; started
    once it printed `mavstack router: ready`; stop() sends SIGTERM and fails unless it exits 0."""

    def __init__(self, binary, links, workdir, stats=1, name="router", ready_timeout=10.0):
        self.workdir = workdir
        self.name = name
        self.cmd = [binary, "router", *links, "--stats", str(stats)]
        self.stats_path = os.path.join(workdir, f"{name}.stats.jsonl")
        self.log_path = os.path.join(workdir, f"{name}.log")
        self._out = open(self.stats_path, "wb")
        self._err = open(self.log_path, "wb")
        self.proc = subprocess.Popen(self.cmd, stdin=subprocess.DEVNULL, stdout=self._out,
                                     stderr=self._err)
        self.rc = None
        deadline = time.monotonic() + ready_timeout
        while "mavstack router: ready" not in self.log():
            if self.proc.poll() is not None:
                fail(f"router exited at once ({self.proc.returncode}): {' '.join(self.cmd)}\n"
                     f"{self.log()}")
            if time.monotonic() > deadline:
                self.kill()
                fail(f"router did not print 'mavstack router: ready' within {ready_timeout} s: "
                     f"{' '.join(self.cmd)}\n{self.log()}")
            time.sleep(0.02)

    def log(self, tail=4000):
        try:
            with open(self.log_path, "rb") as f:
                return f.read().decode("utf-8", "replace")[-tail:]
        except OSError:
            return ""

    def stats(self):
        """Every stats object printed so far (a line that is not a JSON object fails; a last
        line without its newline is still being written and waits for the next look)."""
        out = []
        with open(self.stats_path, "rb") as f:
            text = f.read().decode("utf-8", "replace")
            for line in text[:text.rfind("\n") + 1].splitlines():
                if not line.strip():
                    continue
                try:
                    obj = json.loads(line)
                except ValueError as e:
                    fail(f"router stdout line is not JSON ({e}): {line!r}")
                if not isinstance(obj, dict):
                    fail(f"router stdout line is not a JSON object: {line!r}")
                out.append(obj)
        return out

    def last_stats(self):
        s = self.stats()
        return s[-1] if s else None

    def describe(self):
        """The last stats object and the log tail, for a failure message."""
        return (f"--- {self.name} last stats ---\n{json.dumps(self.last_stats())}\n"
                f"--- {self.name} log (tail) ---\n{self.log(1500)}")

    def check_alive(self):
        if self.proc.poll() is not None:
            fail(f"the router died ({self.proc.returncode}): {' '.join(self.cmd)}\n{self.log()}")

    def stop(self):
        """SIGTERM; fails unless it exits 0 within 5 s. Returns the last stats object."""
        if self.rc is not None:
            return self.last_stats()
        self.check_alive()
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.rc = self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.kill()
            fail(f"router did not exit within 5 s of SIGTERM\n{self.describe()}")
        self._out.close()
        self._err.close()
        if self.rc != 0:
            fail(f"router exited {self.rc} on SIGTERM, expected 0\n{self.describe()}")
        return self.last_stats()

    def kill(self):
        """For cleanup after a failure: no check."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.rc = self.proc.returncode if self.rc is None else self.rc
        self._out.close()
        self._err.close()


def link_stats(stats, name):
    """The entries of router link `name` in a stats object: the link or, for a udpin server
    link, each of its clients (named as the link, their address in `peer`)."""
    return [e for e in (stats or {}).get("links", [])
            if isinstance(e, dict) and e.get("name") == name]


def link_total(stats, name, field):
    return sum(int(e.get(field) or 0) for e in link_stats(stats, name))


def link_dropped(stats, name):
    """{reason: count} summed over the entries of link `name`."""
    out = {}
    for e in link_stats(stats, name):
        for k, v in (e.get("dropped") or {}).items():
            out[k] = out.get(k, 0) + int(v or 0)
    return out


def via_router(binary, workdir, gcs_links, vehicle_opts="", name="router"):
    """A router between the vehicle and the ground station(s) (the `--via-router` runs): the
    vehicle's link `udpin:127.0.0.1:R?name=vehicle[&vehicle_opts]` (the vehicle then runs
    `udpout:127.0.0.1:R`), and for each (NAME, OPTS) of gcs_links a link
    `udpout:127.0.0.1:P?name=NAME[&OPTS]` towards a ground station listening (udpin) on P.
    Returns (router, R, {NAME: P}); ports taken before the router bound them are picked again
    (3 tries)."""
    for attempt in range(3):
        vport = free_udp_port()
        ports = {link: free_udp_port() for link, _ in gcs_links}
        opts = "name=vehicle" + (f"&{vehicle_opts}" if vehicle_opts else "")
        links = [f"udpin:127.0.0.1:{vport}?{opts}"]
        links += [f"udpout:127.0.0.1:{ports[link]}?name={link}" + (f"&{o}" if o else "")
                  for link, o in gcs_links]
        try:
            return Router(binary, links, workdir, name=name), vport, ports
        except Failure as e:
            if attempt == 2 or "in use" not in str(e).lower():
                raise
    raise AssertionError("unreachable")


def check_router_carried(stats, names, what):
    """Every named link received and sent frames, and nothing was dropped for lack of a route
    or conversion (the routing the ground station's session needs)."""
    for name in names:
        rx, tx = link_total(stats, name, "rx_frames"), link_total(stats, name, "tx_frames")
        if not link_stats(stats, name):
            fail(f"{what}: no link {name!r} in the router's stats: {json.dumps(stats)}")
        if rx == 0 or tx == 0:
            fail(f"{what}: router link {name} received {rx} and sent {tx} frames: "
                 f"{json.dumps(stats)}")
        bad = {k: v for k, v in link_dropped(stats, name).items()
               if k in ("unknown_target", "cannot_convert", "bad_crc", "queue_full") and v}
        if bad:
            fail(f"{what}: router link {name} dropped {bad}: {json.dumps(stats)}")


class Timer:
    """Named durations for the summary."""

    def __init__(self):
        self.t0 = time.monotonic()
        self.timings = {}

    def mark(self, name, since):
        self.timings[name] = round(time.monotonic() - since, 3)
        return self.timings[name]

    def total(self):
        return round(time.monotonic() - self.t0, 3)


def write_params_file(path, params):
    """`NAME VALUE` lines (with a comment and one `NAME,VALUE` line, both accepted)."""
    with open(path, "w") as f:
        f.write("# generated by tests-interop/gcs_*.py\n")
        for i, (name, value) in enumerate(params.items()):
            sep = "," if i % 7 == 3 else " "
            f.write(f"{name}{sep}{value}\n")


def write_qgc_wpl(path, items):
    """QGC WPL 110: items are (frame, command, p1..p4, x, y, z, autocontinue); item 0 is home."""
    with open(path, "w") as f:
        f.write("QGC WPL 110\n")
        for seq, it in enumerate(items):
            frame, cmd, p1, p2, p3, p4, x, y, z, ac = it
            cur = 1 if seq == 0 else 0
            f.write(
                f"{seq}\t{cur}\t{frame}\t{cmd}\t{p1:.8f}\t{p2:.8f}\t{p3:.8f}\t{p4:.8f}\t"
                f"{x:.8f}\t{y:.8f}\t{z:.6f}\t{ac}\n"
            )


def read_qgc_wpl(path):
    rows = []
    with open(path) as f:
        head = f.readline().split()
        if head[:2] != ["QGC", "WPL"]:
            fail(f"{path}: not a QGC WPL file (first line {head})")
        for line in f:
            a = line.split()
            if not a:
                continue
            rows.append(
                {
                    "seq": int(a[0]),
                    "frame": int(a[2]),
                    "command": int(a[3]),
                    "params": [float(v) for v in a[4:8]],
                    "x": float(a[8]),
                    "y": float(a[9]),
                    "z": float(a[10]),
                    "autocontinue": int(a[11]),
                }
            )
    return rows


def survey_mission(n, alt=30.0):
    """Home plus n-1 NAV_WAYPOINTs (MAV_FRAME_GLOBAL_RELATIVE_ALT) on a small grid, then the
    values MISSION_ITEM_INT can carry exactly (lat/lon 1e-7 degrees, z float32)."""
    lat0, lon0, amsl = HOME
    items = [(0, 16, 0, 0, 0, 0, lat0, lon0, amsl, 1)]
    for i in range(1, n):
        row, col = divmod(i - 1, 20)
        lat = round(lat0 + 0.0001 * row, 7)
        lon = round(lon0 + 0.0001 * (col if row % 2 == 0 else 19 - col), 7)
        items.append((3, 16, 0, 0, 0, 0, lat, lon, alt + (i % 5), 1))
    return items


def compare_missions(sent, got, what):
    """Items as read_qgc_wpl gives them; positions to 1e-7 degrees, altitude to 1 mm."""
    if len(sent) != len(got):
        fail(f"{what}: {len(sent)} items uploaded, {len(got)} downloaded")
    for a, b in zip(sent, got):
        if a["seq"] == 0:
            continue  # home: the vehicle reports its own
        same = (
            a["command"] == b["command"]
            and a["frame"] == b["frame"]
            and abs(a["x"] - b["x"]) < 1.5e-7
            and abs(a["y"] - b["y"]) < 1.5e-7
            and abs(a["z"] - b["z"]) < 1e-3
            and all(abs(p - q) < 1e-4 for p, q in zip(a["params"], b["params"]))
        )
        if not same:
            fail(f"{what}: item {a['seq']} uploaded {a}, downloaded {b}")


def run_main(name, body):
    """Runs body() -> summary dict; prints `{"script": name, "ok": true, ...}` or the failure."""
    t0 = time.monotonic()
    try:
        summary = body()
    except Failure as e:
        print(f"{name}: FAILED: {e}", file=sys.stderr, flush=True)
        sys.exit(1)
    except Exception as e:  # an unexpected error in a client library is a failure too
        import traceback

        traceback.print_exc()
        print(f"{name}: FAILED: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
        sys.exit(1)
    summary = {"script": name, "ok": True, "seconds": round(time.monotonic() - t0, 3), **summary}
    print(json.dumps(summary), flush=True)


def which(name):
    return shutil.which(name)
