#!/usr/bin/env python3
"""mavstack's Python package against pymavlink on one big tlog, side by side in one run.

Usage: bench_tlog.py [--tlog FILE] [--seconds 64000] [--skip-slow]

Without --tlog, writes the flight of tests-interop/log_tools.py (about 50 MB at 64,000 s).
Each case runs in a fresh interpreter (its time and its peak RSS are its own): the imports of
the libraries (pymavlink with its dialect module, mavstack, pyarrow, and the pandas import
pyarrow makes on its first table()) come before the clock starts; opening the log and reading
it are timed. mavlogdump.py is timed as a whole program, imports included. The python is
the one running this script, with pymavlink, pyarrow and mavstack installed (the test venv).
Cases:
  iterate    recv_match() over every message (the loop only), mavstack vs pymavlink
  attitude   recv_match(type="ATTITUDE") reading m.roll
  tables     every type into tables: mavstack.read_tlog + pyarrow.table, vs pymavlink's
             recv_match loop building one list of to_dict() per type
  csv        ATTITUDE as CSV: mavstack (read_tlog + pyarrow.csv) vs mavlogdump.py --format csv
Prints seconds, messages/s and peak RSS per case and the ratios. Not a test: nothing asserted.
"""

import argparse
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", "..", ".."))

PRELUDE = """
import resource, sys, time
path = sys.argv[1]
"""
START = """
t0 = time.perf_counter()
"""
POSTLUDE = """
dt = time.perf_counter() - t0
print(dt, n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""

CASES = {
    ("iterate", "mavstack"): (
        """
from mavstack import mavutil
""",
        """
log = mavutil.mavlink_connection(path)
n = 0
while log.recv_match() is not None:
    n += 1
"""),
    ("iterate", "pymavlink"): (
        """
from pymavlink import mavutil
mavutil.set_dialect("ardupilotmega")
""",
        """
log = mavutil.mavlink_connection(path, dialect="ardupilotmega")
n = 0
while True:
    m = log.recv_match()
    if m is None:
        break
    n += 1
"""),
    ("attitude", "mavstack"): (
        """
from mavstack import mavutil
""",
        """
log = mavutil.mavlink_connection(path)
n, s = 0, 0.0
while (m := log.recv_match(type="ATTITUDE")) is not None:
    s += m.roll
    n += 1
"""),
    ("attitude", "pymavlink"): (
        """
from pymavlink import mavutil
mavutil.set_dialect("ardupilotmega")
""",
        """
log = mavutil.mavlink_connection(path, dialect="ardupilotmega")
n, s = 0, 0.0
while (m := log.recv_match(type="ATTITUDE")) is not None:
    s += m.roll
    n += 1
"""),
    ("tables", "mavstack"): (
        """
import mavstack, pyarrow as pa
pa.table({"x": [0]})  # pyarrow's first table() imports pandas (0.2 s): setup, not reading
""",
        """
tables = {k: pa.table(v) for k, v in mavstack.read_tlog(path).items()}
n = sum(t.num_rows for t in tables.values())
"""),
    ("tables", "pymavlink"): (
        """
from pymavlink import mavutil
mavutil.set_dialect("ardupilotmega")
""",
        """
log = mavutil.mavlink_connection(path, dialect="ardupilotmega")
rows = {}
n = 0
while True:
    m = log.recv_match()
    if m is None:
        break
    rows.setdefault(m.get_type(), []).append(m.to_dict())
    n += 1
"""),
    ("csv", "mavstack"): (
        """
import mavstack, pyarrow as pa, pyarrow.csv as pc
pa.table({"x": [0]})  # pyarrow's first table() imports pandas (0.2 s): setup, not reading
""",
        """
t = pa.table(mavstack.read_tlog(path, types=["ATTITUDE"])["ATTITUDE"])
pc.write_csv(t, path + ".mavstack.csv")
n = t.num_rows
"""),
}


def run(case, path):
    setup, timed = case
    p = subprocess.run([sys.executable, "-c", PRELUDE + setup + START + timed + POSTLUDE, path],
                       capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(p.stderr[-2000:])
    dt, n, rss = p.stdout.split()[-3:]
    return float(dt), int(n), int(rss) * 1024


def mavlogdump_csv(path):
    """pymavlink's mavlogdump.py --format csv --types ATTITUDE, in a fresh interpreter."""
    exe = os.path.join(os.path.dirname(sys.executable), "mavlogdump.py")
    code = """
import resource, runpy, sys, time
exe, path = sys.argv[1], sys.argv[2]
t0 = time.perf_counter()
out = open(path + ".pymavlink.csv", "w")
real, sys.stdout = sys.stdout, out
sys.argv = [exe, "--format", "csv", "--types", "ATTITUDE", "--dialect", "ardupilotmega", path]
try:
    runpy.run_path(exe, run_name="__main__")
except SystemExit:
    pass
out.close()
sys.stdout = real
n = sum(1 for _ in open(path + ".pymavlink.csv")) - 1
print(time.perf_counter() - t0, n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""
    p = subprocess.run([sys.executable, "-c", code, exe, path], capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(p.stderr[-2000:])
    dt, n, rss = p.stdout.split()[-3:]
    return float(dt), int(n), int(rss) * 1024


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--tlog")
    ap.add_argument("--seconds", type=int, default=64000)
    ap.add_argument("--skip-slow", action="store_true", help="leave out the pymavlink cases")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = a.tlog
        if not path:
            path = os.path.join(tmp, "big.tlog")
            subprocess.run([sys.executable, os.path.join(ROOT, "tests-interop", "log_tools.py"),
                            "make", "--seconds", str(a.seconds), "--out", path], check=True)
        mb = os.path.getsize(path) / 1e6
        print("tlog: %s, %.1f MB" % (path, mb))
        results = {}
        for (case, who), code in CASES.items():
            if who == "pymavlink" and a.skip_slow:
                continue
            results[(case, who)] = run(code, path)
        if not a.skip_slow:
            results[("csv", "pymavlink mavlogdump.py")] = mavlogdump_csv(path)
        for (case, who), (dt, n, rss) in results.items():
            print("  %-9s %-26s %8.3f s %12.0f msg/s  peak RSS %6.0f MB" % (case, who, dt, n / dt, rss / 1e6))
        for case in ("iterate", "attitude", "tables", "csv"):
            ours = results.get((case, "mavstack"))
            theirs = results.get((case, "pymavlink")) or results.get((case, "pymavlink mavlogdump.py"))
            if ours and theirs:
                print("  %-9s mavstack %.0fx faster, peak RSS %.2fx pymavlink's" % (
                    case, theirs[0] / ours[0], ours[2] / theirs[2]))


if __name__ == "__main__":
    main()
