#!/usr/bin/env python3
"""mavstack's Python package against pymavlink on one big tlog, side by side in one run.

Usage: bench_tlog.py [--tlog FILE] [--seconds 64000] [--skip-slow] [--cases CASE,...]

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
  columns    every type into columns, against fasttlogparser (C++; PyPI): its parseTLog gives
             {name: {field: numpy array}} (with sys_id, cmp_id and timestamp in seconds);
             mavstack's read_tlog + pyarrow.table + one numpy array per column (the same
             output), and read_tlog + pyarrow.table alone (Arrow columns, no copy)
Prints seconds, messages/s and peak RSS per case and the ratios. Not a test, but the columns
case first checks that both give the same output: the same message counts per type and the
same values in every column both have (timestamp: ours / 1e6 is theirs), for the types both
give; a difference ends the run with exit status 1.
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
    ("columns", "mavstack"): (
        """
import mavstack, pyarrow as pa
pa.table({"x": [0]})  # pyarrow's first table() imports pandas (0.2 s): setup, not reading
""",
        """
columns = {}
for name, t in mavstack.read_tlog(path).items():
    t = pa.table(t)
    columns[name] = {c: t.column(c).to_numpy() for c in t.column_names}
n = sum(len(c["timestamp_us"]) for c in columns.values())
"""),
    ("columns", "mavstack Arrow"): (
        """
import mavstack, pyarrow as pa
pa.table({"x": [0]})  # pyarrow's first table() imports pandas (0.2 s): setup, not reading
""",
        """
tables = {k: pa.table(v) for k, v in mavstack.read_tlog(path).items()}
n = sum(t.num_rows for t in tables.values())
"""),
    ("columns", "fasttlogparser"): (
        """
import fasttlogparser
""",
        """
messages, ids = fasttlogparser.parseTLog(path)
n = sum(len(c["timestamp"]) for c in messages.values())
"""),
}
# The reader each case is measured against.
RIVAL = {"iterate": "pymavlink", "attitude": "pymavlink", "tables": "pymavlink",
         "csv": "pymavlink mavlogdump.py", "columns": "fasttlogparser"}


def check_columns(path):
    """fasttlogparser's columns and mavstack's of the same log: the same message counts per
    type and the same values in every column both give, for the types both give. Returns
    (types compared, columns compared, differences)."""
    import fasttlogparser
    import numpy as np
    import pyarrow as pa
    import mavstack
    theirs, _ = fasttlogparser.parseTLog(path)
    ours = {k: pa.table(v) for k, v in mavstack.read_tlog(path).items()}
    names = {"sys_id": "sysid", "cmp_id": "compid"}
    diffs, ncols = [], 0
    only = sorted(set(theirs) ^ set(ours))
    if only:
        diffs.append("types in one reader only: %s" % ", ".join(only))
    both = sorted(set(theirs) & set(ours))
    for name in both:
        t, o = theirs[name], ours[name]
        if len(t["timestamp"]) != o.num_rows:
            diffs.append("%s: %d messages, fasttlogparser %d" % (name, o.num_rows, len(t["timestamp"])))
            continue
        for col, values in t.items():
            if col == "timestamp":
                mine = o.column("timestamp_us").to_numpy() / 1e6
            else:
                c = names.get(col, col)
                if c not in o.column_names:
                    diffs.append("%s.%s: no such column in mavstack's table" % (name, col))
                    continue
                mine = o.column(c).to_numpy()
                if mine.dtype == object:  # fixed-size lists
                    mine = np.stack(mine)
            ncols += 1
            if mine.shape != values.shape or not np.array_equal(mine, values, equal_nan=mine.dtype.kind == "f"):
                diffs.append("%s.%s differs" % (name, col))
    return len(both), ncols, diffs


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
    ap.add_argument("--cases", default=",".join(RIVAL),
                    help="comma list of cases to run (default: all: %(default)s)")
    a = ap.parse_args()
    cases = a.cases.split(",")
    unknown = sorted(set(cases) - set(RIVAL))
    if unknown:
        ap.error("unknown case(s): %s" % ", ".join(unknown))
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
            if case not in cases or (who == "pymavlink" and a.skip_slow):
                continue
            results[(case, who)] = run(code, path)
        if "csv" in cases and not a.skip_slow:
            results[("csv", "pymavlink mavlogdump.py")] = mavlogdump_csv(path)
        if "columns" in cases:
            # After the timed cases: a child forked by a process holding both readers' output
            # would start with the parent's peak RSS.
            types, columns, diffs = check_columns(path)
            if diffs:
                sys.exit("columns: mavstack and fasttlogparser differ:\n  " + "\n  ".join(diffs))
            print("columns: the same output from mavstack and fasttlogparser (%d types, %d columns)"
                  % (types, columns))
        for (case, who), (dt, n, rss) in results.items():
            print("  %-9s %-26s %8.3f s %12.0f msg/s  peak RSS %6.0f MB" % (case, who, dt, n / dt, rss / 1e6))
        for case in cases:
            rival = RIVAL[case]
            theirs = results.get((case, rival))
            for who in ("mavstack", "mavstack Arrow"):
                ours = results.get((case, who))
                if ours and theirs:
                    print("  %-9s %s %.1fx faster, peak RSS %.2fx %s's" % (
                        case, who, theirs[0] / ours[0], ours[2] / theirs[2], rival))


if __name__ == "__main__":
    main()
