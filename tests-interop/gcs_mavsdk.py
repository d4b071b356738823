#!/usr/bin/env python3
"""MAVSDK (the real SDK, from PyPI) against `mavstack vehicle --autopilot px4` on loopback UDP.

    gcs_mavsdk.py --api native|grpc|both [--mavstack BIN] [--keep DIR] [--no-netns] [--via-router]

Two distinct Python packages, both driven through the same checks:

- `mavsdk` 4.1.0 (`--api native`): MAVSDK's native binding: ctypes over the bundled
  `mavsdk/lib/libcmavsdk.so` (MAVSDK's C API) in this process; no server, no gRPC. Used through
  its asyncio wrapper (`mavsdk.asyncio`: Mavsdk, first_autopilot, ActionAsync, TelemetryAsync...).
- `mavsdk-grpc` 4.0.5 (`--api grpc`, `import mavsdk_grpc`): the former `mavsdk` package (the
  gRPC wrapper, renamed at 4.x): `System.connect()` starts the bundled
  `mavsdk_grpc/bin/mavsdk_server` (a static binary), which speaks MAVLink to the vehicle and
  gRPC to this script.

mavsdk_server listens for gRPC on all interfaces, so unless --no-netns the script re-runs itself
in a new network namespace (`unshare -n`, then `lo` brought up as `ip link set lo up`
does, by ioctl) where the vehicle, mavsdk_server
and the script share a private loopback. Failing to do so fails the run (never skipped).

Checks, each with a deadline: connect (the autopilot is discovered); telemetry (position at the
vehicle's home -35.363261, 149.165230, 584 m AMSL; battery; armed false; a flight mode); params
(get_all_params holds the --params file's names with their values and the PX4 MAV_SYS_ID = 1;
get/set of an INT32 and a REAL32 read back); mission upload + download (same items); arm (armed
in telemetry); takeoff (relative altitude rises above 2 m, in air); land (back on the ground and
disarmed). Prints one JSON line with timings, exits 1 with the reason on any failure.

--via-router: the same checks with `mavstack router` in the middle, started by this script in
the same namespace (so on the same private loopback): the vehicle sends to the router's
`udpin:127.0.0.1:R?name=vehicle` link, the router's `udpout:127.0.0.1:G?name=gcs` link sends to
MAVSDK's `udpin://127.0.0.1:G`. At the end the router gets SIGTERM and must exit 0; both links
must have carried frames with nothing dropped for lack of a route; its stats are in the JSON.
"""

import argparse
import asyncio
import logging
import math
import os
import socket
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from scenario import free_port  # noqa: E402
from gcs_common import (  # noqa: E402
    HOME,
    Failure,
    Vehicle,
    check_router_carried,
    fail,
    free_udp_port,
    mavstack_bin,
    run_main,
    via_router,
)

# defaults of the PX4 flavour that get_all_params must show
PX4_PARAMS = {"MAV_SYS_ID": 1, "MPC_XY_CRUISE": 5.0, "MIS_TAKEOFF_ALT": 2.5, "NAV_ACC_RAD": 2.0}
TAKEOFF_ALT = 8.0
STEP_TIMEOUT = 20.0


def free_tcp_port():
    return free_port(socket.SOCK_STREAM)


async def step(what, coro, timeout=STEP_TIMEOUT):
    try:
        return await asyncio.wait_for(coro, timeout)
    except asyncio.TimeoutError:
        fail(f"{what}: no result within {timeout} s")


async def first(what, gen, pred=lambda _: True, timeout=STEP_TIMEOUT):
    """The first value of an async generator satisfying pred (with a deadline)."""
    last = []

    async def run():
        async for v in gen:
            last[:] = [v]
            if pred(v):
                return v

    try:
        return await asyncio.wait_for(run(), timeout)
    except asyncio.TimeoutError:
        fail(f"{what}: not seen within {timeout} s (last value: {last[0] if last else 'none'})")


class Native:
    """mavsdk 4.1.0: the native ctypes binding, through mavsdk.asyncio."""

    name = "mavsdk-native"

    async def connect(self, url):
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

        cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        self.mavsdk = Mavsdk(cfg)
        await self.mavsdk.add_any_connection(url)
        system = await self.mavsdk.first_autopilot(timeout_s=STEP_TIMEOUT)
        if system is None:
            fail(f"connect: no autopilot found on {url} within {STEP_TIMEOUT} s")
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mission import MissionAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        self.system = system
        self.action = ActionAsync(system)
        self.mission = MissionAsync(system)
        self.param = ParamAsync(system)
        self.telemetry = TelemetryAsync(system)
        return f"sysid {await system.get_system_id()}, autopilot {await system.autopilot_type()}"

    def stream(self, what):
        return getattr(self.telemetry, f"subscribe_{what}")()

    def mission_types(self):
        from mavsdk.plugins.mission import MissionItem, MissionPlan

        return MissionItem, MissionPlan

    async def close(self):
        await self.mavsdk.destroy()


class Grpc:
    """mavsdk-grpc 4.0.5: the gRPC wrapper with its bundled mavsdk_server."""

    name = "mavsdk-grpc"

    async def connect(self, url):
        import mavsdk_grpc

        self.drone = mavsdk_grpc.System(port=free_tcp_port())
        await self.drone.connect(system_address=url)
        await first("connect: core.connection_state is_connected",
                    self.drone.core.connection_state(), lambda s: s.is_connected)
        self.action = self.drone.action
        self.mission = self.drone.mission
        self.param = self.drone.param
        self.telemetry = self.drone.telemetry
        info = await step("info.get_version", self.drone.info.get_version(), 10)
        return f"flight sw {info.flight_sw_major}.{info.flight_sw_minor}.{info.flight_sw_patch}"

    def stream(self, what):
        return getattr(self.telemetry, what)()

    def mission_types(self):
        from mavsdk_grpc.mission import MissionItem, MissionPlan

        return MissionItem, MissionPlan

    async def close(self):
        self.drone._stop_mavsdk_server()


def mission_items(MissionItem):
    lat0, lon0, _ = HOME
    out = []
    for i in range(6):
        kw = dict(
            latitude_deg=round(lat0 + 0.0002 * (i + 1), 7),
            longitude_deg=round(lon0 + 0.0001 * (i % 3), 7),
            relative_altitude_m=15.0 + i,
            speed_m_s=float("nan"),
            is_fly_through=i % 2 == 0,
            gimbal_pitch_deg=float("nan"),
            gimbal_yaw_deg=float("nan"),
            camera_action=MissionItem.CameraAction.NONE,
            loiter_time_s=float("nan"),
            camera_photo_interval_s=float("nan"),
            acceptance_radius_m=float("nan"),
            yaw_deg=float("nan"),
            camera_photo_distance_m=float("nan"),
            vehicle_action=MissionItem.VehicleAction.NONE,
        )
        out.append(MissionItem(**kw))
    return out


def describe(it):
    return (f"({it.latitude_deg:.7f}, {it.longitude_deg:.7f}, {it.relative_altitude_m:.3f} m, "
            f"fly_through={it.is_fly_through})")


async def scenario(api, binary, work, via=False):
    summary = {"api": api.name}
    t_all = time.monotonic()
    router = None
    if via:
        router, port, gcs_ports = via_router(binary, work, [("gcs", "")])
        gcs_port = gcs_ports["gcs"]
    else:
        port = gcs_port = free_udp_port()
    try:
        vehicle = Vehicle(binary, f"udpout:127.0.0.1:{port}", ["--autopilot", "px4"], work)
    except Failure:
        if router is not None:
            router.kill()
        raise
    try:
        t = time.monotonic()
        summary["system"] = await step("connect", api.connect(f"udpin://127.0.0.1:{gcs_port}"), 25)
        summary["connect_s"] = round(time.monotonic() - t, 3)

        # telemetry
        t = time.monotonic()
        pos = await first("telemetry: position at home", api.stream("position"),
                          lambda p: not math.isnan(p.latitude_deg))
        if (abs(pos.latitude_deg - HOME[0]) > 1e-3 or abs(pos.longitude_deg - HOME[1]) > 1e-3
                or abs(pos.absolute_altitude_m - HOME[2]) > 5):
            fail(f"telemetry: position {pos.latitude_deg}, {pos.longitude_deg}, "
                 f"{pos.absolute_altitude_m} m AMSL; the vehicle's home is {HOME}")
        bat = await first("telemetry: battery", api.stream("battery"))
        if not (bat.voltage_v > 0 or bat.remaining_percent > 0):
            fail(f"telemetry: battery with neither voltage nor remaining: {bat}")
        armed = await first("telemetry: armed", api.stream("armed"))
        if armed:
            fail("telemetry: the vehicle is armed before we armed it")
        mode = await first("telemetry: flight mode", api.stream("flight_mode"))
        summary.update(telemetry_s=round(time.monotonic() - t, 3), flight_mode=getattr(mode, "name", str(mode)),
                       battery_v=round(bat.voltage_v, 2), battery_pct=bat.remaining_percent)

        # params
        t = time.monotonic()
        allp = await step("param.get_all_params", api.param.get_all_params(), 30)
        values = {p.name: p.value for p in list(allp.int_params) + list(allp.float_params)}
        summary["params"] = len(values)
        summary["param_get_all_s"] = round(time.monotonic() - t, 3)
        for name, want in PX4_PARAMS.items():
            if name not in values or abs(values[name] - want) > 1e-6:
                fail(f"params: get_all_params has {name} = {values.get(name)}, the PX4 flavour's "
                     f"default is {want}")
        t = time.monotonic()
        got = await step("param.get_param_int", api.param.get_param_int("MAV_SYS_ID"))
        if got != 1:
            fail(f"params: get_param_int(MAV_SYS_ID) = {got}, expected 1")
        got = await step("param.get_param_int", api.param.get_param_int("GF_ACTION"))
        if got != 2:
            fail(f"params: get_param_int(GF_ACTION) = {got}, expected 2")
        await step("param.set_param_int", api.param.set_param_int("GF_ACTION", 1))
        got = await step("param.get_param_int", api.param.get_param_int("GF_ACTION"))
        if got != 1:
            fail(f"params: GF_ACTION read back {got} after set_param_int 1")
        await step("param.set_param_float", api.param.set_param_float("MPC_XY_CRUISE", 7.25))
        gotf = await step("param.get_param_float", api.param.get_param_float("MPC_XY_CRUISE"))
        if abs(gotf - 7.25) > 1e-6:
            fail(f"params: MPC_XY_CRUISE read back {gotf} after set_param_float 7.25")
        summary["param_set_get_s"] = round(time.monotonic() - t, 3)

        # mission
        MissionItem, MissionPlan = api.mission_types()
        items = mission_items(MissionItem)
        t = time.monotonic()
        await step("mission.upload_mission", api.mission.upload_mission(MissionPlan(items)))
        summary["mission_upload_s"] = round(time.monotonic() - t, 3)
        t = time.monotonic()
        back = await step("mission.download_mission", api.mission.download_mission())
        summary["mission_download_s"] = round(time.monotonic() - t, 3)
        got_items = list(back.mission_items)
        if len(got_items) != len(items):
            fail(f"mission: uploaded {len(items)} items, downloaded {len(got_items)}: "
                 f"{[describe(i) for i in got_items]}")
        for i, (a, b) in enumerate(zip(items, got_items)):
            if (abs(a.latitude_deg - b.latitude_deg) > 1.5e-7
                    or abs(a.longitude_deg - b.longitude_deg) > 1.5e-7
                    or abs(a.relative_altitude_m - b.relative_altitude_m) > 1e-3
                    or a.is_fly_through != b.is_fly_through):
                fail(f"mission: item {i} uploaded {describe(a)}, downloaded {describe(b)}")
        summary["mission_items"] = len(items)

        # arm, takeoff, land
        t = time.monotonic()
        await step("action.arm", api.action.arm())
        await first("arm: armed in telemetry", api.stream("armed"), lambda a: a)
        summary["arm_s"] = round(time.monotonic() - t, 3)
        t = time.monotonic()
        await step("action.set_takeoff_altitude", api.action.set_takeoff_altitude(TAKEOFF_ALT))
        await step("action.takeoff", api.action.takeoff())
        pos = await first(f"takeoff: relative altitude above {TAKEOFF_ALT - 1} m",
                          api.stream("position"),
                          lambda p: p.relative_altitude_m > TAKEOFF_ALT - 1, 30)
        await first("takeoff: in air", api.stream("in_air"), lambda a: a)
        summary["takeoff_s"] = round(time.monotonic() - t, 3)
        summary["takeoff_alt_m"] = round(pos.relative_altitude_m, 2)
        t = time.monotonic()
        await step("action.land", api.action.land())
        await first("land: on the ground (in_air false)", api.stream("in_air"), lambda a: not a, 40)
        await first("land: disarmed after landing", api.stream("armed"), lambda a: not a, 20)
        pos = await first("land: position", api.stream("position"))
        if pos.relative_altitude_m > 1.0:
            fail(f"land: disarmed at {pos.relative_altitude_m} m above home")
        summary["land_s"] = round(time.monotonic() - t, 3)
        vehicle.check_alive()
        if router is not None:
            stats = router.stop()
            check_router_carried(stats, ["vehicle", "gcs"], "through the router")
            summary["router"] = {e["name"]: {k: e.get(k) for k in
                                             ("version", "rx_frames", "tx_frames", "converted",
                                              "dropped")}
                                 for e in stats.get("links", [])}
    except BaseException as e:
        if not isinstance(e, (KeyboardInterrupt, SystemExit)):
            sys.stderr.write(f"--- vehicle log (tail) ---\n{vehicle.log(2000)}\n")
            if router is not None:
                sys.stderr.write(router.describe() + "\n")
        raise
    finally:
        try:
            await asyncio.wait_for(api.close(), 5)
        except Exception:
            pass
        vehicle.stop()
        if router is not None:
            router.kill()
    summary["total_s"] = round(time.monotonic() - t_all, 3)
    return summary


def in_netns():
    return os.environ.get("MAVSTACK_GCS_NETNS") == "1"


def loopback_up():
    """Brings `lo` up in this (new) network namespace (what `ip link set lo up` does), then
    checks that a datagram to 127.0.0.1 arrives."""
    import fcntl
    import struct

    siocgifflags, siocsifflags, iff_up = 0x8913, 0x8914, 0x1
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        ifr = struct.pack("16sH22x", b"lo", 0)
        flags = struct.unpack("16sH22x", fcntl.ioctl(s, siocgifflags, ifr))[1]
        if not flags & iff_up:
            fcntl.ioctl(s, siocsifflags, struct.pack("16sH22x", b"lo", flags | iff_up))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        s.settimeout(2)
        s.sendto(b"ping", s.getsockname())
        if s.recv(16) != b"ping":
            fail("the network namespace's loopback does not carry a datagram")


def reexec_in_netns():
    """Runs this script again in a new network namespace (`unshare -n`); loopback_up() there."""
    cmd = [sys.executable, os.path.abspath(__file__), *sys.argv[1:]]
    env = dict(os.environ, MAVSTACK_GCS_NETNS="1")
    try:
        r = subprocess.run(["unshare", "-n", *cmd], env=env)
    except FileNotFoundError:
        print("gcs_mavsdk: FAILED: unshare not found (util-linux); mavsdk_server must run in its "
              "own network namespace", file=sys.stderr)
        sys.exit(1)
    if r.returncode != 0:
        print(f"gcs_mavsdk: FAILED: the run in `unshare -n` exited {r.returncode} (a failure "
              "above, or no permission for a network namespace: run as root)", file=sys.stderr)
    sys.exit(r.returncode)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--api", choices=["native", "grpc", "both"], default="both")
    ap.add_argument("--mavstack", help="the mavstack binary (default $MAVSTACK_BIN)")
    ap.add_argument("--keep", help="work directory to keep")
    ap.add_argument("--no-netns", action="store_true",
                    help="stay in the current network namespace")
    ap.add_argument("--via-router", action="store_true",
                    help="through `mavstack router` (in the same namespace)")
    args = ap.parse_args()
    if not args.no_netns and not in_netns():
        reexec_in_netns()

    def body():
        if in_netns():
            loopback_up()
        binary = mavstack_bin(args.mavstack)
        work = args.keep or tempfile.mkdtemp(prefix="gcs-mavsdk-")
        os.makedirs(work, exist_ok=True)
        logging.basicConfig(filename=os.path.join(work, "mavsdk.log"), level=logging.INFO)
        apis = {"native": [Native], "grpc": [Grpc], "both": [Native, Grpc]}[args.api]
        runs = []
        for cls in apis:
            try:
                api = cls()
            except ImportError as e:
                fail(f"{cls.name}: not installed ({e}); run scripts/setup-peers.sh")
            sub = os.path.join(work, cls.name)
            os.makedirs(sub, exist_ok=True)
            try:
                runs.append(asyncio.run(scenario(api, binary, sub, args.via_router)))
            except ImportError as e:
                fail(f"{cls.name}: not installed ({e}); run scripts/setup-peers.sh")
            except Exception as e:
                if type(e).__name__ == "Failure":
                    raise type(e)(f"{cls.name}: {e}") from None
                raise
        return {"netns": in_netns(), "via_router": args.via_router, "runs": runs}

    run_main("gcs_mavsdk", body)


if __name__ == "__main__":
    main()
