#!/usr/bin/env python3
"""Microservice operations in connected sessions, timed from the call to the result: the Rust
API (`examples/bench_ops.rs`), `mavstack.aio`, MAVSDK 4.1.0 (native binding) and pymavlink
2.4.50 on the same vehicle, on a clean UDP link and through tests-interop/lossy_relay.py
(20 % of the datagrams dropped each way, 100 ms each way).

usage: bench_ops.py --port P --name NAME [--rust BIN] [--tools rust,aio,mavsdk,pymavlink]
                    [--links clean,lossy] [--items 100] [--rounds 3] [--commands 10] [--seed 7]
                    [--out FILE.json]
                    [--md FILE.md]

The vehicle sends UDP to 127.0.0.1:P (PX4 SITL: 14550; `mavstack vehicle udpout:127.0.0.1:P`;
ArduPilot SITL with `--serial1 udpclient:127.0.0.1:P`). Each tool connects first (untimed),
then, each timed alone (with SETTLE seconds after the parameter table):
  params    the whole parameter table (aio: `params.get_all(via="list")`, PARAM_REQUEST_LIST
            as the others do; the Rust API `params().get_all()`; MAVSDK get_all_params;
            pymavlink: PARAM_REQUEST_LIST, then PARAM_REQUEST_READ for the gaps until complete)
  upload    home + N waypoints (MAVSDK's mission_raw; pymavlink: the MISSION_REQUEST_INT loop)
  download  the same plan read back
            (upload and download: --rounds times on the clean link, once through loss, with
            TRANSFER_SETTLE seconds before each; the median is reported)
  command   DO_SET_MODE to the vehicle's hold mode, --commands round trips (default 10; MAVSDK:
            action.hold()): the median and the mean of those answered, and how many were not
            (through loss a command answered at the first attempt takes one round trip and one
            resent takes the tool's resend wait more, so a median of few samples mostly says how
            many were lucky: use --commands 50 there)
A step not done in --timeout seconds (default 120) is 'timed out'; one that raised is 'failed
after S s' with its error (a tool's own TimeoutError included). Prints a Markdown table.
"""
import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from lossy_relay import LossyRelay  # noqa: E402

STEPS = ["params", "upload", "download", "command"]

# Seconds every tool waits after the parameter table before the next step: PX4 goes on
# sending its whole list (about a second) after a client that re-requests gaps has it all, and
# an upload timed meanwhile would measure that stream, not the tool.
SETTLE = 2.0

# Seconds every tool waits before each transfer: PX4 checks a plan it has just taken, reading
# every item back from its storage, and a download started meanwhile waits on that storage
# (items 2.5-3 ms apart instead of 0.1 ms: 15 ms for 100 items against 3.7 ms a second later).
TRANSFER_SETTLE = 1.0


def median_of(values):
    """The median of a step's rounds, or the first round's failure."""
    bad = [v for v in values if not isinstance(v, float)]
    return bad[0] if bad else statistics.median(values)


async def transfer_rounds(out, rounds, upload, download, timeout):
    """`rounds` timed uploads and downloads (`upload()` and `download()` make their
    coroutines), TRANSFER_SETTLE seconds before each; their medians into `out`."""
    ups, downs = [], []
    for _ in range(rounds):
        await asyncio.sleep(TRANSFER_SETTLE)
        ups.append(await timed(upload(), timeout))
        await asyncio.sleep(TRANSFER_SETTLE)
        downs.append(await timed(download(), timeout))
    out["upload"], out["download"] = median_of(ups), median_of(downs)


def free_udp():
    import socket
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def plan(home, n):
    """(lat, lon, alt) of home then n waypoints."""
    return [home] + [(home[0] + 0.00005 * (i % 20), home[1] + 0.00005 * (i // 20), 20.0)
                     for i in range(1, n + 1)]


def hold_params(autopilot):
    # DO_SET_MODE's params for the hold mode: PX4 AUTO.LOITER (main 4, sub 3), ArduPilot LOITER 5.
    return (1.0, 4.0, 3.0) if autopilot == 12 else (1.0, 5.0, 0.0)


async def timed(coro, timeout):
    """Seconds `coro` took; 'timed out' only when it had not ended after `timeout` seconds,
    'failed after S s: ...' when it raised. (A tool's own timeout error is a failure of the
    tool: mavstack.aio's TimeoutError, raised when a parameter list stays incomplete after
    the retries, is a builtins.TimeoutError like asyncio.wait_for's, and was reported as the
    caller's timeout.)"""
    t = time.monotonic()
    task = asyncio.ensure_future(coro)
    done, _ = await asyncio.wait({task}, timeout=timeout)
    if not done:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        return "timed out"
    took = time.monotonic() - t
    if task.exception() is not None:
        e = task.exception()
        return "failed after %.1f s: %s: %s" % (took, type(e).__name__, str(e)[:80])
    return took


def commands_result(rtts, failed):
    """The command step's result: median and mean of the round trips answered, and how many
    commands went unanswered."""
    if not rtts:
        return "failed"
    return {"median": statistics.median(rtts), "mean": statistics.mean(rtts), "failed": failed,
            "n": len(rtts) + failed}


async def bench_aio(url, n, rounds, commands, timeout):
    import mavstack.aio as aio
    out = {}
    async with aio.connect(url) as gcs:
        v = await gcs.vehicle(timeout=60)
        out["params"] = await timed(v.params.get_all(via="list"), timeout)
        await asyncio.sleep(SETTLE)
        home = await v.home()
        h = (home.lat_deg, home.lon_deg, home.alt_m) if home else (-35.363261, 149.16523, 584.0)
        items = [aio.MissionItem(16, frame=0 if i == 0 else 3, x=int(lat * 1e7), y=int(lon * 1e7), z=alt)
                 for i, (lat, lon, alt) in enumerate(plan(h, n))]
        await transfer_rounds(out, rounds, lambda: v.mission.upload(items), v.mission.download, timeout)
        rtts, failed = [], 0
        for _ in range(commands):
            t = time.monotonic()
            try:
                r = await v.command("DO_SET_MODE", *hold_params(v.autopilot))
            except aio.Error:
                r = None
            if str(r) != "ACCEPTED":
                failed += 1
                continue
            rtts.append(time.monotonic() - t)
        out["command"] = commands_result(rtts, failed)
    return out


async def bench_mavsdk(url, n, rounds, commands, timeout):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    from mavsdk.plugins.mission_raw import MissionItem

    cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    m = Mavsdk(cfg)
    await m.add_any_connection(url)
    system = await m.first_autopilot(timeout_s=60)
    out = {}
    try:
        param, mission, action = ParamAsync(system), MissionRawAsync(system), ActionAsync(system)
        out["params"] = await timed(param.get_all_params(), timeout)
        await asyncio.sleep(SETTLE)
        telemetry = TelemetryAsync(system)
        home = None
        try:
            home = await asyncio.wait_for(telemetry.home(), 5)
        except Exception:  # noqa: BLE001 - a default home then
            pass
        h = (home.latitude_deg, home.longitude_deg, home.absolute_altitude_m) if home else None
        if h is None or any(x != x for x in h):  # no home, or NaN
            h = (-35.363261, 149.16523, 584.0)
        items = [MissionItem(i, 0 if i == 0 else 3, 16, 1 if i == 0 else 0, 1, 0.0, 0.0, 0.0, float("nan"),
                             int(lat * 1e7), int(lon * 1e7), float(alt), 0)
                 for i, (lat, lon, alt) in enumerate(plan(h, n))]
        await transfer_rounds(out, rounds, lambda: mission.upload_mission(items), mission.download_mission,
                              timeout)
        rtts, failed = [], 0
        for _ in range(commands):
            t = time.monotonic()
            try:
                await asyncio.wait_for(action.hold(), timeout)
            except Exception:  # noqa: BLE001
                failed += 1
                continue
            rtts.append(time.monotonic() - t)
        out["command"] = commands_result(rtts, failed)
    finally:
        m.destroy()
    return out


def bench_pymavlink(url, n, rounds, commands, timeout):
    from pymavlink import mavutil
    c = mavutil.mavlink_connection(url, source_system=255, source_component=190)
    hb = c.wait_heartbeat(timeout=60)
    ts, tc = c.target_system, c.target_component
    out = {}

    def deadline():
        return time.monotonic() + timeout

    t = time.monotonic()
    c.mav.param_request_list_send(ts, tc)
    got, count, end, last = {}, None, deadline(), time.monotonic()
    while time.monotonic() < end:
        m = c.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
        if m is not None:
            got[m.param_index] = m.param_value
            count = m.param_count
            last = time.monotonic()
        if count is not None and len(got) >= count:
            break
        if count is not None and time.monotonic() - last > 0.5:
            for i in range(count):
                if i not in got:
                    c.mav.param_request_read_send(ts, tc, b"", i)
            last = time.monotonic()
    out["params"] = time.monotonic() - t if count and len(got) >= count else "timed out"
    def drain(seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            c.recv_match(blocking=True, timeout=0.1)

    drain(SETTLE)
    home = (-35.363261, 149.16523, 584.0)
    pts = plan(home, n)

    def upload():
        t = time.monotonic()
        c.mav.mission_count_send(ts, tc, len(pts), 0)
        end, done = deadline(), False
        while time.monotonic() < end:
            m = c.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True,
                             timeout=1)
            if m is None:
                continue
            if m.get_type() == "MISSION_ACK":
                done = m.type == 0
                break
            lat, lon, alt = pts[m.seq]
            c.mav.mission_item_int_send(ts, tc, m.seq, 0 if m.seq == 0 else 3, 16, 0, 1, 0, 0, 0, 0,
                                        int(lat * 1e7), int(lon * 1e7), alt, 0)
        return time.monotonic() - t if done else "failed"

    def download():
        t = time.monotonic()
        c.mav.mission_request_list_send(ts, tc, 0)
        end, count, items = deadline(), None, {}
        while time.monotonic() < end:
            m = c.recv_match(type=["MISSION_COUNT", "MISSION_ITEM_INT"], blocking=True, timeout=0.5)
            if m is not None and m.get_type() == "MISSION_COUNT":
                count = m.count
            elif m is not None:
                items[m.seq] = m
            if count is not None and len(items) >= count:
                c.mav.mission_ack_send(ts, tc, 0, 0)
                break
            if count is not None:
                nxt = next(i for i in range(count) if i not in items)
                c.mav.mission_request_int_send(ts, tc, nxt, 0)
        return time.monotonic() - t if count is not None and len(items) >= count else "timed out"

    ups, downs = [], []
    for _ in range(rounds):
        drain(TRANSFER_SETTLE)
        ups.append(upload())
        drain(TRANSFER_SETTLE)
        downs.append(download())
    out["upload"], out["download"] = median_of(ups), median_of(downs)

    p = hold_params(hb.autopilot)
    rtts, failed = [], 0
    for _ in range(commands):
        t = time.monotonic()
        c.mav.command_long_send(ts, tc, 176, 0, p[0], p[1], p[2], 0, 0, 0, 0)
        m = c.recv_match(type="COMMAND_ACK", blocking=True, timeout=3)
        if m is None or m.command != 176:
            failed += 1
            continue
        rtts.append(time.monotonic() - t)
    out["command"] = commands_result(rtts, failed)
    c.close()
    return out


def bench_rust(binary, url, n, rounds, commands, timeout):
    try:
        p = subprocess.run([binary, url, str(n), str(rounds), str(commands)], capture_output=True,
                           text=True, timeout=timeout * (2 * rounds + 2) + 60 + 5 * commands)
        r = json.loads(p.stdout.splitlines()[-1])
    except (subprocess.TimeoutExpired, ValueError, IndexError) as e:
        return {s: "failed: %s" % type(e).__name__ for s in STEPS}

    def step(v):
        return v if v is not None else "failed: %s" % "; ".join(r["errors"])[:80]

    return {"params": step(r["params_s"]), "upload": median_of([step(v) for v in r["upload_s"]]),
            "download": median_of([step(v) for v in r["download_s"]]),
            "command": commands_result(r["command_rtts"], r["command_failed"])}


def run_tool(tool, link, a):
    """One tool's session on one link: the URL it listens on, through the relay when lossy."""
    relay = None
    port = a.port
    rounds = a.rounds if link == "clean" else 1
    if link == "lossy":
        tool_port = free_udp()
        relay = LossyRelay(("127.0.0.1", a.port), ("127.0.0.1", tool_port), loss=0.2, seed=a.seed,
                           delay=0.1)
        relay.start()
        port = tool_port
    try:
        c = a.commands
        if tool == "rust":
            return bench_rust(a.rust, "udpin:127.0.0.1:%d" % port, a.items, rounds, c, a.timeout)
        if tool == "aio":
            return asyncio.run(bench_aio("udpin:127.0.0.1:%d" % port, a.items, rounds, c, a.timeout))
        if tool == "mavsdk":
            return asyncio.run(bench_mavsdk("udpin://127.0.0.1:%d" % port, a.items, rounds, c, a.timeout))
        return bench_pymavlink("udpin:127.0.0.1:%d" % port, a.items, rounds, c, a.timeout)
    finally:
        if relay is not None:
            relay.stop()


def fmt(v):
    if isinstance(v, dict):
        lost = ", %d of %d unanswered" % (v["failed"], v["n"]) if v["failed"] else ""
        return "%.1f (mean %.1f%s)" % (v["median"] * 1000, v["mean"] * 1000, lost)
    return "%.1f" % (v * 1000) if isinstance(v, float) else str(v)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--name", required=True)
    ap.add_argument("--rust", help="the bench_ops example's binary")
    ap.add_argument("--tools", default="rust,aio,mavsdk,pymavlink")
    ap.add_argument("--links", default="clean,lossy")
    ap.add_argument("--items", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=3,
                    help="transfers timed per tool on the clean link (the median is reported)")
    ap.add_argument("--commands", type=int, default=10, help="commands timed per tool")
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--seed", type=int, default=7,
                    help="the lossy relay's seed: which datagrams it drops is a function of it and of"
                         " how many came before, so a tool's steps meet the same losses run after run")
    ap.add_argument("--out")
    ap.add_argument("--md")
    a = ap.parse_args()
    rows = []
    for link in a.links.split(","):
        for tool in a.tools.split(","):
            if tool == "rust" and not a.rust:
                continue
            r = run_tool(tool, link, a)
            rows.append({"target": a.name, "link": link, "tool": tool, **r})
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    head = "| target | link | tool | params (ms) | upload %d (ms) | download (ms) | command (ms) |" % a.items
    lines = [head, "| --- | --- | --- | --- | --- | --- | --- |"]
    lines += ["| %s | %s | %s | %s |" % (r["target"], r["link"], r["tool"],
                                         " | ".join(fmt(r.get(s)) for s in STEPS)) for r in rows]
    print("\n".join(lines))
    if a.out:
        with open(a.out, "w") as f:
            json.dump(rows, f, indent=1)
    if a.md:
        with open(a.md, "w") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
