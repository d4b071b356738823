"""A ground station with mavstack.aio: the first vehicle heard, its parameters, a mission,
arming, a mode, its attitude at 10 Hz; and a served component answering commands.

    python aio_ground_station.py udpin:0.0.0.0:14550 [SERVE_CONN]

(typed: `mypy --strict aio_ground_station.py` passes)
"""

import asyncio
import sys
from typing import List, Optional

import mavstack.aio as aio


async def ground_station(device: str) -> None:
    async with aio.connect(device) as gcs:
        vehicle = await gcs.vehicle(timeout=10)
        print("vehicle", vehicle.system, "autopilot", vehicle.autopilot)
        params = await vehicle.params.get_all()
        print(len(params), "parameters via", vehicle.params.last_via)
        home = aio.MissionItem(16, frame=0, x=-353632610, y=1491652300, z=584.0)
        items: List[aio.MissionItem] = [home] + [
            aio.MissionItem(16, x=-353632610 + 100 * i, y=1491652300, z=20.0) for i in range(1, 6)
        ]
        await vehicle.mission.upload(items)
        back = await vehicle.mission.download()
        print("mission", len(back), "items")
        result = await vehicle.arm()
        print("arm:", result, *result.statustext)
        if result.accepted:
            print("disarm:", await vehicle.disarm())
        try:
            print("mode:", await vehicle.set_mode("RTL"))
        except aio.UnknownModeError as e:
            print("mode:", e)
        n = 0
        async for m in vehicle.telemetry("ATTITUDE", rate_hz=10):
            roll: float = m.roll
            n += 1
            if n == 5:
                print("roll %.3f rad" % roll)
                break
        try:
            await asyncio.wait_for(vehicle.params.get("NO_SUCH_PARAM"), 1.0)
        except TimeoutError:
            print("NO_SUCH_PARAM: no answer")


async def handle(request: aio.CommandRequest) -> Optional[str]:
    """Accepts MAV_CMD_USER_1, refuses the rest."""
    await asyncio.sleep(0)
    return None if request.name == "USER_1" else "UNSUPPORTED"


async def component(device: str) -> None:
    async with aio.serve(device, system=1, component=100, params={"CAM_EXPOSURE": 0.01},
                         on_command=handle) as server:
        await asyncio.sleep(30)
        print("set by ground stations:", server.changes())


async def main(argv: List[str]) -> None:
    if len(argv) > 2:
        await component(argv[2])
    else:
        await ground_station(argv[1] if len(argv) > 1 else "udpin:0.0.0.0:14550")


if __name__ == "__main__":
    asyncio.run(main(sys.argv))
