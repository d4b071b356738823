#!/usr/bin/env python3
"""Flying a vehicle with mavstack.aio: the flight-stack scenarios of the flying API, one per
run, against ArduPilot SITL, PX4 SITL or `mavstack vehicle`.

usage: flight_flying.py CONN SCENARIO

SCENARIO is one of:
  modes         every mode the vehicle lists is set (then current) or refused with the
                vehicle's reason; each standard name maps to the custom mode the built-in
                tables give it
  takeoff_goto  arm, takeoff 10 (at least 9.5 m above home), goto 30 m north at 10 m (within
                1.5 m), land, disarmed
  offboard      arm, takeoff 10, offboard velocity 3 m/s north for 5 s (moves 13-17 m), a
                position setpoint 10 m east (held within 1 m), the block left (the vehicle
                holds), land
  manual        arm, takeoff 10, a position mode, sticks forward for 4 s (moves more than 3 m
                north), centred (holds), land

Prints one JSON object per step ({"step", "ok", "detail", "seconds"}), then the list of them
all on the last line; exit 0 when every step passed.
"""
import asyncio
import json
import math
import sys
import time

import mavstack.aio as aio

STEPS = []
T0 = time.monotonic()
M_PER_DEG_LAT = 111_319.49


def step(name, ok, detail):
    s = {"step": name, "ok": bool(ok), "detail": detail, "seconds": round(time.monotonic() - T0, 1)}
    STEPS.append(s)
    print(json.dumps(s), flush=True)
    return ok


def metres(a, b):
    """Horizontal metres between two positions (lat_deg, lon_deg, ...)."""
    dn = (b[0] - a[0]) * M_PER_DEG_LAT
    de = (b[1] - a[1]) * M_PER_DEG_LAT * math.cos(math.radians(a[0]))
    return math.hypot(dn, de), dn, de


async def arm_when_ready(v, limit=180.0):
    """Arms in a mode that holds position (a landing leaves ArduPilot in LAND, which it will
    not arm in), asking again while the vehicle refuses (its estimator settling)."""
    end = time.monotonic() + limit
    while True:
        try:
            await v.hold()
            break
        except aio.Error as e:
            if time.monotonic() > end:
                return step("armed", False, "hold mode: %s" % e)
            await asyncio.sleep(3)
    reasons = []
    while True:
        r = await v.arm()
        if str(r) == "ACCEPTED":
            return step("armed", True, "after %d refusals" % len(reasons))
        reasons = r.statustext or reasons
        if time.monotonic() > end:
            return step("armed", False, "refused: %s %s" % (r, reasons[:3]))
        await asyncio.sleep(3)


async def take_off(v, height=10.0):
    t = time.monotonic()
    await v.takeoff(height)
    p = await v.position()
    return step("takeoff", p is not None and p.height_m >= 0.95 * height,
                "%.1f m above home in %.1f s" % (p.height_m if p else float("nan"), time.monotonic() - t))


async def land(v):
    await v.land(wait=True)
    return step("landed_disarmed", not v.armed, "armed %s" % v.armed)


async def heading_deg(v):
    """Its heading (degrees), from one GLOBAL_POSITION_INT."""
    async for m in v.telemetry("GLOBAL_POSITION_INT", rate_hz=5):
        return m.hdg / 100.0
    return 0.0


async def modes(v):
    listed = await v.modes()
    set_ok, refused, failed = [], [], []
    for m in listed:
        if not m.selectable:
            continue
        try:
            r = await v.set_mode(m.name)
        except aio.Error as e:
            # Accepted, then not entered, the vehicle saying why (PX4's VTOL Takeoff on a
            # multicopter: "Unsupported auto mode"): refused with its reason.
            said = "did not report it" in str(e) and str(e).rstrip().endswith(")")
            (refused if said else failed).append("%s: %s" % (m.name, e))
            continue
        if str(r) != "ACCEPTED":
            (refused if r.statustext or str(r) in ("DENIED", "FAILED", "UNSUPPORTED",
                                                   "TEMPORARILY_REJECTED") else failed).append(
                "%s %s %s" % (m.name, r, r.statustext[:1]))
            continue
        now = await v.mode()
        (set_ok if now is not None and now.custom_mode == m.custom_mode else failed).append(m.name)
    step("modes_set", not failed, "%d set and current, %d refused (%s), %d failed %s" % (
        len(set_ok), len(refused), "; ".join(refused[:6]), len(failed), failed[:6]))
    standard = [m for m in listed if m.standard]
    wrong = []
    for m in standard:
        r = await v.set_mode(m.standard)
        now = await v.mode()
        if str(r) == "ACCEPTED" and (now is None or now.custom_mode != m.custom_mode):
            wrong.append("%s -> %s" % (m.standard, now))
    step("standard_names", not wrong, "%d standard (%s); wrong: %s" % (
        len(standard), ", ".join("%s=%s" % (m.standard, m.name) for m in standard), wrong))
    await v.hold()  # a mode every later scenario can arm in


async def takeoff_goto(v):
    if not await arm_when_ready(v):
        return
    if not await take_off(v):
        return
    start = await v.position()
    target = (start.lat_deg + 30.0 / M_PER_DEG_LAT, start.lon_deg)
    t = time.monotonic()
    try:
        await v.goto(target[0], target[1], 10.0)
        p = await v.position()
        d, _, _ = metres((p.lat_deg, p.lon_deg), target)
        step("goto_30m_north", d <= 1.5, "%.2f m from the point, %.1f m up, in %.1f s" % (
            d, p.height_m, time.monotonic() - t))
    except aio.Error as e:
        step("goto_30m_north", False, str(e))
    await land(v)


async def offboard(v):
    if not await arm_when_ready(v):
        return
    if not await take_off(v):
        return
    local = v.telemetry("LOCAL_POSITION_NED", rate_hz=10)
    last = {}

    async def follow():
        async for m in local:
            last["p"] = (m.x, m.y, m.z)
            last["v"] = (m.vx, m.vy, m.vz)

    follower = asyncio.ensure_future(follow())
    try:
        async with v.offboard(rate_hz=20) as ob:
            ob.set_velocity_ned(3.0, 0.0, 0.0)
            # 5 s at 3 m/s: timed from when the vehicle reports the speed (it accelerates
            # at its own rate first; ArduPilot's guided velocity takes about 2 s).
            t = time.monotonic()
            while time.monotonic() - t < 15 and last.get("v", (0.0,))[0] < 2.7:
                await asyncio.sleep(0.05)
            a = last["p"]
            await asyncio.sleep(5.0)
            b = last["p"]
            ob.set_velocity_ned(0.0, 0.0, 0.0)
            dn = b[0] - a[0]
            step("velocity_3ms_5s", 13.0 <= dn <= 17.0, "moved %.1f m north in 5 s at 3 m/s (%.1f s to reach it)" % (
                dn, time.monotonic() - t - 5.0))
            await asyncio.sleep(2.0)
            while "p" not in last:
                await asyncio.sleep(0.1)
            n, e, dd = last["p"]
            goal = (n, e + 10.0, dd)
            ob.set_position_ned(*goal)
            end = time.monotonic() + 60
            while time.monotonic() < end:
                p = last["p"]
                if math.dist(p[:2], goal[:2]) <= 1.0:
                    break
                await asyncio.sleep(0.2)
            await asyncio.sleep(2.0)  # past any overshoot
            held = []
            for _ in range(15):
                await asyncio.sleep(0.2)
                held.append(math.dist(last["p"][:2], goal[:2]))
            step("position_10m_east", max(held) <= 1.0, "within %.2f m of the setpoint for 3 s, 2 s after reaching it" % max(held))
            sent = ob.sent
        m = await v.mode()
        p0 = last["p"]
        await asyncio.sleep(3.0)
        drift = math.dist(last["p"][:2], p0[:2])
        step("left_block_holds", m is not None and drift < 1.5, "mode %s after %d setpoints; drifted %.2f m in 3 s" % (
            m.name if m else None, sent, drift))
    except aio.Error as e:
        step("offboard", False, "%s: %s" % (type(e).__name__, e))
    finally:
        follower.cancel()
    await land(v)


async def manual(v):
    if not await arm_when_ready(v):
        return
    if not await take_off(v):
        return
    try:
        async with v.manual_control(rate_hz=20) as mc:
            await asyncio.sleep(1.0)
            await v.set_mode("position_hold")
            heading = await heading_deg(v)
            a = await v.position()
            mc.set(0.6, 0.0, 0.5, 0.0)
            await asyncio.sleep(4.0)
            mc.set(0.0, 0.0, 0.5, 0.0)
            b = await v.position()
            d, dn, de = metres((a.lat_deg, a.lon_deg), (b.lat_deg, b.lon_deg))
            forward = dn * math.cos(math.radians(heading)) + de * math.sin(math.radians(heading))
            step("sticks_forward_4s", forward > 3.0, "moved %.1f m forward (heading %.0f°; %.1f m north, %.1f m east)" % (
                forward, heading, dn, de))
            await asyncio.sleep(3.0)
            c = await v.position()
            await asyncio.sleep(3.0)
            e = await v.position()
            drift, _, _ = metres((c.lat_deg, c.lon_deg), (e.lat_deg, e.lon_deg))
            step("centred_holds", drift < 1.5, "drifted %.2f m in 3 s" % drift)
    except aio.Error as e:
        step("manual", False, "%s: %s" % (type(e).__name__, e))
    await land(v)


async def main(conn, scenario):
    async with aio.connect(conn) as gcs:
        v = await gcs.vehicle(timeout=60)
        await {"modes": modes, "takeoff_goto": takeoff_goto, "offboard": offboard,
               "manual": manual}[scenario](v)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    try:
        asyncio.run(main(sys.argv[1], sys.argv[2]))
    except Exception as e:  # noqa: BLE001 - the report says what ended the run
        step("error", False, "%s: %s" % (type(e).__name__, e))
    print(json.dumps(STEPS), flush=True)
    sys.exit(0 if STEPS and all(s["ok"] for s in STEPS) else 1)
