"""Flying a vehicle with mavstack.aio: its modes, arm, take off, fly north at 3 m/s with
offboard setpoints while this program is busy elsewhere, hold, land.

    python aio_flight.py udpin:0.0.0.0:14550

The setpoint stream is the library's (on its own thread): the loop below blocks for 200 ms
at a time and the vehicle still gets its 20 setpoints a second.

(typed: `mypy --strict aio_flight.py` passes)
"""

import asyncio
import sys
import time

import mavstack.aio as aio


async def arm(vehicle: aio.Vehicle, tries: int = 60) -> None:
    for _ in range(tries):
        result = await vehicle.arm()
        if result.accepted:
            return
        print("arming refused:", result, *result.statustext)
        await asyncio.sleep(3)
    raise SystemExit("the vehicle never armed")


async def fly(device: str) -> None:
    async with aio.connect(device) as gcs:
        vehicle = await gcs.vehicle(timeout=30)
        modes = await vehicle.modes()
        standard = [m.name for m in modes if m.standard]
        print(len(modes), "modes; standard:", ", ".join(standard))
        await arm(vehicle)
        await vehicle.takeoff(10.0)
        start = await vehicle.position()
        assert start is not None
        print("took off: %.1f m above home" % start.height_m)
        async with vehicle.offboard(rate_hz=20) as ob:
            ob.set_velocity_ned(3.0, 0.0, 0.0)
            for _ in range(25):
                time.sleep(0.2)  # a busy caller: the stream keeps its rate
                await asyncio.sleep(0)
            sent = ob.sent
        end = await vehicle.position()
        assert end is not None
        moved = (end.lat_deg - start.lat_deg) * 111_319.49
        mode = await vehicle.mode()
        print("offboard: %d setpoints, moved %.1f m north, now %s" % (
            sent, moved, mode.name if mode else "?"))
        await vehicle.land()
        print("landed and disarmed:", not vehicle.armed)


if __name__ == "__main__":
    asyncio.run(fly(sys.argv[1] if len(sys.argv) > 1 else "udpin:0.0.0.0:14550"))
