#!/usr/bin/env python3
"""Times `mavstack log summary` and `log plot` against pymavlink's mavsummarize.py, mavloss.py
and mavgraph.py on one big tlog (the flight of log_tools.py, about 50 MB), in one run.

Usage: bench_log_tools.py --mavstack BIN [--graph-python PY] [--seconds 64000] [--runs 3]

--graph-python is a Python with pymavlink 2.4.50 and matplotlib (mavgraph.py needs it; the
test venv has no GUI stack): for example `python3 -m venv /tmp/graph && /tmp/graph/bin/pip
install pymavlink==2.4.50 matplotlib`. Without it mavgraph is not timed. Prints one line per
command (best of --runs, wall clock) and the ratios; not a test (no timing is asserted).
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def best(argv, runs, env=None):
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        p = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
        times.append(time.perf_counter() - t)
        if p.returncode != 0:
            sys.exit("%s failed: %s" % (" ".join(argv), p.stderr.decode()[-400:]))
    return min(times)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--graph-python")
    ap.add_argument("--seconds", type=int, default=64000)
    ap.add_argument("--runs", type=int, default=3)
    a = ap.parse_args()
    py = sys.executable
    tools = os.path.dirname(py)
    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "big.tlog")
        subprocess.run([py, os.path.join(HERE, "log_tools.py"), "make", "--seconds", str(a.seconds), "--out", log], check=True)
        mb = os.path.getsize(log) / 1e6
        fields = ["ATTITUDE.roll", "GLOBAL_POSITION_INT.relative_alt"]
        rows = [
            ("mavstack log summary --json", best([a.mavstack, "log", "summary", log, "--json"], a.runs)),
            ("mavsummarize.py", best([py, os.path.join(tools, "mavsummarize.py"), log], a.runs)),
            ("mavloss.py", best([py, os.path.join(tools, "mavloss.py"), log], a.runs)),
            ("mavstack log plot (PNG)", best([a.mavstack, "log", "plot", log, *fields, "--out", os.path.join(tmp, "a.png")], a.runs)),
        ]
        if a.graph_python:
            gtools = os.path.dirname(a.graph_python)
            env = dict(os.environ, MPLBACKEND="Agg")
            rows.append(("mavgraph.py (PNG)", best([a.graph_python, os.path.join(gtools, "mavgraph.py"), "--output",
                                                     os.path.join(tmp, "b.png"), log, *fields], a.runs, env)))
        print("tlog: %.1f MB, best of %d" % (mb, a.runs))
        for name, t in rows:
            print("  %-30s %7.2f s  %6.1f MB/s" % (name, t, mb / t))
        by = dict(rows)
        ours = by["mavstack log summary --json"]
        print("  summary: %.0fx faster than mavsummarize.py, %.0fx than mavloss.py" % (
            by["mavsummarize.py"] / ours, by["mavloss.py"] / ours))
        if "mavgraph.py (PNG)" in by:
            print("  plot: %.0fx faster than mavgraph.py" % (by["mavgraph.py (PNG)"] / by["mavstack log plot (PNG)"]))


if __name__ == "__main__":
    main()
