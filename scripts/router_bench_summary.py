"""Summary of a router_bench.py --out file that also counts converted frames.

router_bench.py counts a frame as delivered only when its bytes equal what was sent. A router
that converts (MAVLink 2 -> 1 on a version=1 link) or signs (a key= link) changes the bytes
by design, so the harness reports those frames as "non-identical". This table counts, per
router and step, frames delivered to each output whether identical or converted (identical +
mismatch), the loss that leaves, and CPU seconds per 100 k frames so counted. Medians over
rounds.

The harness's latency table pools both outputs, but it too takes identical frames only: for the
converting and signing variants it holds output 2 alone. A router sends a frame to its two
outputs one after the other, and the second send waits for the first (on loopback a send
carries the datagram all the way to the receiver: about 10 us). So the last table gives the
latency of each output, minus direct's in the same round, medians over rounds: output 2 of a
converting variant compares with the later-sent output of the others.

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
    steps = first_seen(step for (_, step) in rows)
    routers = first_seen(r for (r, _) in rows)
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
    latency_per_output(data)


def first_seen(items):
    """The distinct items in the order they first appear."""
    return list(dict.fromkeys(items))


def latency_per_output(data):
    """Added latency p50 / p99 per output, medians over rounds."""
    direct = {}
    for s in data["sessions"]:
        if s["router"] == "direct" and s.get("latency_us"):
            direct[s["round"]] = s["latency_us"]
    per = {}
    for s in data["sessions"]:
        base = direct.get(s["round"])
        if s["router"] == "direct" or not base:
            continue
        for i, lat in enumerate(s.get("latency_us_per_rx") or []):
            if lat:
                per.setdefault((s["router"], i), []).append(
                    (lat["p50"] - base["p50"], lat["p99"] - base["p99"]))
    routers = first_seen(r for (r, _) in per)
    print()
    print("Added latency per output at the latency step, p50 / p99 in us (minus direct's, medians "
          "over rounds); `-` where the harness counted no identical frame (a converted output).")
    print()
    print("| router | output 1 | output 2 |")
    print("|---|---|---|")
    for r in routers:
        cells = []
        for i in range(2):
            v = per.get((r, i))
            cells.append("%.1f / %.1f" % (statistics.median(x[0] for x in v),
                                          statistics.median(x[1] for x in v)) if v else "-")
        print("| %s | %s |" % (r, " | ".join(cells)))


if __name__ == "__main__":
    main(sys.argv[1])
