#!/usr/bin/env python3
"""The fleet test (issue 14), on loopback, bounded to about 60 s: N simulated vehicles (default
1,000; sysids 1..100, so ten vehicles share each), each a mavstack Node with an MQTT bridge
link, HEARTBEAT 1 Hz, ATTITUDE 10 Hz, GLOBAL_POSITION_INT 5 Hz, SYS_STATUS 1 Hz (17 k
messages/s for 1,000), through mosquitto to one wildcard subscriber, ten per-vehicle ones and
one that turns slow (10 ms a message); a command to every vehicle at once (MQTT 5 request/reply
through the bridges) with telemetry running and again after it stopped; mosquitto killed and
restarted mid-run.

    fleet_test.py --fleet BIN [--count N] [--out results.json]

BIN is `target/release/examples/fleet` (cargo build --release -p mavstack-bridge --example
fleet). Timeline (s): telemetry 0-40; slow subscriber from 5; commands at 12 (under load) and
46 (no load); mosquitto killed at 24 and started again at 26; the vehicles report at 52.
Prints a table and writes the JSON.
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mqtt_broker  # noqa: E402

TELEMETRY_S, RUN_S, SLOW_FROM = 40, 52, 5
COMMANDS_AT = (12, 46)
KILL_AT, RESTART_AT = 24, 26
# mosquitto keeps at most 1,000 QoS 1 messages queued per subscriber by default and drops the
# rest: the wildcard subscriber (17 k messages/s on a busy 2-core machine) must not lose the
# control lane to its own slowness, so the queue is made long enough for the whole run.
BROKER_CONF = "max_queued_messages 1000000\n"
LANES = {"telemetry": ("ATTITUDE", "GLOBAL_POSITION_INT", "SYS_STATUS"), "control": ("HEARTBEAT",)}


def window(by_second, names, lo, hi):
    return sum(n for m, s, n in by_second if m in names and lo <= s < hi)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fleet", required=True)
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--out", default="fleet-results.json")
    ap.add_argument("--check", action="store_true",
                    help="exit 1 unless every command was answered, the control lane lost nothing and "
                         "the telemetry lane less than 1 %% in the steady window (counts, not timings)")
    a = ap.parse_args()
    # A connection per vehicle, in the vehicles' process and in mosquitto: raise the soft
    # limit on open files to the hard one (the children inherit it).
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    want = hard if hard != resource.RLIM_INFINITY else max(soft, 65536)
    if soft != resource.RLIM_INFINITY and soft < want:
        resource.setrlimit(resource.RLIMIT_NOFILE, (want, hard))
    broker = mqtt_broker.Broker(extra=BROKER_CONF)
    port = broker.port
    start_us = int(time.time() * 1e6) + 3_000_000  # every client connected before t=0
    common = ["--port", str(port), "--count", str(a.count), "--start-us", str(start_us)]
    veh = subprocess.Popen([a.fleet, "vehicles", *common, "--telemetry-s", str(TELEMETRY_S), "--run-s", str(RUN_S)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    watch = subprocess.Popen([a.fleet, "watch", *common, "--run-s", str(RUN_S + 1), "--slow-from", str(SLOW_FROM),
                              "--steady-until", str(KILL_AT - 1),
                              "--commands-at", ",".join(map(str, COMMANDS_AT))],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    t0 = start_us / 1e6

    def at(t):
        d = t0 + t - time.time()
        if d > 0:
            time.sleep(d)

    at(KILL_AT)
    broker.proc.kill()
    broker.proc.wait()
    at(RESTART_AT)
    broker2 = mqtt_broker.Broker(port=port, extra=BROKER_CONF)
    try:
        vout, verr = veh.communicate(timeout=RUN_S + 20)
        wout, werr = watch.communicate(timeout=30)
    finally:
        for p in (veh, watch):
            if p.poll() is None:
                p.kill()
        broker2.stop()
        broker.log.close()
    if veh.returncode != 0 or watch.returncode != 0:
        print("FAIL: vehicles exit %s, watch exit %s\n%s\n%s" % (veh.returncode, watch.returncode,
              verr.decode()[-2000:], werr.decode()[-2000:]), file=sys.stderr)
        sys.exit(1)
    v, w = json.loads(vout), json.loads(wout)
    sent_s = v["sent_by_second"]
    wild = w["wildcard"]
    rows = []
    # Before the broker went down (whole seconds 1..KILL_AT-1), and from 4 s after it came back.
    windows = {"steady": (1, KILL_AT - 1), "after restart": (RESTART_AT + 4, TELEMETRY_S)}
    for lane, names in LANES.items():
        for wname, (lo, hi) in windows.items():
            s = window(sent_s, names, lo, hi)
            r = window(wild["received_by_second"], names, lo, hi)
            rows.append((lane, wname, s, r, 100.0 * (s - r) / s if s else 0.0))
    arrivals = wild["arrivals_s"]
    after = [t for t in arrivals if t >= RESTART_AT]
    recovery = (min(after) - RESTART_AT) if after else None
    rate = window(wild["received_by_second"], sum(LANES.values(), ()), 1, KILL_AT - 1) / (KILL_AT - 2)
    summary = {
        "count": a.count, "delivered_per_s_steady": round(rate), "lanes": rows,
        "latency": wild["latency"], "per_vehicle_latency": w["per_vehicle"]["latency"],
        "slow_received": w["slow"]["received"], "commands": w["commands"],
        "router_cpu_s": v["cpu_s"], "router_cpu_share": round(v["cpu_s"] / RUN_S, 2),
        "router_peak_rss_mb": round(v["peak_rss_mb"], 1), "recovery_s": recovery,
        "bridge": {k: v[k] for k in ("published", "replaced", "dropped_telemetry", "connections", "acks_sent")},
    }
    with open(a.out, "w") as f:
        json.dump({"summary": summary, "vehicles": v, "watch": w}, f)
    print("| lane | window | sent | received (wildcard) | loss |")
    print("| --- | --- | --- | --- | --- |")
    for lane, wname, s, r, loss in rows:
        print("| %s | %s | %d | %d | %.2f %% |" % (lane, wname, s, r, loss))
    for lane, l in wild["latency"].items():
        print("%s latency (sent before the broker went down): p50 %.2f ms, p99 %.2f ms, max %.1f ms (n %d)" % (
            lane, l["p50_us"] / 1e3, l["p99_us"] / 1e3, l["max_us"] / 1e3, l["n"]))
    for c in w["commands"]:
        l = c["latency"] or {}
        print("commands at %s s: %d/%d answered, p50 %.1f ms, p99 %.1f ms" % (
            c["at_s"], c["answered"], c["sent"], l.get("p50_us", 0) / 1e3, l.get("p99_us", 0) / 1e3))
    print("delivered %d messages/s (steady); vehicles process: %.1f CPU s over %d s, peak RSS %.0f MB; "
          "recovery after the broker restart: %s s; bridge: %s" % (
              rate, v["cpu_s"], RUN_S, v["peak_rss_mb"], recovery, summary["bridge"]))
    print(json.dumps(summary))
    if a.check:
        bad = []
        for c in w["commands"]:
            if c["answered"] != c["sent"]:
                bad.append("commands at %s s: %d of %d answered" % (c["at_s"], c["answered"], c["sent"]))
        for lane, wname, s, r, loss in rows:
            if wname == "steady" and (loss > (0.0 if lane == "control" else 1.0) or s == 0):
                bad.append("%s lane, steady: %d sent, %d received" % (lane, s, r))
        if not after:
            bad.append("nothing arrived after the broker restart")
        for b in bad:
            print("FAIL: " + b, file=sys.stderr)
        if bad:
            sys.exit(1)


if __name__ == "__main__":
    main()
