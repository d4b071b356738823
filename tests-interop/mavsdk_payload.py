#!/usr/bin/env python3
"""MAVSDK (the native binding `mavsdk` 4.1.0 from PyPI) against mavstack's camera and gimbal,
both ways, on loopback UDP.

    mavsdk_payload.py [--mavstack BIN] [--keep DIR] [--only camera,gimbal,camera-server]

MAVSDK's Camera, Gimbal and CameraServer plugins all live in the native binding (ctypes over
its bundled libcmavsdk, in this process: no mavsdk_server, no gRPC port, so no network
namespace is needed).

1. camera: MAVSDK's Camera plugin against `mavstack vehicle --autopilot px4 --camera DIR`
   (the simulated camera is component 100). MAVSDK lists it (vendor, model, resolution from
   CAMERA_INFORMATION), fetches its definition over MAVFTP (`mftp://camera.xml`; its cache
   is a fresh directory, so it has to), takes a photo: take_photo succeeds, its capture_info
   stream gives index 0, success, the file URL of DIR/IMG_0000.pgm and the vehicle's home,
   and that file is a PGM. Its settings: the current ones as the definition says under the
   defaults (CAM_ISO excluded under automatic exposure), CAM_PHOTOFMT's options; then
   set_setting CAM_PHOTOFMT=1 (PPM) and the next photo, index 1, is DIR/IMG_0001.ppm, a PPM;
   set_setting CAM_EXPMODE=1 (manual) brings CAM_ISO into the current settings and takes
   CAM_EV out. Its mode: photo; set_mode video, read back; set_mode photo again. Storage.
2. gimbal: MAVSDK's Gimbal plugin against the same vehicle's gimbal manager (component 1,
   device 1): listed; take_control primary (the control status names MAVSDK's own ids);
   set_angles pitch -30 yaw 45 in yaw-follow, and MAVSDK's attitude stream reads that back
   within 2 degrees (the model turns at 60 deg/s); set_angles pitch 10 yaw -90 in yaw-lock
   (north-referenced attitude); set_roi_location 100 m east and 100 m below home (MAVSDK
   sends COMMAND_INT in the relative-altitude frame) turns it to yaw 90, pitch -45;
   set_angular_rates yaw -20 deg/s turns it (the yaw falls); release_control leaves nobody
   in control.
3. camera-server: MAVSDK's CameraServer plugin (set_information, take-photo, storage and
   capture-status handlers answering with MAVSDK's own CaptureInfo) against
   `mavstack camera udpin:... list|photo|video|mode --json`: our client lists MAVSDK's
   camera (vendor, model, firmware, resolution), gets each photo with the index and URL the
   server gave (indices 7 and 8: the server's own count, not ours), and starts and stops a
   video and switches the mode through MAVSDK's handlers.

Every step has a deadline. Prints one JSON line (`"ok": true`, what was seen), or exits 1 with
the reason (and MAVSDK's and the vehicle's last log lines).
"""

import argparse
import asyncio
import json
import math
import os
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from gcs_common import HOME, Failure, Vehicle, fail, free_udp_port, mavstack_bin  # noqa: E402
from interop_checks import MAVSDK_LOG, quiet_mavsdk  # noqa: E402

STEP = 15.0
M_PER_DEG = 111_319.49
CAMERA_COMPONENT = 100


async def step(what, coro, timeout=STEP):
    """coro's result within `timeout`; a MAVSDK error is a failure naming its result."""
    try:
        return await asyncio.wait_for(coro, timeout)
    except asyncio.TimeoutError:
        fail(f"{what}: no result within {timeout} s")
    except Failure:
        raise
    except Exception as e:  # noqa: BLE001 - MAVSDK's errors carry their result
        result = getattr(e, "result", None)
        fail(f"{what}: {type(e).__name__} {getattr(result, 'name', result)}: {e}")


async def first(what, gen, pred, timeout=STEP):
    """The first value of MAVSDK stream `gen` satisfying pred, within `timeout`."""
    last = []

    async def run():
        async for v in gen:
            last[:] = [v]
            if pred(v):
                return v

    try:
        return await asyncio.wait_for(run(), timeout)
    except asyncio.TimeoutError:
        fail(f"{what}: not seen within {timeout} s (last: {last[0] if last else 'nothing'})")


def near(a, b, tol):
    return abs(a - b) <= tol


def angle_near(a, b, tol):
    return abs((a - b + 180.0) % 360.0 - 180.0) <= tol


# ---------------------------------------------------------------- 1: MAVSDK's Camera

async def check_camera(system, camera_dir):
    from mavsdk.asyncio.plugins.camera import CameraAsync
    from mavsdk.plugins.camera import Mode, Option, Setting

    cam = CameraAsync(system)
    out = {}
    listed = await first("camera: camera_list has component 100", cam.subscribe_camera_list(),
                         lambda cl: any(c.component_id == CAMERA_COMPONENT for c in cl.cameras))
    info = next(c for c in listed.cameras if c.component_id == CAMERA_COMPONENT)
    if (info.vendor_name, info.model_name) != ("mavstack", "Simulated camera") or (
            info.horizontal_resolution_px, info.vertical_resolution_px) != (320, 240):
        fail(f"camera: MAVSDK lists {info}; the simulated camera is mavstack Simulated camera, "
             "320x240")
    out["listed"] = f"{info.vendor_name} {info.model_name} {info.horizontal_resolution_px}x" \
                    f"{info.vertical_resolution_px}"

    captures = []
    seen = asyncio.Event()

    async def collect():
        async for c in cam.subscribe_capture_info():
            captures.append(c)
            seen.set()

    watcher = asyncio.ensure_future(collect())
    try:
        photos = []
        for index, ext, magic in ((0, "pgm", b"P5"), (1, "ppm", b"P6")):
            if index == 1:
                await step("camera: set_setting CAM_PHOTOFMT=1", cam.set_setting(
                    CAMERA_COMPONENT, Setting(setting_id="CAM_PHOTOFMT",
                                              option=Option(option_id="1"))))
            await step(f"camera: take_photo {index}", cam.take_photo(CAMERA_COMPONENT))
            deadline = time.monotonic() + STEP
            while not any(c.index == index for c in captures):
                if time.monotonic() > deadline:
                    fail(f"camera: no capture_info with index {index} within {STEP} s "
                         f"(got {[str(c) for c in captures]})")
                seen.clear()
                try:
                    await asyncio.wait_for(seen.wait(), 1.0)
                except asyncio.TimeoutError:
                    pass
            c = next(c for c in captures if c.index == index)
            path = os.path.join(camera_dir, f"IMG_{index:04d}.{ext}")
            if not c.is_success or c.file_url != f"file://{path}":
                fail(f"camera: photo {index}: capture_info {c}; expected success and "
                     f"file://{path}")
            if not (near(c.position.latitude_deg, HOME[0], 1e-4)
                    and near(c.position.longitude_deg, HOME[1], 1e-4)
                    and near(c.position.absolute_altitude_m, HOME[2], 5.0)):
                fail(f"camera: photo {index} taken at {c.position}; the vehicle is at {HOME}")
            try:
                with open(path, "rb") as f:
                    head = f.read(2)
            except OSError as e:
                fail(f"camera: photo {index}: {path} not written ({e})")
            if head != magic:
                fail(f"camera: {path} starts with {head!r}, not {magic!r}")
            photos.append({"index": c.index, "file_url": c.file_url})
        out["photos"] = photos
    finally:
        watcher.cancel()

    def by_id(settings):
        return {s.setting_id: s.option.option_id for s in settings}

    current = by_id(await step("camera: get_current_settings",
                               cam.get_current_settings(CAMERA_COMPONENT)))
    if current.get("CAM_EXPMODE") != "0" or current.get("CAM_PHOTOFMT") != "1" \
            or "CAM_ISO" in current or "CAM_EV" not in current:
        fail(f"camera: current settings {current}; expected CAM_EXPMODE 0 (auto), "
             "CAM_PHOTOFMT 1 (set above), CAM_EV, and no CAM_ISO (excluded under auto)")
    options = await step("camera: get_possible_setting_options",
                         cam.get_possible_setting_options(CAMERA_COMPONENT))
    fmt = next((o for o in options if o.setting_id == "CAM_PHOTOFMT"), None)
    if fmt is None or [(o.option_id, o.option_description) for o in fmt.options] != [
            ("0", "PGM"), ("1", "PPM")]:
        fail(f"camera: CAM_PHOTOFMT's options as MAVSDK reads the definition: {fmt}")
    await step("camera: set_setting CAM_EXPMODE=1", cam.set_setting(
        CAMERA_COMPONENT, Setting(setting_id="CAM_EXPMODE", option=Option(option_id="1"))))
    deadline = time.monotonic() + STEP
    while True:
        manual = by_id(await step("camera: get_current_settings",
                                  cam.get_current_settings(CAMERA_COMPONENT)))
        if manual.get("CAM_EXPMODE") == "1" and "CAM_ISO" in manual and "CAM_EV" not in manual:
            break
        if time.monotonic() > deadline:
            fail(f"camera: after CAM_EXPMODE=1 the current settings are {manual}; expected "
                 "CAM_ISO in, CAM_EV out")
        await asyncio.sleep(0.2)
    out["settings_manual"] = sorted(manual)

    # get_mode gives what MAVSDK last heard (UNKNOWN before that): its stream, then.
    await first("camera: mode photo (the simulated camera starts in it)", cam.subscribe_mode(),
                lambda m: m.component_id == CAMERA_COMPONENT and m.mode == Mode.PHOTO)
    await step("camera: set_mode video", cam.set_mode(CAMERA_COMPONENT, Mode.VIDEO))
    await first("camera: mode video", cam.subscribe_mode(),
                lambda m: m.component_id == CAMERA_COMPONENT and m.mode == Mode.VIDEO)
    await step("camera: set_mode photo", cam.set_mode(CAMERA_COMPONENT, Mode.PHOTO))
    await first("camera: mode photo", cam.subscribe_mode(),
                lambda m: m.component_id == CAMERA_COMPONENT and m.mode == Mode.PHOTO)
    out["modes"] = ["PHOTO", "VIDEO", "PHOTO"]
    storage = await step("camera: get_storage", cam.get_storage(CAMERA_COMPONENT))
    if not storage.total_storage_mib > 0:
        fail(f"camera: storage {storage}")
    out["storage_mib"] = storage.total_storage_mib
    return out


# ---------------------------------------------------------------- 2: MAVSDK's Gimbal

async def check_gimbal(system, own_ids):
    from mavsdk.asyncio.plugins.gimbal import GimbalAsync
    from mavsdk.plugins.gimbal import ControlMode, GimbalMode, SendMode

    g = GimbalAsync(system)
    out = {}
    listed = await first("gimbal: gimbal_list", g.subscribe_gimbal_list(),
                         lambda gl: len(gl.gimbals) > 0)
    item = listed.gimbals[0]
    if (item.gimbal_manager_component_id, item.gimbal_device_id) != (1, 1):
        fail(f"gimbal: MAVSDK lists {item}; the simulated gimbal is device 1 of the manager in "
             "component 1")
    gid = item.gimbal_id
    out["listed"] = f"{item.vendor_name} {item.model_name}, manager " \
                    f"{item.gimbal_manager_component_id}, device {item.gimbal_device_id}"

    await step("gimbal: take_control primary", g.take_control(gid, ControlMode.PRIMARY))
    await first("gimbal: control status names MAVSDK primary", g.subscribe_control_status(),
                lambda s: s.gimbal_id == gid and s.control_mode == ControlMode.PRIMARY
                and (s.sysid_primary_control, s.compid_primary_control) == own_ids)

    async def attitude(what, pred):
        return await first(f"gimbal: attitude {what}", g.subscribe_attitude(),
                           lambda a: a.gimbal_id == gid and pred(a))

    await step("gimbal: set_angles -30/45 follow", g.set_angles(
        gid, 0.0, -30.0, 45.0, GimbalMode.YAW_FOLLOW, SendMode.ONCE))
    a = await attitude("pitch -30 yaw 45 (vehicle frame)",
                       lambda a: near(a.euler_angle_forward.pitch_deg, -30.0, 2.0)
                       and angle_near(a.euler_angle_forward.yaw_deg, 45.0, 2.0))
    out["follow"] = [round(a.euler_angle_forward.pitch_deg, 1),
                     round(a.euler_angle_forward.yaw_deg, 1)]

    await step("gimbal: set_angles 10/-90 lock", g.set_angles(
        gid, 0.0, 10.0, -90.0, GimbalMode.YAW_LOCK, SendMode.ONCE))
    a = await attitude("pitch 10 yaw -90 (north)",
                       lambda a: near(a.euler_angle_north.pitch_deg, 10.0, 2.0)
                       and angle_near(a.euler_angle_north.yaw_deg, -90.0, 2.0))
    out["lock"] = [round(a.euler_angle_north.pitch_deg, 1), round(a.euler_angle_north.yaw_deg, 1)]

    east = 100.0 / (M_PER_DEG * math.cos(math.radians(HOME[0])))
    await step("gimbal: set_roi_location", g.set_roi_location(gid, HOME[0], HOME[1] + east,
                                                                -100.0))
    a = await attitude("at the ROI: yaw 90, pitch -45",
                       lambda a: near(a.euler_angle_north.pitch_deg, -45.0, 2.0)
                       and angle_near(a.euler_angle_north.yaw_deg, 90.0, 2.0))
    out["roi"] = [round(a.euler_angle_north.pitch_deg, 1), round(a.euler_angle_north.yaw_deg, 1)]

    await step("gimbal: set_angular_rates yaw -20", g.set_angular_rates(
        gid, 0.0, 0.0, -20.0, GimbalMode.YAW_FOLLOW, SendMode.ONCE))
    start = a.euler_angle_forward.yaw_deg
    a = await attitude("yaw falling at -20 deg/s",
                       lambda a: a.euler_angle_forward.yaw_deg < start - 5.0
                       and a.angular_velocity.yaw_rad_s < 0)
    out["rates_yaw_rad_s"] = round(a.angular_velocity.yaw_rad_s, 3)

    await step("gimbal: release_control", g.release_control(gid))
    await first("gimbal: nobody in control", g.subscribe_control_status(),
                lambda s: s.gimbal_id == gid and s.control_mode == ControlMode.NONE
                and s.sysid_primary_control == 0)
    return out


async def against_vehicle(binary, work, only):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

    camera_dir = os.path.join(work, "photos")
    os.makedirs(camera_dir, exist_ok=True)
    port = free_udp_port()
    vehicle = Vehicle(binary, f"udpout:127.0.0.1:{port}",
                      ["--autopilot", "px4", "--camera", camera_dir], work)
    cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    own_ids = (cfg.system_id, cfg.component_id)
    mav = Mavsdk(cfg)
    out = {}
    try:
        await mav.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await mav.first_autopilot(timeout_s=STEP)
        if system is None:
            fail(f"connect: no autopilot on udpin://127.0.0.1:{port} within {STEP} s")
        if "camera" in only:
            out["camera"] = await check_camera(system, camera_dir)
            if not any("mftp://camera.xml" in line for line in MAVSDK_LOG):
                fail("camera: MAVSDK never downloaded mftp://camera.xml (a cached definition?)")
        if "gimbal" in only:
            out["gimbal"] = await check_gimbal(system, own_ids)
        vehicle.check_alive()
    except BaseException:
        sys.stderr.write(f"--- vehicle log (tail) ---\n{vehicle.log(3000)}\n")
        raise
    finally:
        vehicle.stop()
    return out


# ---------------------------------------------------------------- 3: MAVSDK's CameraServer

def check_camera_server(binary):
    from mavsdk.component_type import ComponentType
    from mavsdk.mavsdk import Configuration, Mavsdk
    from mavsdk.plugins.camera_server import (
        CameraFeedback, CameraServer, CaptureInfo, CaptureStatus, Information, Position,
        Quaternion, StorageInformation)

    cfg = Configuration.create_with_component_type(ComponentType.CAMERA)
    cfg.system_id = 42
    sysid, compid = cfg.system_id, cfg.component_id
    mav = Mavsdk(cfg)
    port = free_udp_port()
    server = None
    lock = threading.Lock()
    state = {"count": 6, "sequences": [], "videos": [], "modes": []}
    where = Position(latitude_deg=47.3977419, longitude_deg=8.5455938,
                     absolute_altitude_m=488.5, relative_altitude_m=20.25)
    out = {"server": f"MAVSDK {mav.version()} camera server, system {sysid} component {compid}"}
    try:
        mav.add_any_connection(f"udpout://127.0.0.1:{port}")
        server = CameraServer(mav.server_component())
        r = server.set_information(Information(
            vendor_name="MAVSDK", model_name="CameraServer", firmware_version="4.1.2",
            focal_length_mm=3.04, horizontal_sensor_size_mm=3.68, vertical_sensor_size_mm=2.76,
            horizontal_resolution_px=3280, vertical_resolution_px=2464, lens_id=0,
            definition_file_version=0, definition_file_uri=""))
        if r not in (None, 0, 1) and getattr(r, "name", "SUCCESS") != "SUCCESS":
            fail(f"camera-server: set_information: {r}")

        def on_photo(sequence, _user=None):
            with lock:
                state["count"] += 1
                state["sequences"].append(sequence)
                index = state["count"]
            server.respond_take_photo(CameraFeedback.OK, CaptureInfo(
                position=where, attitude_quaternion=Quaternion(w=1.0, x=0.0, y=0.0, z=0.0),
                time_utc_us=int(time.time() * 1e6), is_success=True, index=index,
                file_url=f"https://camera.invalid/photos/DSC{index:05d}.jpg"))

        def on_storage(storage_id, _user=None):
            server.respond_storage_information(CameraFeedback.OK, StorageInformation(
                used_storage_mib=10.0, available_storage_mib=990.0, total_storage_mib=1000.0,
                storage_status=StorageInformation.StorageStatus.FORMATTED,
                storage_id=1, storage_type=StorageInformation.StorageType.SD))

        def on_status(_unused, _user=None):
            with lock:
                count = state["count"]
            server.respond_capture_status(CameraFeedback.OK, CaptureStatus(
                image_count=count, available_capacity_mib=990.0))

        def on_start_video(stream, _user=None):
            state["videos"].append(("start", stream))
            server.respond_start_video(CameraFeedback.OK)

        def on_stop_video(stream, _user=None):
            state["videos"].append(("stop", stream))
            server.respond_stop_video(CameraFeedback.OK)

        def on_mode(mode, _user=None):
            state["modes"].append(getattr(mode, "name", str(mode)))
            server.respond_set_mode(CameraFeedback.OK)

        server.subscribe_take_photo(on_photo)
        server.subscribe_storage_information(on_storage)
        server.subscribe_capture_status(on_status)
        server.subscribe_start_video(on_start_video)
        server.subscribe_stop_video(on_stop_video)
        server.subscribe_set_mode(on_mode)

        conn = f"udpin:127.0.0.1:{port}"

        def mavstack_camera(*args):
            cmd = [binary, "camera", conn, *args, "--json", "--target-system", str(sysid),
                   "--timeout", "10"]
            try:
                r = subprocess.run(cmd, capture_output=True, text=True, timeout=40)
            except subprocess.TimeoutExpired:
                fail(f"camera-server: `{' '.join(cmd)}` did not finish within 40 s")
            if r.returncode != 0:
                fail(f"camera-server: `{' '.join(cmd)}` exited {r.returncode}: {r.stderr.strip()}")
            try:
                return [json.loads(line) for line in r.stdout.splitlines() if line.strip()]
            except ValueError:
                fail(f"camera-server: `{' '.join(cmd)}` printed no JSON: {r.stdout!r}")

        listed = mavstack_camera("list")
        cam = next((c for c in listed if c.get("component") == {"system": sysid,
                                                                   "component": compid}), None)
        if cam is None or (cam.get("vendor"), cam.get("model"), cam.get("firmware"),
                           cam.get("resolution")) != ("MAVSDK", "CameraServer", "4.1.2.0",
                                                      [3280, 2464]):
            fail(f"camera-server: `mavstack camera list` gives {listed}; MAVSDK serves "
                 "MAVSDK CameraServer 4.1.2, 3280x2464")
        out["listed"] = {k: cam.get(k) for k in ("vendor", "model", "firmware", "resolution",
                                                  "storage")}
        photos = []
        for want in (7, 8):
            got = mavstack_camera("photo")
            photo = got[0] if got else {}
            url = f"https://camera.invalid/photos/DSC{want:05d}.jpg"
            if (photo.get("index"), photo.get("file_url"), photo.get("success")) != (want, url,
                                                                                     True):
                fail(f"camera-server: `mavstack camera photo` gives {got}; MAVSDK answered "
                     f"index {want}, {url}")
            if not (near(photo.get("lat", 0), where.latitude_deg, 1e-6)
                    and near(photo.get("lon", 0), where.longitude_deg, 1e-6)
                    and near(photo.get("alt", 0), where.absolute_altitude_m, 0.01)
                    and near(photo.get("relative_alt", 0), where.relative_altitude_m, 0.01)):
                fail(f"camera-server: photo {want} at {photo}; MAVSDK said {where}")
            photos.append({k: photo.get(k) for k in ("index", "file_url")})
        out["photos"] = photos
        out["sequences_received"] = list(state["sequences"])
        for action in ("start", "stop"):
            mavstack_camera("video", action)
        if [a for a, _ in state["videos"]] != ["start", "stop"]:
            fail(f"camera-server: MAVSDK's video handlers saw {state['videos']}")
        mavstack_camera("mode", "video")
        mavstack_camera("mode", "photo")
        if state["modes"] != ["VIDEO", "PHOTO"]:
            fail(f"camera-server: MAVSDK's set-mode handler saw {state['modes']}")
        out["videos"] = [a for a, _ in state["videos"]]
        out["modes"] = state["modes"]
    finally:
        if server is not None:
            server.destroy()
        mav.destroy()
    return out


# ---------------------------------------------------------------- main

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mavstack", help="the mavstack binary (default $MAVSTACK_BIN)")
    ap.add_argument("--keep", help="work directory to keep")
    ap.add_argument("--only", default="camera,gimbal,camera-server",
                    help="which checks, comma-separated")
    ap.add_argument("--show-log", action="store_true",
                    help="print MAVSDK's log (all but its DEBUG lines) to stderr at the end")
    args = ap.parse_args()
    only = set(args.only.split(","))
    t0 = time.monotonic()
    work = args.keep or tempfile.mkdtemp(prefix="mavsdk-payload-")
    os.makedirs(work, exist_ok=True)
    # MAVSDK caches camera definitions under $HOME/.cache: a fresh one, so that it fetches.
    os.environ["HOME"] = work
    code = 1
    try:
        try:
            import mavsdk  # noqa: F401
        except ImportError as e:
            fail(f"mavsdk (the native binding) is not installed ({e}); run scripts/setup-peers.sh")
        binary = mavstack_bin(args.mavstack)
        quiet_mavsdk()
        summary = {"script": "mavsdk_payload", "ok": True}
        if only & {"camera", "gimbal"}:
            summary.update(asyncio.run(against_vehicle(binary, work, only)))
        if "camera-server" in only:
            summary["camera_server"] = check_camera_server(binary)
        summary["seconds"] = round(time.monotonic() - t0, 3)
        print(json.dumps(summary), flush=True)
        code = 0
    except Failure as e:
        lines = [m for m in MAVSDK_LOG if not m.startswith("DEBUG")][-15:]
        for line in lines:
            print(f"  mavsdk log: {line}", file=sys.stderr)
        print(f"mavsdk_payload: FAILED: {e}", file=sys.stderr, flush=True)
    except Exception as e:  # noqa: BLE001 - an error in the client library is a failure too
        import traceback

        traceback.print_exc()
        print(f"mavsdk_payload: FAILED: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
    if args.show_log:
        for line in MAVSDK_LOG:
            if not line.startswith("DEBUG"):
                print(f"mavsdk log: {line}", file=sys.stderr)
    sys.stdout.flush()
    sys.stderr.flush()
    # Not sys.exit: a MAVSDK call still blocked in a worker thread must not hold the exit.
    os._exit(code)


if __name__ == "__main__":
    main()
