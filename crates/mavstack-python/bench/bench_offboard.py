"""The offboard setpoint stream's rate and jitter while the Python caller is busy.

    python bench_offboard.py [--seconds 10] [--rate 20] [--block 0.2]

A stand-in vehicle written with pymavlink (the independent peer: a PX4-flavoured HEARTBEAT,
armed; DO_SET_MODE acknowledged and reported; every SET_POSITION_TARGET_LOCAL_NED stamped
on arrival by a thread of its own) is flown through `mavstack.aio`: `async with
vehicle.offboard(rate_hz=RATE)`, then the caller blocks the event loop for BLOCK seconds at
a time (`time.sleep`) for SECONDS. Prints one JSON object: setpoints received, the rate, and
the intervals between them (p50, p99, max, ms). The stream is the library's, on its own
thread, so the intervals stay near 1/RATE whatever the caller does.
"""

import argparse
import asyncio
import json
import os
import socket
import sys
import threading
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

import mavstack.aio as aio  # noqa: E402

SET_POSITION_TARGET_LOCAL_NED = 84


class StandIn(threading.Thread):
    """A vehicle that accepts any mode and stamps every setpoint."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port, source_system=1,
                                               source_component=1)
        self.custom_mode = 0
        self.arrivals: list = []
        self.stop = False

    def heartbeat(self) -> None:
        m = mavutil.mavlink
        self.conn.mav.heartbeat_send(m.MAV_TYPE_QUADROTOR, m.MAV_AUTOPILOT_PX4,
                                     m.MAV_MODE_FLAG_SAFETY_ARMED | m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                     self.custom_mode, m.MAV_STATE_ACTIVE)

    def run(self) -> None:
        m = mavutil.mavlink
        last = 0.0
        while not self.stop:
            msg = self.conn.recv_match(blocking=True, timeout=0.05)
            now = time.monotonic()
            if now - last > 0.5 and self.conn.last_address is not None:
                self.heartbeat()
                last = now
            if msg is None:
                continue
            if msg.get_msgId() == SET_POSITION_TARGET_LOCAL_NED:
                self.arrivals.append(now)
            elif msg.get_type() == "COMMAND_LONG":
                result = m.MAV_RESULT_ACCEPTED
                if msg.command == m.MAV_CMD_DO_SET_MODE:
                    self.custom_mode = (int(msg.param2) << 16) | (int(msg.param3) << 24)
                elif msg.command == m.MAV_CMD_REQUEST_MESSAGE and int(msg.param1) == 0:
                    self.heartbeat()
                else:
                    result = m.MAV_RESULT_UNSUPPORTED
                self.conn.mav.command_ack_send(msg.command, result, 0, 0,
                                               msg.get_srcSystem(), msg.get_srcComponent())
                if msg.command == m.MAV_CMD_DO_SET_MODE:
                    self.heartbeat()


def percentile(values: list, p: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(round(p / 100 * (len(s) - 1))))]


async def main(a: argparse.Namespace) -> dict:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    vehicle = StandIn(port)
    vehicle.start()
    async with aio.connect("udpout:127.0.0.1:%d" % port) as gcs:
        v = await gcs.vehicle(timeout=10)
        async with v.offboard(rate_hz=a.rate) as ob:
            ob.set_velocity_ned(1.0, 0.0, 0.0)
            first = len(vehicle.arrivals)
            t0 = time.monotonic()
            while time.monotonic() - t0 < a.seconds:
                time.sleep(a.block)  # the caller busy: nothing runs on the loop meanwhile
                await asyncio.sleep(0)
            window = vehicle.arrivals[first:]
    vehicle.stop = True
    gaps = [1000 * (b - x) for x, b in zip(window, window[1:])]
    span = window[-1] - window[0] if len(window) > 1 else float("nan")
    return {
        "rate_asked_hz": a.rate,
        "caller_blocks_s": a.block,
        "seconds": a.seconds,
        "setpoints": len(window),
        "rate_hz": round((len(window) - 1) / span, 2) if len(window) > 1 else None,
        "interval_ms": {"p50": round(percentile(gaps, 50), 2), "p99": round(percentile(gaps, 99), 2),
                        "max": round(max(gaps), 2)} if gaps else None,
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=20.0)
    ap.add_argument("--block", type=float, default=0.2)
    print(json.dumps(asyncio.run(main(ap.parse_args()))))
    sys.exit(0)
