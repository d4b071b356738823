#!/usr/bin/env python3
"""mavstack.aio against MAVSDK's asyncio binding, on the same simulated vehicle.

    .venv/bin/python crates/mavstack-python/bench/bench_aio.py [--mavstack target/release/mavstack]
        [--autopilot px4] [--params N] [--loss 0.2] [--seconds 5] [--rate 200] [--runs 1]

For each API, in a fresh interpreter of its own (imports done before any clock starts), against
a fresh `mavstack vehicle udpout:127.0.0.1:P --autopilot AP` on loopback UDP (with --params N,
serving a table of N parameters, every third an integer, instead of its flavour's 30-odd; with
--loss, through tests-interop/lossy_relay.py dropping that fraction of the datagrams each way):

  connect   from opening the link to the first autopilot found (mavstack.aio
            `await gcs.vehicle()`; MAVSDK `first_autopilot`);
  params    the whole parameter table after that: mavstack.aio `params.get_all()` (MAVFTP,
            which the vehicle offers) and `params.get_all(via="list")` (PARAM_REQUEST_LIST);
            MAVSDK `get_all_params()`;
  mission   a 100-item mission uploaded (mavstack.aio `mission.upload(items, plan=False)`,
            MAVSDK `upload_mission` of 100 waypoints);
  telemetry ATTITUDE asked for at --rate Hz (mavstack.aio `telemetry("ATTITUDE", rate_hz=)`;
            MAVSDK `set_rate_attitude_euler` and `subscribe_attitude_euler`), read for --seconds
            after the first message: the process's CPU time (every thread: the Python loop, the
            stack's or MAVSDK's own) per message received, and messages per second.

Prints one JSON line per API and a Markdown table.
"""

import argparse
import asyncio
import json
import os
import socket
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", "..", ".."))
N_ITEMS = 100
HOME = (-35.363261, 149.165230)


def free_udp_port():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def cpu():
    return time.process_time()


async def telemetry_cpu(aiter_, seconds):
    """(messages, CPU s, wall s) over `seconds` after the first message of `aiter_`."""
    await aiter_.__anext__()
    n, c0, t0 = 0, cpu(), time.monotonic()
    end = t0 + seconds
    async for _ in aiter_:
        n += 1
        if time.monotonic() >= end:
            break
    return n, cpu() - c0, time.monotonic() - t0


async def run_mavstack(port, a):
    import mavstack.aio as aio
    out = {"api": "mavstack.aio"}
    t0 = time.monotonic()
    async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
        vehicle = await gcs.vehicle(timeout=20)
        out["connect_s"] = time.monotonic() - t0
        t = time.monotonic()
        table = await vehicle.params.get_all()
        out["params_s"] = time.monotonic() - t
        out["params_via"] = vehicle.params.last_via
        out["params"] = len(table)
        t = time.monotonic()
        listed = await vehicle.params.get_all(via="list")
        out["params_list_s"] = time.monotonic() - t
        assert listed == table
        items = [aio.MissionItem(16, x=int((HOME[0] + 0.0001 * (i // 20)) * 1e7),
                                 y=int((HOME[1] + 0.0001 * (i % 20)) * 1e7), z=20.0 + i % 5)
                 for i in range(N_ITEMS)]
        t = time.monotonic()
        await vehicle.mission.upload(items, plan=False)
        out["mission_s"] = time.monotonic() - t
        back = await vehicle.mission.download(plan=False)
        assert len(back) == N_ITEMS, len(back)
        stream = vehicle.telemetry("ATTITUDE", rate_hz=a.rate)
        n, c, w = await telemetry_cpu(stream, a.seconds)
        stream.close()
        out.update(messages=n, msg_per_s=n / w, cpu_us_per_msg=1e6 * c / max(n, 1), cpu_s=c)
    return out


async def run_mavsdk(port, a):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.mission import MissionAsync
    from mavsdk.asyncio.plugins.param import ParamAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    from mavsdk.plugins.mission import MissionItem, MissionPlan
    out = {"api": "mavsdk 4.1.0 (native, mavsdk.asyncio)"}
    t0 = time.monotonic()
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await sdk.add_any_connection("udpin://127.0.0.1:%d" % port)
        system = await sdk.first_autopilot(timeout_s=20.0)
        if system is None:
            raise SystemExit("MAVSDK: no autopilot within 20 s")
        out["connect_s"] = time.monotonic() - t0
        tel, param, mission = TelemetryAsync(system), ParamAsync(system), MissionAsync(system)
        t = time.monotonic()
        allp = await asyncio.wait_for(param.get_all_params(), 60)
        out["params_s"] = time.monotonic() - t
        out["params"] = len(list(allp.int_params)) + len(list(allp.float_params))
        items = []
        for i in range(N_ITEMS):
            row, col = divmod(i, 20)
            items.append(MissionItem(
                latitude_deg=round(HOME[0] + 0.0001 * row, 7),
                longitude_deg=round(HOME[1] + 0.0001 * col, 7),
                relative_altitude_m=float(20 + i % 5), speed_m_s=float("nan"), is_fly_through=True,
                gimbal_pitch_deg=float("nan"), gimbal_yaw_deg=float("nan"),
                camera_action=MissionItem.CameraAction.NONE, loiter_time_s=float("nan"),
                camera_photo_interval_s=float("nan"), acceptance_radius_m=float("nan"),
                yaw_deg=float("nan"), camera_photo_distance_m=float("nan"),
                vehicle_action=MissionItem.VehicleAction.NONE))
        t = time.monotonic()
        await asyncio.wait_for(mission.upload_mission(MissionPlan(items)), 60)
        out["mission_s"] = time.monotonic() - t
        await asyncio.wait_for(tel.set_rate_attitude_euler(float(a.rate)), 10)
        n, c, w = await telemetry_cpu(tel.subscribe_attitude_euler().__aiter__(), a.seconds)
        out.update(messages=n, msg_per_s=n / w, cpu_us_per_msg=1e6 * c / max(n, 1), cpu_s=c)
    finally:
        try:
            await asyncio.wait_for(sdk.destroy(), 5)
        except Exception:
            pass
    return out


def one(a):
    """One API against one vehicle, in this process."""
    import tempfile
    port = free_udp_port()
    vehicle_port, relay = port, None
    if a.loss > 0:
        sys.path.insert(0, os.path.join(ROOT, "tests-interop"))
        from lossy_relay import LossyRelay
        relay = LossyRelay(("127.0.0.1", 0), ("127.0.0.1", port), loss=a.loss, seed=7)
        relay.start()
        vehicle_port = relay.listen_port
    args = [a.mavstack, "vehicle", "udpout:127.0.0.1:%d" % vehicle_port, "--autopilot", a.autopilot]
    with tempfile.TemporaryDirectory() as tmp:
        if a.params:
            path = os.path.join(tmp, "bench.params")
            with open(path, "w") as f:
                for i in range(a.params):
                    f.write("BENCH_P%05d %s\n" % (i, i if i % 3 == 0 else "%.3f" % (i / 7)))
            args += ["--params", path]
        vehicle = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            run = run_mavstack if a.one == "mavstack" else run_mavsdk
            out = asyncio.run(run(port, a))
        finally:
            vehicle.terminate()
            vehicle.wait()
            if relay is not None:
                relay.stop()
    print(json.dumps(out))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mavstack", default=None, help="the mavstack binary (default target/release, else debug)")
    ap.add_argument("--autopilot", default="px4", choices=["px4", "ardupilot"])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--params", type=int, default=0, help="serve a table of this many parameters")
    ap.add_argument("--loss", type=float, default=0.0, help="drop this fraction each way (lossy_relay.py)")
    ap.add_argument("--one", choices=["mavstack", "mavsdk"], help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.mavstack is None:
        for profile in ("release", "debug"):
            path = os.path.join(ROOT, "target", profile, "mavstack")
            if os.access(path, os.X_OK):
                a.mavstack = path
                break
        else:
            raise SystemExit("no mavstack binary: cargo build --release -p mavstack-cli, or --mavstack")
    if a.one:
        one(a)
        return
    rows = []
    for _ in range(a.runs):
        for api in ("mavstack", "mavsdk"):
            p = subprocess.run([sys.executable, __file__, "--one", api, "--mavstack", a.mavstack,
                                "--autopilot", a.autopilot, "--seconds", str(a.seconds),
                                "--rate", str(a.rate), "--params", str(a.params), "--loss", str(a.loss)],
                               capture_output=True, text=True, timeout=300)
            if p.returncode != 0:
                raise SystemExit("%s failed (%d):\n%s%s" % (api, p.returncode, p.stdout, p.stderr))
            row = json.loads(p.stdout.strip().splitlines()[-1])
            print(json.dumps(row), flush=True)
            rows.append(row)
    print()
    print("| API | connect | full parameter list | 100-item mission upload | ATTITUDE at %g Hz: msg/s | CPU per message |"
          % a.rate)
    print("| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        params = "%.3f s (%d, %s)" % (r["params_s"], r["params"], r.get("params_via", "list"))
        if "params_list_s" in r:
            params += "; %.3f s via list" % r["params_list_s"]
        print("| %s | %.3f s | %s | %.3f s | %.0f | %.1f µs |" % (
            r["api"], r["connect_s"], params, r["mission_s"], r["msg_per_s"], r["cpu_us_per_msg"]))


if __name__ == "__main__":
    main()
