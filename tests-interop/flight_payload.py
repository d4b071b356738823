"""The `gimbal` and `camera` scenarios of tests-interop/flight_stacks.py (issue 41): `mavstack
gimbal` (gimbal protocol v2) and `mavstack camera` (camera protocol v2) against one vehicle.

A stack whose gimbal or camera must be switched on first gets it by its parameters and a
restart (the runner's --restart command); what was changed is put back afterwards (in effect
at the vehicle's next start):
  ArduPilot  a servo mount: MNT1_TYPE=1 with SERVO5/6/7_FUNCTION 8/7/6 (roll, pitch, yaw, as
             ArduPilot's autotest sets one up); a servo camera: CAM1_TYPE=1
  PX4        the gimbal module: MNT_MODE_IN=4 (gimbal protocol v2), MNT_MODE_OUT=0 (AUX)
  simulator  its gimbal is always there; its camera comes with `--camera DIR`, run by the
             runner's --camera-restart command and undone by --restart
Where a stack has no such thing, or does not do a step, the scenario is n/a with what
pymavlink asked the autopilot and what it answered.

  gimbal  `list` finds a manager; `set -30 20` and `attitude` read back within 3 degrees;
          `point` at a location 60 m north-east of the vehicle at its altitude ACCEPTED, then
          the gimbal looking there (bearing 45, pitch 0, within 5 degrees; up to 90 s: ArduPilot
          turns it once its estimator has a position); `clear` ACCEPTED
  camera  `list` finds a camera; `photo` gets its CAMERA_IMAGE_CAPTURED (n/a where the stack
          accepts MAV_CMD_IMAGE_START_CAPTURE but never sends one: pymavlink's capture shows
          what it sends instead); with a definition file, `settings` lists its settings and
          one with options is set to another option and back
"""
import json
import math
import os
import subprocess
import time

from pymavlink import mavutil

# What switches a stack's gimbal manager or camera on, keyed by a parameter only that stack has.
GIMBAL_PARAMS = {
    "MNT1_TYPE": [("MNT1_TYPE", 1), ("SERVO5_FUNCTION", 8), ("SERVO6_FUNCTION", 7), ("SERVO7_FUNCTION", 6)],
    "MNT_MODE_IN": [("MNT_MODE_IN", 4), ("MNT_MODE_OUT", 0)],
}
CAMERA_PARAMS = {"CAM1_TYPE": [("CAM1_TYPE", 1)]}
TOLERANCE_DEG = 3.0
CAMERA_INFORMATION, GIMBAL_MANAGER_INFORMATION = 259, 280  # message ids, for REQUEST_MESSAGE
# Where the targets start (flight-stacks.sh's ArduPilot --home, PX4 SIH's default), for when
# the vehicle does not tell its position.
HOMES = {"px4": (47.397742, 8.545594, 488.0), "other": (-35.363261, 149.165230, 584.0)}


def param_get(runner, name):
    rc, out, _, _ = runner.mavstack("param", "get", runner.conn, name, "--json", timeout=60)
    if rc != 0 or not out.strip():
        return None
    return json.loads(out.splitlines()[0])["value"]


def switch_on(runner, table):
    """Sets the parameters of the first stack in `table` whose key parameter the vehicle has.
    Returns (changed [(name, old value)], what was set) or (None, None) when none applies;
    raises RuntimeError when a set fails."""
    for key, params in table.items():
        if param_get(runner, key) is None:
            continue
        changed = []
        for name, value in params:
            old = param_get(runner, name)
            if old == value:
                continue
            rc, _, err, _ = runner.mavstack("param", "set", runner.conn, name, str(value), "--json", timeout=60)
            if rc != 0:
                raise RuntimeError("param set %s %s: %s" % (name, value, err.strip()[-200:]))
            changed.append((name, old))
        return changed, ", ".join("%s=%s" % p for p in params)
    return None, None


def put_back(runner, changed):
    for name, old in changed:
        runner.mavstack("param", "set", runner.conn, name, str(old), "--json", timeout=60)


def restart(runner, command):
    return subprocess.run(command, shell=True, timeout=120).returncode == 0


def until_found(runner, args, timeout=90.0):
    """Runs `mavstack ARGS` until it exits 0 (a restarted vehicle takes a while to answer)."""
    deadline = time.monotonic() + timeout
    while True:
        rc, out, err, _ = runner.mavstack(*args, "--timeout", "20", timeout=60)
        if rc == 0 or time.monotonic() > deadline:
            return rc, out, err
        time.sleep(2)


def ask_autopilot(conn, command, params, watch, seconds=4.0, target=None):
    """pymavlink as the independent peer: COMMAND_LONG `command` (7 params) to the autopilot
    (or `target`), then what came back for `seconds`: (COMMAND_ACK result name or None,
    {message name: the last one}). In MAVLink 2, so that messages above id 255 can come back
    (the simulator keeps to MAVLink 1 until it hears MAVLink 2)."""
    before = os.environ.get("MAVLINK20")
    os.environ["MAVLINK20"] = "1"
    try:
        m = mavutil.mavlink_connection(conn, source_system=254, source_component=190, dialect="ardupilotmega")
    finally:
        if before is None:
            del os.environ["MAVLINK20"]
    try:
        deadline = time.monotonic() + 15
        hb = None
        while time.monotonic() < deadline:
            hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=1)
            if hb is not None and hb.autopilot != mavutil.mavlink.MAV_AUTOPILOT_INVALID:
                break
            hb = None
        if hb is None:
            return "no HEARTBEAT from an autopilot", {}
        sysid, compid = target or (hb.get_srcSystem(), hb.get_srcComponent())
        m.mav.command_long_send(sysid, compid, command, 0, *params)
        ack, got = None, {}
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            msg = m.recv_match(type=["COMMAND_ACK"] + watch, blocking=True, timeout=0.2)
            if msg is None or msg.get_srcSystem() != sysid:
                continue
            if msg.get_type() == "COMMAND_ACK":
                if msg.command == command:
                    ack = mavutil.mavlink.enums["MAV_RESULT"][msg.result].name.replace("MAV_RESULT_", "")
            else:
                got[msg.get_type()] = msg
        return ack, got
    finally:
        m.close()


def asked(what, ack, got):
    """One phrase: what pymavlink asked and what came back."""
    came = ", ".join(sorted(got)) or "nothing else"
    return "%s: %s, %s" % (what, ack or "no COMMAND_ACK", came)


def first_json(out):
    try:
        return json.loads(out.splitlines()[0])
    except (ValueError, IndexError):
        return None


def vehicle_position(runner):
    """(lat, lon, alt MSL, heading or None) of GLOBAL_POSITION_INT (asked at 2 Hz); the target's
    home where it has no position yet (the vehicles sit there)."""
    rc, out, _, _ = runner.mavstack("listen", runner.conn, "--filter", "GLOBAL_POSITION_INT", "--rate",
                                    "GLOBAL_POSITION_INT:2", "--count", "1", "--duration", "10", timeout=30)
    p = first_json(out) if rc == 0 else None
    fields = (p or {}).get("fields") or {}
    heading = fields["hdg"] / 100.0 if fields.get("hdg", 65535) != 65535 else None
    if fields.get("lat"):
        return fields["lat"] / 1e7, fields["lon"] / 1e7, fields["alt"] / 1000.0, heading
    return HOMES["px4" if runner.name.startswith("px4") else "other"] + (heading,)


def looks_at(runner, bearing, pitch, timeout=90.0):
    """Polls `gimbal attitude` until it looks along `bearing` (from north) at `pitch`, within
    5 degrees, or `timeout` (ArduPilot turns only once its estimator has a position):
    (there, seconds, the last attitude). A yaw in the vehicle's frame is turned from north
    with the vehicle's heading read at the same time (ArduPilot's moves by some degrees while
    its estimator settles)."""
    t0 = time.monotonic()
    last = None
    while time.monotonic() - t0 < timeout:
        rc, out, _, _ = runner.mavstack("gimbal", runner.conn, "attitude", "--json")
        a = first_json(out) if rc == 0 else None
        if a is not None:
            earth = a.get("yaw_earth")
            if earth is None and a.get("yaw_vehicle") is not None:
                heading = vehicle_position(runner)[3]
                earth = None if heading is None else (a["yaw_vehicle"] + heading) % 360
            last = (a["pitch"], earth)
            if earth is not None and abs((earth - bearing + 180) % 360 - 180) <= 5 and abs(a["pitch"] - pitch) <= 5:
                return True, time.monotonic() - t0, last
        time.sleep(1)
    return False, time.monotonic() - t0, last


def gimbal(runner):
    t0 = time.monotonic()
    conn = runner.conn
    rc, out, err, _ = runner.mavstack("gimbal", conn, "list", "--json", "--timeout", "15")
    changed, notes = [], []
    if rc != 0:
        try:
            changed, what = switch_on(runner, GIMBAL_PARAMS)
        except RuntimeError as e:
            return runner.report("gimbal", "fail", time.monotonic() - t0, str(e))
        if changed is None:
            ack, got = ask_autopilot(conn, mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE,
                                     (GIMBAL_MANAGER_INFORMATION, 0, 0, 0, 0, 0, 0),
                                     ["GIMBAL_MANAGER_INFORMATION"])
            return runner.report("gimbal", "n/a", time.monotonic() - t0, "no gimbal manager: %s; %s" % (
                err.strip()[-160:], asked("pymavlink REQUEST_MESSAGE(GIMBAL_MANAGER_INFORMATION)", ack, got)))
        if changed:
            if not runner.restart_cmd:
                put_back(runner, changed)
                return runner.report("gimbal", "n/a", time.monotonic() - t0,
                                     "%s needs a restart and there is no --restart command" % what)
            restart(runner, runner.restart_cmd)
            notes.append("%s set, restarted" % what)
        rc, out, err = until_found(runner, ("gimbal", conn, "list", "--json"))
    try:
        ok, parts = gimbal_steps(runner, rc, out, err)
    finally:
        put_back(runner, changed)
    if changed:
        notes.append("put back after")
    runner.report("gimbal", "pass" if ok else "fail", time.monotonic() - t0,
                  "; ".join(parts + (["(%s)" % ", ".join(notes)] if notes else [])))


def gimbal_steps(runner, rc, out, err):
    """list, set and read back, point, clear: (ok, detail parts)."""
    conn = runner.conn
    g = first_json(out) if rc == 0 else None
    if g is None:
        return False, ["list: exit %s %s" % (rc, err.strip()[-200:])]
    parts = ["manager %d/%d device %d, pitch %s yaw %s" % (
        g["manager"]["system"], g["manager"]["component"], g["device_id"],
        "%g..%g" % tuple(g["pitch"]) if g.get("pitch") else "?", "%g..%g" % tuple(g["yaw"]) if g.get("yaw") else "?")]
    rc, out, err, _ = runner.mavstack("gimbal", conn, "set", "-30", "20", "--json")
    if rc != 0:
        return False, parts + ["set -30 20: exit %s %s" % (rc, err.strip()[-200:])]
    rc, out, err, _ = runner.mavstack("gimbal", conn, "attitude", "--json")
    a = first_json(out) if rc == 0 else None
    if a is None:
        return False, parts + ["attitude: exit %s %s" % (rc, err.strip()[-200:])]
    yaw = a.get("yaw_vehicle") if a.get("yaw_vehicle") is not None else a.get("yaw")
    ok = abs(a["pitch"] + 30) <= TOLERANCE_DEG and yaw is not None and abs(yaw - 20) <= TOLERANCE_DEG
    parts.append("set -30 20, read back pitch %.1f yaw %.1f (%s frame)" % (a["pitch"], yaw if yaw is not None
                                                                           else float("nan"), a.get("frame")))
    lat, lon, alt, _ = vehicle_position(runner)
    north, east = 42.4, 42.4  # 60 m north-east, at the vehicle's altitude: bearing 45, pitch 0
    plat = lat + north / 111320.0
    plon = lon + east / (111320.0 * math.cos(math.radians(lat)))
    rc, out, err, _ = runner.mavstack("gimbal", conn, "point", "%.7f" % plat, "%.7f" % plon, "%.1f" % alt, "--json")
    p = first_json(out) if rc == 0 else None
    ok &= p is not None and p.get("result") == "ACCEPTED"
    if p is None:
        parts.append("point: exit %s %s" % (rc, err.strip()[-200:]))
    else:
        there, secs, last = looks_at(runner, 45.0, 0.0)
        ok &= there
        parts.append("point 60 m NE %s, %s (pitch %s, %s from north)" % (
            p.get("result"), "looking there after %.0f s" % secs if there else "NOT looking there after %.0f s" % secs,
            "%.1f" % last[0] if last else "?", "%.1f" % last[1] if last and last[1] is not None else "?"))
    rc, out, err, _ = runner.mavstack("gimbal", conn, "clear", "--json")
    c = first_json(out) if rc == 0 else None
    ok &= c is not None and c.get("result") == "ACCEPTED"
    parts.append("clear %s" % (c.get("result") if c else "exit %s %s" % (rc, err.strip()[-200:])))
    return ok, parts


def camera(runner):
    t0 = time.monotonic()
    conn = runner.conn
    rc, out, err, _ = runner.mavstack("camera", conn, "list", "--json", "--timeout", "15")
    changed, notes, undo = [], [], None
    if rc != 0:
        if runner.camera_restart:
            restart(runner, runner.camera_restart)
            undo = runner.restart_cmd
            notes.append("restarted with its camera")
        else:
            try:
                changed, what = switch_on(runner, CAMERA_PARAMS)
            except RuntimeError as e:
                return runner.report("camera", "fail", time.monotonic() - t0, str(e))
            if changed is None:
                ack, got = ask_autopilot(conn, mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE,
                                         (CAMERA_INFORMATION, 0, 0, 0, 0, 0, 0),
                                         ["CAMERA_INFORMATION"])
                ack2, got2 = ask_autopilot(conn, mavutil.mavlink.MAV_CMD_IMAGE_START_CAPTURE, (0, 0, 1, 0, 0, 0, 0),
                                           ["CAMERA_IMAGE_CAPTURED", "CAMERA_FEEDBACK"])
                return runner.report("camera", "n/a", time.monotonic() - t0, "no camera: %s; %s; %s" % (
                    err.strip()[-160:],
                    asked("pymavlink REQUEST_MESSAGE(CAMERA_INFORMATION) to the autopilot", ack, got),
                    asked("MAV_CMD_IMAGE_START_CAPTURE", ack2, got2)))
            if changed:
                if not runner.restart_cmd:
                    put_back(runner, changed)
                    return runner.report("camera", "n/a", time.monotonic() - t0,
                                         "%s needs a restart and there is no --restart command" % what)
                restart(runner, runner.restart_cmd)
                notes.append("%s set, restarted" % what)
        rc, out, err = until_found(runner, ("camera", conn, "list", "--json"))
    try:
        status, parts = camera_steps(runner, rc, out, err)
    finally:
        put_back(runner, changed)
        if undo:
            restart(runner, undo)
    if changed:
        notes.append("put back after")
    runner.report("camera", status, time.monotonic() - t0,
                  "; ".join(parts + (["(%s)" % ", ".join(notes)] if notes else [])))


def camera_steps(runner, rc, out, err):
    """list, photo, settings: (status, detail parts)."""
    conn = runner.conn
    c = first_json(out) if rc == 0 else None
    if c is None:
        return "fail", ["list: exit %s %s" % (rc, err.strip()[-200:])]
    comp = (c["component"]["system"], c["component"]["component"])
    parts = ["camera %d/%d %s %s, flags %d, definition %s" % (
        comp[0], comp[1], c.get("vendor") or "(no vendor)", c.get("model") or "(no model)", c.get("flags", 0),
        c.get("definition_uri") or "none")]
    status = "pass"
    rc, out, err, _ = runner.mavstack("camera", conn, "photo", "--json", timeout=60)
    p = first_json(out) if rc == 0 else None
    if p is not None and p.get("success"):
        # Announced by CAMERA_IMAGE_CAPTURED, or by ArduPilot's CAMERA_FEEDBACK (no file URL).
        parts.append("photo %d announced, %s" % (
            p["index"], (p.get("file_url") or "no file URL").rsplit("/", 1)[-1]))
    else:
        # What the stack sends for a photo, seen by pymavlink.
        ack, got = ask_autopilot(conn, mavutil.mavlink.MAV_CMD_IMAGE_START_CAPTURE, (0, 0, 1, 0, 0, 0, 0),
                                 ["CAMERA_IMAGE_CAPTURED", "CAMERA_FEEDBACK"], target=comp)
        theirs = asked("pymavlink MAV_CMD_IMAGE_START_CAPTURE", ack, got)
        ours = "photo: exit %s %s" % (rc, (err.strip() or out.strip())[-200:])
        if ack == "ACCEPTED" and "CAMERA_IMAGE_CAPTURED" not in got:
            status = "n/a"
            parts.append("%s; %s: the stack never sends CAMERA_IMAGE_CAPTURED%s" % (
                ours, theirs, " (it sends CAMERA_FEEDBACK, img_idx %d)" % got["CAMERA_FEEDBACK"].img_idx
                if "CAMERA_FEEDBACK" in got else ""))
        else:
            status = "fail"
            parts.append("%s; %s" % (ours, theirs))
    if not c.get("definition_uri"):
        parts.append("settings: no definition file (cam_definition_uri empty)")
        return status, parts
    ok, detail = settings_steps(runner)
    parts.append(detail)
    return (status if ok else "fail"), parts


def settings_steps(runner):
    """The settings listed with the definition's descriptions; one with options set to another
    option and back: (ok, detail)."""
    conn = runner.conn
    rc, out, err, _ = runner.mavstack("camera", conn, "settings", "--json", timeout=60)
    rows = [json.loads(line) for line in out.splitlines() if line.startswith("{")] if rc == 0 else []
    if not rows:
        return False, "settings: exit %s %s" % (rc, err.strip()[-200:])
    described = sum(1 for r in rows if r.get("description"))
    detail = "settings: %d, %d described by the definition" % (len(rows), described)
    pick = next((r for r in rows if len(r.get("options") or []) >= 2 and not r.get("excluded")
                 and not r.get("read_only") and r["name"] != "CAM_MODE"), None)
    if pick is None:
        return described > 0, detail + ", none with options to set"
    other = next(o for o in pick["options"] if o["value"] != pick["value"])
    back = pick.get("option") or str(pick["value"])
    rc, out, err, _ = runner.mavstack("camera", conn, "settings", "--set", "%s=%s" % (pick["name"], other["name"]),
                                      "--json", timeout=60)
    now = next((json.loads(line) for line in out.splitlines()
                if line.startswith("{") and json.loads(line)["name"] == pick["name"]), None)
    set_ok = rc == 0 and now is not None and now["value"] == other["value"]
    rc2, _, err2, _ = runner.mavstack("camera", conn, "settings", "--set", "%s=%s" % (pick["name"], back), "--json",
                                      timeout=60)
    detail += ", %s %s -> %s %s, back %s" % (pick["name"], back, other["name"],
                                            "ok" if set_ok else "FAILED %s" % err.strip()[-150:],
                                            "ok" if rc2 == 0 else "FAILED %s" % err2.strip()[-150:])
    return described > 0 and set_ok and rc2 == 0, detail
