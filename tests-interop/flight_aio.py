#!/usr/bin/env python3
"""mavstack.aio against one running vehicle (ArduPilot SITL, PX4 SITL or `mavstack vehicle`):
the asyncio API's ground-station session, as a user would write it. Prints one JSON object.

usage: flight_aio.py CONN [--params N]

Steps (each recorded, a failure does not stop the rest):
  vehicle    `gcs.vehicle()`: the first autopilot heard (system, component, autopilot)
  params     `vehicle.params.get_all()`: the whole table, its count and time (N: the count
             a direct `mavstack param list` gave, to compare)
  param_get  `vehicle.params.get(name)` of the first name equals the table's value
  mission    a 20-item plan (home, take-off, 17 waypoints, RTL) uploaded and read back: the
             same commands and positions (item 0, home, is the vehicle's on ArduPilot)
  telemetry  `vehicle.telemetry("ATTITUDE", rate_hz=10)` for 4 s after the first: the rate seen
  arm        `vehicle.arm()`: accepted (then disarmed), or refused with the vehicle's reasons
             (STATUSTEXT, or PX4's EVENT texts) in `.statustext`
  mode       `vehicle.set_mode()` to LOITER (ArduPilot) or HOLD (PX4), then back to the mode
             it was in (its HEARTBEAT's, by DO_SET_MODE with numbers: `vehicle.command()`)
"""
import argparse
import asyncio
import json
import sys
import time

import mavstack.aio as aio

HOME = (-353632610, 1491652300)
MODES = {3: "LOITER", 12: "HOLD"}  # by MAV_AUTOPILOT


def plan():
    items = [aio.MissionItem(command=16, frame=0, x=HOME[0], y=HOME[1], z=0.0)]
    items.append(aio.MissionItem(command=22, z=20.0, x=HOME[0], y=HOME[1]))
    items += [aio.MissionItem(command=16, x=HOME[0] + 200 * i, y=HOME[1] + 100 * i, z=30.0 + i)
              for i in range(1, 18)]
    items.append(aio.MissionItem(command=20, frame=2))
    return items


async def step(results, name, coro):
    t = time.monotonic()
    try:
        ok, detail = await coro
    except Exception as e:  # a step's failure is its result, not the session's end
        ok, detail = False, "%s: %s" % (type(e).__name__, e)
    results.append({"step": name, "ok": ok, "seconds": round(time.monotonic() - t, 2),
                    "detail": detail})


async def session(conn, expected_params):
    results = []
    async with aio.connect(conn, source_system=246, source_component=190) as gcs:
        vehicle = None

        async def find():
            nonlocal vehicle
            vehicle = await gcs.vehicle(timeout=20)
            return True, "system %d component %d autopilot %d type %d" % (
                vehicle.system, vehicle.component, vehicle.autopilot, vehicle.mav_type)
        await step(results, "vehicle", find())
        if vehicle is None:
            return results
        table = {}

        async def params():
            table.update(await vehicle.params.get_all())
            ok = expected_params is None or len(table) == expected_params
            return ok, "%d parameters%s" % (len(table), "" if expected_params is None
                                            else " (direct param list: %d)" % expected_params)
        await step(results, "params", params())

        async def param_get():
            name = sorted(table)[0]
            value = await vehicle.params.get(name)
            return value == table[name], "%s = %r (table: %r)" % (name, value, table[name])
        if table:
            await step(results, "param_get", param_get())

        async def mission():
            sent = plan()
            await vehicle.mission.upload(sent)
            got = await vehicle.mission.download()
            diffs = []
            if len(got) != len(sent):
                diffs.append("%d items sent, %d read back" % (len(sent), len(got)))
            for i, (a, b) in enumerate(zip(sent, got)):
                if i == 0:
                    continue
                if a.command != b.command:
                    diffs.append("item %d command %d vs %d" % (i, a.command, b.command))
                elif a.command != 20 and ((a.x, a.y) != (b.x, b.y) or abs(a.z - b.z) > 1e-3):
                    diffs.append("item %d position %s vs %s" % (i, (a.x, a.y, a.z), (b.x, b.y, b.z)))
            await vehicle.mission.clear()
            return not diffs, "%d items up and down%s" % (len(sent), "; " + "; ".join(diffs[:4]) if diffs else "")
        await step(results, "mission", mission())

        async def telemetry():
            stream = vehicle.telemetry("ATTITUDE", rate_hz=10)
            try:
                await asyncio.wait_for(stream.__anext__(), 10)
                n, t0 = 0, time.monotonic()
                while time.monotonic() - t0 < 4.0:
                    await asyncio.wait_for(stream.__anext__(), 5)
                    n += 1
                rate = n / (time.monotonic() - t0)
            finally:
                stream.close()
            return 8.0 <= rate <= 12.0, "ATTITUDE at %.1f Hz (asked 10)" % rate
        await step(results, "telemetry", telemetry())

        async def arm():
            r = await vehicle.arm()
            if r.accepted:
                await vehicle.disarm(force=True)
                return True, "ACCEPTED (disarmed again)"
            return bool(r.statustext), "%s, reasons: %s" % (r, r.statustext)
        await step(results, "arm", arm())

        async def mode():
            # The mode it is in (its HEARTBEAT's custom_mode), to go back to with DO_SET_MODE
            # by number: PX4's main and sub mode are custom_mode's third and fourth bytes.
            beats = vehicle.telemetry("HEARTBEAT")
            try:
                custom = (await asyncio.wait_for(beats.__anext__(), 5)).custom_mode
            finally:
                beats.close()
            back = ((custom >> 16) & 0xFF, custom >> 24) if vehicle.autopilot == 12 else (custom, 0)
            there = MODES.get(vehicle.autopilot, "LOITER")
            r1 = await vehicle.set_mode(there)
            r2 = await vehicle.command(176, 1, float(back[0]), float(back[1]))
            return r1.accepted and r2.accepted, "%s %s, back to custom mode %d %s%s" % (
                there, r1, custom, r2, "" if r1.accepted and r2.accepted else " (%s)" % (r1.statustext + r2.statustext))
        await step(results, "mode", mode())
    return results


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("conn")
    ap.add_argument("--params", type=int, default=None)
    a = ap.parse_args()
    results = asyncio.run(asyncio.wait_for(session(a.conn, a.params), 240))
    print(json.dumps(results))
    return 0 if results and all(r["ok"] for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
