"""mavstack.aio's shell and RTK corrections: `vehicle.shell(...)` against the simulated
vehicle (`mavstack vehicle`, PX4's nsh; ArduPilot has no shell), and `vehicle.inject_rtcm(...)`
received by pymavlink as the vehicle, which puts GPS_RTCM_DATA back together itself."""

import asyncio
import os
import threading
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

import mavstack.aio as aio  # noqa: E402
from conftest import Vehicle, free_port  # noqa: E402


def run(coro, timeout=60):
    return asyncio.run(asyncio.wait_for(coro, timeout))


def test_shell_runs_commands_on_px4s_nsh():
    port = free_port()

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            ver = await vehicle.shell("ver all")
            assert ver.startswith("HW arch: MAVSTACK_SIM\n"), ver
            assert "\nPX4 version: Release 4.1.0 (67174655)\n" in ver, ver
            help_ = await vehicle.shell("help", timeout=20)
            assert "  listener\n" in help_ and len(help_) > 8 * 70, help_
            assert await vehicle.shell("nosuch") == "nsh: nosuch: command not found\n"
            with pytest.raises(aio.InvalidValueError, match="one line"):
                await vehicle.shell("ver\nhelp")

    with Vehicle("udpout:127.0.0.1:%d" % port, "--autopilot", "px4"):
        run(session())


def test_shell_on_ardupilot_is_a_timeout_with_the_reason():
    port = free_port()

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            with pytest.raises(aio.TimeoutError, match="ArduPilot has no such device"):
                await vehicle.shell("ver all")

    with Vehicle("udpout:127.0.0.1:%d" % port, "--autopilot", "ardupilot"):
        run(session())


class PymavlinkVehicle(threading.Thread):
    """pymavlink as a PX4 vehicle on UDP: HEARTBEAT twice a second, GPS_RTCM_DATA recorded."""

    def __init__(self):
        super().__init__(daemon=True)
        self.port = free_port()
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % self.port,
                                               source_system=1, source_component=1)
        self.raw = []
        self.stop = threading.Event()

    def run(self):
        beat = 0.0
        while not self.stop.is_set():
            if time.monotonic() >= beat:
                self.conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_QUADROTOR,
                                             mavutil.mavlink.MAV_AUTOPILOT_PX4, 0, 0, 3)
                beat = time.monotonic() + 0.5
            m = self.conn.recv_match(type="GPS_RTCM_DATA", blocking=True, timeout=0.05)
            if m is not None:
                self.raw.append((m.flags, bytes(m.data[:m.len])))

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.join(5)
        self.conn.close()


def whole_messages(raw):
    """GPS_RTCM_DATA put together as common.xml says (see tests-interop/rtk_interop.py)."""
    out, held, seq = [], {}, None
    for flags, data in raw:
        if not flags & 1:
            out.append(data)
            continue
        fid, s = (flags >> 1) & 3, flags >> 3
        if seq is not None and (s != seq or fid in held):
            held = {}
        seq, held[fid] = s, data
        short = next((i for i in sorted(held) if len(held[i]) < 180), None)
        count = 4 if short is None else short + 1
        if all(i in held for i in range(count)):
            out.append(b"".join(held[i] for i in range(count)))
            held, seq = {}, None
    return out


def test_inject_rtcm_reaches_a_pymavlink_vehicle_byte_for_byte():
    messages = [bytes(range(100)), bytes(i % 251 for i in range(360)), bytes(720), b"\x01" * 181]

    async def session(port):
        async with aio.connect("udpout:127.0.0.1:%d" % port) as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            counts = [await vehicle.inject_rtcm(m) for m in messages[:3]]
            counts.append(await vehicle.inject_rtcm(bytearray(messages[3])))
            assert counts == [1, 3, 4, 2]
            with pytest.raises(aio.InvalidValueError, match="721 bytes is longer than GPS_RTCM_DATA can carry"):
                await vehicle.inject_rtcm(bytes(721))
            with pytest.raises(aio.InvalidValueError, match="cannot be empty"):
                await vehicle.inject_rtcm(b"")

    with PymavlinkVehicle() as v:
        run(session(v.port))
        end = time.monotonic() + 10
        while len(v.raw) < 10 and time.monotonic() < end:
            time.sleep(0.05)
        time.sleep(0.3)
        assert [len(d) for _, d in v.raw] == [100, 180, 180, 0, 180, 180, 180, 180, 180, 1]
        assert whole_messages(v.raw) == messages
        assert [f >> 3 for f, _ in v.raw] == [0, 1, 1, 1, 2, 2, 2, 2, 3, 3]
