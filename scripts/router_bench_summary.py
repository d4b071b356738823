"""Summary of a router_bench.py --out file that also counts converted frames.

router_bench.py counts a frame as delivered only when its bytes equal what was sent. A router
that converts (MAVLink 2 -> 1 on a version=1 link) or signs (a key= link) changes the bytes
by design, so the harness reports those frames as "non-identical". This table counts, per
router and step, frames delivered to each output whether identical or converted (identical +
mismatch), the loss that leaves, and CPU seconds per 100 k frames so counted. Medians over
rounds.

    python scripts/router_bench_summary.py target/router-bench/results.json
"""
import json
import statistics
import sys


def main(path):
    data = json.load(open(path))
    rows = {}
    for s in data["sessions"]:
        for st in s.get("steps", []):
            sent = st.get("sent") or 0
            rx = st.get("rx") or []
            if not sent or not rx:
                continue
            got = [r.get("delivered", 0) + r.get("mismatch", 0) for r in rx]
            conv = [r.get("mismatch", 0) for r in rx]
            dur = st.get("dur") or 1.0
            cpu = st.get("cpu_s")
            per100k = cpu / (min(got) / 1e5) if cpu and min(got) else None
            rows.setdefault((s["router"], st["step"]), []).append(
                (min(got) / dur, max(0.0, 1 - min(got) / sent), sum(conv), per100k))
    steps = []
    for (_, step) in rows:
        if step not in steps:
            steps.append(step)
    routers = []
    for (r, _) in rows:
        if r not in routers:
            routers.append(r)
    print()
    print("Frames delivered per output counting converted ones (identical + converted), per second (loss); "
          "median over rounds. `conv` = frames that arrived converted (on output 1 of the v1 / signed variants).")
    print()
    print("| router | " + " | ".join(steps) + " |")
    print("|---|" + "---|" * len(steps))
    for r in routers:
        cells = []
        for step in steps:
            v = rows.get((r, step))
            if not v:
                cells.append("-")
                continue
            rate = statistics.median(x[0] for x in v)
            loss = statistics.median(x[1] for x in v)
            conv = statistics.median(x[2] for x in v)
            cpu = [x[3] for x in v if x[3] is not None]
            cell = "%.0fk (%.1f%%)" % (rate / 1000, loss * 100)
            if conv:
                cell += ", conv %d" % conv
            if cpu:
                cell += ", %.2f s/100k" % statistics.median(cpu)
            cells.append(cell)
        print("| %s | %s |" % (r, " | ".join(cells)))


if __name__ == "__main__":
    main(sys.argv[1])
