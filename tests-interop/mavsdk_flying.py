#!/usr/bin/env python3
"""MAVSDK's Action and Offboard (the native binding, mavsdk 4.1.0 from PyPI) flying a PX4
vehicle: PX4 SITL, or `mavstack vehicle --autopilot px4` standing in for it. What MAVSDK
sees — which requests are accepted, which flight modes follow — is written as a transcript,
so that the simulator's can be compared with PX4's.

    mavsdk_flying.py URL [--out FILE.json] [--expect FILE.json]

URL is MAVSDK's (`udpin://127.0.0.1:14550` for PX4 SITL, which sends there). Steps: connect;
hold; arm (asked again while refused: the estimator settling); takeoff to 10 m (in air, at least
9 m up); offboard start without a setpoint (MAVSDK refuses it itself); a zero velocity set,
offboard start (OFFBOARD); 3 m/s north for 5 s (moved 10-20 m); offboard stop (HOLD); goto
20 m east at the same altitude (within 3 m); land (landed, disarmed). The transcript is the
list of (step, result, flight mode after it). With --expect, the transcript must equal the
file's (PX4 SITL's, recorded by the flight-stacks script); exit 1 with the differences if
not.
"""
import argparse
import asyncio
import json
import math
import sys
import time

STEP_TIMEOUT = 60.0
M_PER_DEG = 111_319.49


async def main(url):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.offboard import OffboardAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    from mavsdk.plugins.offboard import OffboardError, VelocityNedYaw

    transcript, notes = [], []
    cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    mavsdk = Mavsdk(cfg)
    await mavsdk.add_any_connection(url)
    system = await mavsdk.first_autopilot(timeout_s=STEP_TIMEOUT)
    if system is None:
        raise SystemExit("no autopilot on %s" % url)
    action, offboard, telemetry = ActionAsync(system), OffboardAsync(system), TelemetryAsync(system)
    state = {"mode": None, "position": None, "in_air": None, "armed": None}

    async def watch(name, gen):
        async for v in gen:
            state[name] = v

    watchers = [asyncio.ensure_future(watch("mode", telemetry.subscribe_flight_mode())),
                asyncio.ensure_future(watch("position", telemetry.subscribe_position())),
                asyncio.ensure_future(watch("in_air", telemetry.subscribe_in_air())),
                asyncio.ensure_future(watch("armed", telemetry.subscribe_armed()))]

    async def until(pred, limit=STEP_TIMEOUT):
        end = time.monotonic() + limit
        while time.monotonic() < end:
            if pred():
                return True
            await asyncio.sleep(0.1)
        return False

    def mode():
        return state["mode"].name if state["mode"] is not None else None

    async def record(step, coro, settle=None):
        try:
            await asyncio.wait_for(coro, STEP_TIMEOUT)
            result = "ok"
        except Exception as e:  # noqa: BLE001 - MAVSDK's errors name their result
            result = getattr(e, "result", None)
            result = result.name if hasattr(result, "name") else type(e).__name__
        if settle is not None:
            await until(settle, 20)
        transcript.append([step, result, mode()])
        return result

    await until(lambda: state["position"] is not None and state["mode"] is not None)
    # Hold first: PX4 arms in Hold, not in a manual mode without sticks.
    await record("hold", action.hold(), lambda: mode() == "HOLD")
    end = time.monotonic() + 180
    while True:
        r = await record("arm", action.arm(), lambda: state["armed"])
        if r == "ok" or time.monotonic() > end:
            break
        transcript.pop()
        await asyncio.sleep(3)
    await action.set_takeoff_altitude(10.0)
    # Settled: up, and out of the takeoff mode (PX4 holds once it is there).
    await record("takeoff", action.takeoff(),
                 lambda: state["in_air"] and state["position"].relative_altitude_m >= 9.0
                 and mode() != "TAKEOFF")
    notes.append("takeoff to %.1f m" % state["position"].relative_altitude_m)
    try:
        await offboard.start()
        transcript.append(["offboard_start_without_setpoint", "ok", mode()])
    except OffboardError as e:
        transcript.append(["offboard_start_without_setpoint", e.result.name, mode()])
    await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
    await record("offboard_start", offboard.start(), lambda: mode() == "OFFBOARD")
    a = state["position"]
    await offboard.set_velocity_ned(VelocityNedYaw(3.0, 0.0, 0.0, 0.0))
    await asyncio.sleep(5.0)
    await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
    b = state["position"]
    north = (b.latitude_deg - a.latitude_deg) * M_PER_DEG
    transcript.append(["velocity_3ms_5s", "ok" if 10.0 <= north <= 20.0 else "moved %.1f m" % north, mode()])
    notes.append("moved %.1f m north" % north)
    await record("offboard_stop", offboard.stop(), lambda: mode() == "HOLD")
    p = state["position"]
    lon = p.longitude_deg + 20.0 / (M_PER_DEG * math.cos(math.radians(p.latitude_deg)))
    await record("goto_20m_east", action.goto_location(p.latitude_deg, lon, p.absolute_altitude_m, float("nan")))
    reached = await until(lambda: abs(state["position"].longitude_deg - lon) * M_PER_DEG
                          * math.cos(math.radians(p.latitude_deg)) <= 3.0)
    transcript.append(["goto_reached", "ok" if reached else "not within 3 m", mode()])
    await record("land", action.land(), lambda: state["armed"] is False)
    transcript.append(["landed_disarmed", "ok" if state["armed"] is False else "still armed", mode()])
    for w in watchers:
        w.cancel()
    mavsdk.destroy()
    return transcript, notes


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("--out")
    ap.add_argument("--expect")
    a = ap.parse_args()
    transcript, notes = asyncio.run(main(a.url))
    print(json.dumps({"transcript": transcript, "notes": notes}))
    if a.out:
        with open(a.out, "w") as f:
            json.dump(transcript, f, indent=1)
    if a.expect:
        with open(a.expect) as f:
            want = json.load(f)
        if want != transcript:
            diffs = [(w, g) for w, g in zip(want, transcript) if w != g]
            print("differs from %s: %s (lengths %d, %d)" % (a.expect, diffs, len(want), len(transcript)),
                  file=sys.stderr)
            sys.exit(1)
    sys.exit(0 if all(t[1] == "ok" or t[0] == "offboard_start_without_setpoint" for t in transcript) else 1)
