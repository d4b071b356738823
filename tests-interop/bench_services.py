#!/usr/bin/env python3
"""Times the configuration services of `mavstack vehicle` from the `mavstack` ground-station
commands: fetching 1,000 parameters, uploading and downloading a 500-item mission, over
loopback UDP, clean and through lossy_relay.py dropping a share of datagrams each way.

Usage: bench_services.py --mavstack BIN [--loss 0 0.2] [--runs 3] [--params 1000] [--items 500]

Setup per run: `mavstack vehicle udpout:RELAY --params FILE` (FILE: N parameters, INT32 and
REAL32) -> lossy_relay.py (seeded, a new seed per run) -> the ground station on udpin. Each
operation is timed by the command itself (from its first request to its result, link setup
excluded) and checked: every parameter arrived with its value, the mission read back equals
the one uploaded. Prints one JSON line per (operation, loss) with every run's seconds and the
median, then a table.
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from gcs_common import free_udp_port as free_port  # noqa: E402
from lossy_relay import LossyRelay  # noqa: E402

HOME = (-35.363261, 149.165230)


def write_params(path, n):
    rows = []
    with open(path, "w") as f:
        for i in range(n):
            if i % 2:
                name, value = f"BENCH_R{i:05d}", f"{i * 0.25 - 100.5}"
            else:
                name, value = f"BENCH_I{i:05d}", f"{i * 7 - 3000}"
            rows.append((name, float(value)))
            f.write(f"{name} {value}\n")
    return rows


def write_plan(path, n):
    lines = ["QGC WPL 110"]
    for i in range(n):
        lat = HOME[0] + (i % 50) * 1e-4
        lon = HOME[1] + (i // 50) * 1e-4
        lines.append(f"{i}\t0\t3\t16\t0\t2\t0\tnan\t{lat:.8f}\t{lon:.8f}\t{20 + i % 30}\t1")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


class Setup:
    """A vehicle behind a lossy relay, and a port the ground station listens on."""

    def __init__(self, binary, params_file, loss, seed):
        self.gcs_port = free_port()
        self.relay = LossyRelay(("127.0.0.1", 0), ("127.0.0.1", self.gcs_port),
                                loss=loss, seed=seed)
        self.relay.start()
        self.vehicle = subprocess.Popen(
            [binary, "vehicle", f"udpout:127.0.0.1:{self.relay.listen_port}",
             "--params", params_file, "--start-mavlink2"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def close(self):
        self.vehicle.terminate()
        try:
            self.vehicle.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.vehicle.kill()
        self.relay.stop()


def run(binary, setup, *args):
    cmd = [binary, args[0], args[1], f"udpin:127.0.0.1:{setup.gcs_port}", *args[2:],
           "--timeout", "30"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
    if out.returncode != 0:
        raise SystemExit(f"FAIL: {' '.join(cmd)}: {out.stderr.strip()}")
    return out


def seconds_in(text):
    m = re.search(r" in ([0-9.]+) s", text)
    if not m:
        raise SystemExit(f"FAIL: no timing in {text!r}")
    return float(m.group(1))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--loss", type=float, nargs="+", default=[0.0, 0.2])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--params", type=int, default=1000)
    ap.add_argument("--items", type=int, default=500)
    args = ap.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        params_file = os.path.join(tmp, "params.parm")
        rows = write_params(params_file, args.params)
        plan = os.path.join(tmp, "plan.waypoints")
        write_plan(plan, args.items)
        for loss in args.loss:
            for r in range(args.runs):
                setup = Setup(args.mavstack, params_file, loss, seed=1000 + r)
                try:
                    out = run(args.mavstack, setup, "param", "list", "--json")
                    got = [json.loads(line) for line in out.stdout.splitlines()]
                    if [(g["name"], float(g["value"])) for g in got] != rows:
                        raise SystemExit(f"FAIL: parameter list differs (loss {loss})")
                    results.setdefault(("fetch 1,000 params" if args.params == 1000
                                        else f"fetch {args.params} params", loss), []).append(
                        seconds_in(out.stderr))
                    out = run(args.mavstack, setup, "mission", "upload", plan)
                    results.setdefault((f"upload {args.items}-item mission", loss), []).append(
                        seconds_in(out.stdout))
                    back = os.path.join(tmp, "back.waypoints")
                    out = run(args.mavstack, setup, "mission", "download", back)
                    with open(plan) as a, open(back) as b:
                        if a.read() != b.read():
                            raise SystemExit(f"FAIL: mission read back differs (loss {loss})")
                    results.setdefault((f"download {args.items}-item mission", loss), []).append(
                        seconds_in(out.stderr))
                finally:
                    setup.close()
    for (op, loss), secs in results.items():
        print(json.dumps({"client": "mavstack", "operation": op, "loss": loss,
                          "runs": secs, "median_s": statistics.median(secs)}))
    print()
    print(f"{'operation':<28} {'loss':>5}  {'median s':>9}  runs")
    for (op, loss), secs in results.items():
        print(f"{op:<28} {loss:>5.0%}  {statistics.median(secs):>9.3f}  "
              + " ".join(f"{s:.3f}" for s in secs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
