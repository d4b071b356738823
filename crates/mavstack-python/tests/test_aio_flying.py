"""mavstack.aio flies the simulated vehicle (`mavstack vehicle`, as ArduPilot and as PX4): modes
by the vehicle's names and by standard names, takeoff to a height above home, goto, land,
offboard setpoints that keep their rate while the caller blocks, manual control; and values
that must not be sent (NaN, a rate too slow, a takeoff while disarmed) refused with nothing
sent. Positions and modes are asserted, never times."""

import asyncio
import math
import time

import pytest

import mavstack.aio as aio
from conftest import Vehicle, free_port
from test_aio import run

M_PER_DEG = 111_319.49


async def arm(v):
    await v.hold()
    r = await v.arm()
    assert r.accepted, (str(r), r.statustext)


# One flavour each: the Rust tests (crates/mavstack/tests/flying.rs) fly both through the same
# library; these check what the binding adds.
@pytest.mark.parametrize("autopilot", ["px4"])
def test_modes_takeoff_goto_land(autopilot):
    async def go(url):
        async with aio.connect(url) as gcs:
            v = await gcs.vehicle(timeout=10)
            modes = await v.modes()
            names = {m.name for m in modes}
            assert modes and all(m.custom_mode >= 0 for m in modes)
            standard = {m.standard: m.custom_mode for m in modes if m.standard}
            # safe_recovery is RTL on both; set by its standard name, it is then current.
            assert "safe_recovery" in standard, standard
            with pytest.raises(aio.UnknownModeError) as e:
                await v.set_mode("warp")
            assert any(n in str(e.value) for n in names)
            with pytest.raises(aio.InvalidValueError):
                await v.takeoff(10.0)  # not armed: nothing sent
            await arm(v)
            with pytest.raises(aio.InvalidValueError):
                await v.takeoff(float("nan"))
            await v.takeoff(10.0)
            p = await v.position()
            assert p is not None and p.height_m >= 9.5 and v.in_air
            target = (p.lat_deg + 30.0 / M_PER_DEG, p.lon_deg)
            await v.goto(target[0], target[1], 10.0)
            q = await v.position()
            north = (q.lat_deg - target[0]) * M_PER_DEG
            east = (q.lon_deg - target[1]) * M_PER_DEG * math.cos(math.radians(q.lat_deg))
            assert math.hypot(north, east) <= 1.5, (north, east)
            r = await v.set_mode("safe_recovery")
            assert r.accepted
            mode = await v.mode()
            assert mode is not None and mode.custom_mode == standard["safe_recovery"]
            await v.land()
            assert not v.armed

    port = free_port()
    with Vehicle("udpout:127.0.0.1:%d" % port, "--autopilot", autopilot):
        run(go("udpin:127.0.0.1:%d" % port), timeout=180)


@pytest.mark.parametrize("autopilot", ["ardupilot"])
def test_offboard_keeps_its_rate_while_the_caller_blocks_and_holds_after(autopilot):
    async def go(url):
        async with aio.connect(url) as gcs:
            v = await gcs.vehicle(timeout=10)
            await arm(v)
            await v.takeoff(10.0)
            with pytest.raises(aio.InvalidValueError):
                async with v.offboard(rate_hz=1.0):
                    pass
            a = await v.position()
            async with v.offboard(rate_hz=20) as ob:
                with pytest.raises(ValueError):
                    ob.set_velocity_ned(float("nan"), 0.0, 0.0)
                ob.set_velocity_ned(3.0, 0.0, 0.0)
                started = ob.sent
                for _ in range(10):
                    time.sleep(0.2)  # the loop blocked: the library's stream goes on
                    await asyncio.sleep(0)
                during = ob.sent - started
                mode = await v.mode()
                ob.set_velocity_ned(0.0, 0.0, 0.0)
            b = await v.position()
            held = await v.mode()
            # 2 s blocked in 200 ms slices at 20 Hz: the stream kept going (counts, not times).
            assert during >= 20, during
            assert mode is not None and mode.name.upper() in ("OFFBOARD", "GUIDED"), mode
            assert (b.lat_deg - a.lat_deg) * M_PER_DEG > 3.0
            assert held is not None and held.name.upper() not in ("OFFBOARD", "GUIDED"), held
            await v.land()

    port = free_port()
    with Vehicle("udpout:127.0.0.1:%d" % port, "--autopilot", autopilot):
        run(go("udpin:127.0.0.1:%d" % port), timeout=180)


def test_manual_control_moves_the_vehicle_in_a_position_mode():
    async def go(url):
        async with aio.connect(url) as gcs:
            v = await gcs.vehicle(timeout=10)
            await arm(v)
            await v.takeoff(10.0)
            async with v.manual_control(rate_hz=20) as mc:
                with pytest.raises(ValueError):
                    mc.set(2.0, 0.0, 0.5, 0.0)
                r = await v.set_mode("position_hold")
                assert r.accepted
                a = await v.position()
                mc.set(0.8, 0.0, 0.5, 0.0)
                deadline = time.monotonic() + 30
                moved = 0.0
                while time.monotonic() < deadline and moved < 3.0:
                    await asyncio.sleep(0.2)
                    b = await v.position()
                    moved = math.hypot((b.lat_deg - a.lat_deg) * M_PER_DEG,
                                       (b.lon_deg - a.lon_deg) * M_PER_DEG * math.cos(math.radians(a.lat_deg)))
                assert moved >= 3.0, moved
            await v.land()

    port = free_port()
    with Vehicle("udpout:127.0.0.1:%d" % port, "--autopilot", "ardupilot"):
        run(go("udpin:127.0.0.1:%d" % port), timeout=180)
