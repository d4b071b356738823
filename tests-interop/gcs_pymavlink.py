#!/usr/bin/env python3
"""`mavstack vehicle` driven by pymavlink 2.4.50's mavutil as the ground station, over loopback
UDP: parameters, waypoints, commands, message intervals and a flown mission.

Usage: gcs_pymavlink.py SCENARIO --mavstack BIN

pymavlink uses its own ardupilotmega dialect (from the wheel) and MAVLink 2 (MAVLINK20=1); the
vehicle runs on `udpout` towards pymavlink's `udpin`. Every expectation is checked on what
pymavlink decoded. Exit 0 with "<scenario>: ... ok", or 1 with FAIL lines.

Scenarios:
  params      --params FILE of 60 parameters of four types: PARAM_REQUEST_LIST returns every one
              (count, index, name, value as pymavlink decodes C-cast values); read by name and by
              index; PARAM_SET of an INT and a REAL answered with the new value and kept (read back);
              PX4 flavour: the same file's INT values come bytewise-encoded (struct reinterpretation)
  waypoints   pymavlink's MAVWPLoader: upload 12 items (MISSION_COUNT, answer each MISSION_REQUEST /
              MISSION_REQUEST_INT), MISSION_ACK accepted; download: same items field by field;
              MISSION_SET_CURRENT 3 -> MISSION_CURRENT 3; fence upload/download (mission_type 1);
              MISSION_CLEAR_ALL -> count 0
  commands    arm (400) -> ACK ACCEPTED and HEARTBEAT armed; DO_SET_MODE GUIDED (4) -> custom_mode 4;
              NAV_TAKEOFF 12 m -> relative_alt climbs past 10 m; DISARM in the air -> DENIED;
              a retry with confirmation 1 -> one ACK, no second effect; unknown command ->
              UNSUPPORTED; NAV_LAND -> lands and disarms (HEARTBEAT, EXTENDED_SYS_STATE)
  intervals   SET_MESSAGE_INTERVAL ATTITUDE 50 ms -> ATTITUDE every 50 ms by its time_boot_ms (the
              vehicle's clock, whatever the machine's load); REQUEST_MESSAGE(244, 30) ->
              MESSAGE_INTERVAL 50000; -1 -> no ATTITUDE until the third HEARTBEAT after the ACK;
              REQUEST_MESSAGE(242) -> HOME_POSITION at the SITL home; REQUEST_DATA_STREAM(POSITION,
              10 Hz) -> GLOBAL_POSITION_INT every 100 ms by its time_boot_ms
  clock       every time field counts from the vehicle's start, as a flight stack's from its boot:
              ATTITUDE and GLOBAL_POSITION_INT time_boot_ms (8 of each) at most the milliseconds
              the vehicle has run (+1 s) and rising from one message to the next; GPS_RAW_INT
              time_usec and TIMESYNC tc1 (the answer to a request) likewise in their units; the
              same with --autopilot px4
  mission     --autopilot px4: upload take-off, two waypoints, land; arm; DO_SET_MODE AUTO.MISSION;
              MISSION_ITEM_REACHED 0..3 in order, MISSION_CURRENT follows, the vehicle lands at
              the last waypoint and disarms; battery drains

The other way round, `mavstack param|mission|command` against a vehicle written here with
pymavlink alone (PymavlinkVehicle: ArduPilot-like, C-cast parameters, MISSION_ITEM_INT):
  cli_params        `param list --json` of 300 params (names, indices, values, types), `param set`
                    (the vehicle's table changes), `param get`
  cli_mission       a 40-item plan saved by pymavlink's MAVWPLoader: `mission upload` (the vehicle
                    stores the same items), `mission download FILE` (MAVWPLoader reads the same
                    items back), `mission clear`, `command arm` (the vehicle saw 400/1), an
                    UNSUPPORTED command -> exit 1
  cli_params_lossy, cli_mission_lossy
                    the same with the vehicle ignoring 20 % of what it receives and dropping 20 %
                    of what it sends: the retries and gap re-requests of our clients
"""

import argparse
import math
import os
import struct
import subprocess
import sys
import tempfile
import time

os.environ["MAVLINK20"] = "1"
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")
from pymavlink import mavutil, mavwp  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gcs_common import free_udp_port as free_port  # noqa: E402

M = mavutil.mavlink
HOME = (-35.363261, 149.165230)
FAILS = []
# How long a wait for a message that must come lasts (s): only one that never comes fails.
DEADLINE = 30.0


def fail(msg):
    FAILS.append(msg)
    print("FAIL:", msg, flush=True)


def check(cond, msg):
    if not cond:
        fail(msg)
    return cond


class Session:
    """A vehicle process and a pymavlink ground station talking to it."""

    def __init__(self, binary, *vehicle_args):
        port = free_port()
        self.gcs = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        # the vehicle's boot is after this: its time since boot is at most the time since this
        self.started = time.monotonic()
        self.proc = subprocess.Popen(
            [binary, "vehicle", f"udpout:127.0.0.1:{port}", *vehicle_args],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        hb = self.gcs.wait_heartbeat(timeout=10)
        if hb is None:
            self.close()
            raise SystemExit("FAIL: no HEARTBEAT from the vehicle within 10 s")
        self.target = (hb.get_srcSystem(), hb.get_srcComponent())
        # A MAVLink 2 frame switches the vehicle's link to MAVLink 2.
        self.gcs.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def close(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.gcs.close()

    def recv(self, types, timeout=DEADLINE, cond=None):
        deadline = time.time() + timeout
        while time.time() < deadline:
            m = self.gcs.recv_match(type=types, blocking=True, timeout=deadline - time.time())
            if m is None:
                return None
            if cond is None or cond(m):
                return m
        return None

    def command(self, cmd, *params, confirmation=0, wait=True):
        p = list(params) + [0.0] * (7 - len(params))
        self.gcs.mav.command_long_send(*self.target, cmd, confirmation, *p)
        if not wait:
            return None
        return self.recv("COMMAND_ACK", cond=lambda a: a.command == cmd)

    def heartbeat(self, cond, timeout=DEADLINE):
        return self.recv(
            "HEARTBEAT", timeout, lambda h: h.get_srcSystem() == self.target[0] and cond(h)
        )


def write_params(path):
    """60 parameters: INT (some negative), REAL, values exact in float."""
    rows = []
    for i in range(20):
        rows.append((f"TEST_INT_{i:02d}", -5000 + 517 * i))
    for i in range(20):
        rows.append((f"TEST_REAL_{i:02d}", 0.25 * i - 3.5))
    for i in range(20):
        rows.append((f"TEST_BIG_{i:02d}", 100000 + 3 * i))
    with open(path, "w") as f:
        f.write("# written by gcs_pymavlink.py\n")
        for name, value in rows:
            f.write(f"{name} {value}\n")
    return rows


def bytewise(value, param_type):
    """What a bytewise-encoded INT32 reads as when the float is taken at face value."""
    if param_type == M.MAV_PARAM_TYPE_REAL32:
        return value
    return struct.unpack("<f", struct.pack("<i", int(value)))[0]


def scenario_params(binary, autopilot):
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "params.parm")
        rows = write_params(path)
        s = Session(binary, "--autopilot", autopilot, "--params", path)
        try:
            s.gcs.mav.param_request_list_send(*s.target)
            got = {}
            deadline = time.time() + 10
            while time.time() < deadline and len(got) < len(rows):
                m = s.recv("PARAM_VALUE", 2.0)
                if m is None:
                    break
                check(m.param_count == len(rows), f"param_count {m.param_count} != {len(rows)}")
                got[m.param_id] = (m.param_index, m.param_value, m.param_type)
            check(len(got) == len(rows), f"received {len(got)} of {len(rows)} parameters")
            for i, (name, value) in enumerate(rows):
                if name not in got:
                    fail(f"{name} missing")
                    continue
                index, raw, ty = got[name]
                want_ty = M.MAV_PARAM_TYPE_INT32 if isinstance(value, int) else M.MAV_PARAM_TYPE_REAL32
                check(index == i, f"{name}: index {index} != {i}")
                check(ty == want_ty, f"{name}: type {ty} != {want_ty}")
                want = float(value) if autopilot == "ardupilot" else bytewise(value, ty)
                check(raw == want or (math.isnan(raw) and math.isnan(want)),
                      f"{name}: value {raw!r} != {want!r}")
            # Read by name and by index.
            s.gcs.mav.param_request_read_send(*s.target, b"TEST_REAL_05", -1)
            m = s.recv("PARAM_VALUE", 3.0, lambda m: m.param_id == "TEST_REAL_05")
            check(m is not None and m.param_value == -2.25 and m.param_index == 25,
                  f"read by name: {m}")
            s.gcs.mav.param_request_read_send(*s.target, b"", 7)
            m = s.recv("PARAM_VALUE", 3.0, lambda m: m.param_index == 7)
            check(m is not None and m.param_id == "TEST_INT_07", f"read by index: {m}")
            # Set an INT and a REAL; the answer carries the new value; read back.
            s.gcs.param_set_send("TEST_REAL_03", 42.5, M.MAV_PARAM_TYPE_REAL32)
            m = s.recv("PARAM_VALUE", 3.0, lambda m: m.param_id == "TEST_REAL_03")
            check(m is not None and m.param_value == 42.5, f"set REAL: {m}")
            if autopilot == "ardupilot":
                s.gcs.param_set_send("TEST_INT_02", 1234, M.MAV_PARAM_TYPE_INT32)
                want = 1234.0
            else:
                s.gcs.mav.param_set_send(*s.target, b"TEST_INT_02", bytewise(1234, 6), 6)
                want = bytewise(1234, 6)
            m = s.recv("PARAM_VALUE", 3.0, lambda m: m.param_id == "TEST_INT_02")
            check(m is not None and m.param_value == want, f"set INT: {m}")
            s.gcs.mav.param_request_read_send(*s.target, b"TEST_INT_02", -1)
            m = s.recv("PARAM_VALUE", 3.0, lambda m: m.param_id == "TEST_INT_02")
            check(m is not None and m.param_value == want, f"read back: {m}")
        finally:
            s.close()
    return f"{len(rows)} params fetched, read by name/index, set x2 ({autopilot})"


def make_items(target, count, mission_type=0):
    items = []
    for seq in range(count):
        items.append(M.MAVLink_mission_item_int_message(
            target[0], target[1], seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
            M.MAV_CMD_NAV_WAYPOINT if mission_type == 0 else M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
            0, 1, 1.5 * seq, 2.0, 0.0, float("nan") if seq == 5 else 0.0,
            int((HOME[0] + 0.0001 * seq) * 1e7), int((HOME[1] - 0.0001 * seq) * 1e7),
            10.0 + seq, mission_type))
    return items


def upload(s, items, mission_type=0):
    s.gcs.mav.mission_count_send(*s.target, len(items), mission_type)
    sent = set()
    deadline = time.time() + 15
    while time.time() < deadline:
        m = s.recv(["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"], 3.0)
        if m is None:
            fail("upload: no request/ack within 3 s")
            return False
        if m.get_type() == "MISSION_ACK":
            check(m.type == M.MAV_MISSION_ACCEPTED, f"upload ack {m.type}")
            check(sent == set(range(len(items))), f"requested {sorted(sent)}")
            return m.type == M.MAV_MISSION_ACCEPTED
        check(m.mission_type == mission_type, f"request for type {m.mission_type}")
        sent.add(m.seq)
        s.gcs.mav.send(items[m.seq])
    fail("upload did not finish")
    return False


def download(s, mission_type=0):
    s.gcs.mav.mission_request_list_send(*s.target, mission_type)
    c = s.recv("MISSION_COUNT", 3.0)
    if not check(c is not None, "no MISSION_COUNT"):
        return []
    out = []
    for seq in range(c.count):
        s.gcs.mav.mission_request_int_send(*s.target, seq, mission_type)
        m = s.recv("MISSION_ITEM_INT", 3.0, lambda m, seq=seq: m.seq == seq)
        if not check(m is not None, f"no item {seq}"):
            return out
        out.append(m)
    s.gcs.mav.mission_ack_send(*s.target, M.MAV_MISSION_ACCEPTED, mission_type)
    return out


FIELDS = ["seq", "frame", "command", "autocontinue", "param1", "param2", "param3", "param4",
          "x", "y", "z", "mission_type"]


def same_items(sent, got, what):
    check(len(sent) == len(got), f"{what}: {len(got)} items back of {len(sent)}")
    for a, b in zip(sent, got):
        for f in FIELDS:
            va, vb = getattr(a, f), getattr(b, f)
            same = va == vb or (isinstance(va, float) and math.isnan(va) and math.isnan(vb))
            check(same, f"{what} item {a.seq} {f}: sent {va!r} got {vb!r}")


def scenario_waypoints(binary):
    s = Session(binary)
    try:
        items = make_items(s.target, 12)
        # MAVWPLoader holds the plan as pymavlink's own mission tools do.
        loader = mavwp.MAVWPLoader(target_system=s.target[0], target_component=s.target[1])
        for it in items:
            loader.add(it)
        check(loader.count() == 12, "loader count")
        upload(s, [loader.wp(i) for i in range(loader.count())])
        same_items(items, download(s), "mission")
        s.gcs.mav.mission_set_current_send(*s.target, 3)
        m = s.recv("MISSION_CURRENT", 3.0, lambda m: m.seq == 3)
        check(m is not None, "MISSION_CURRENT 3 after MISSION_SET_CURRENT")
        fence = make_items(s.target, 4, mission_type=1)
        upload(s, fence, mission_type=1)
        same_items(fence, download(s, 1), "fence")
        same_items(items, download(s), "mission after fence upload")
        s.gcs.mav.mission_clear_all_send(*s.target, 0)
        a = s.recv("MISSION_ACK", 3.0)
        check(a is not None and a.type == M.MAV_MISSION_ACCEPTED, f"clear ack {a}")
        s.gcs.mav.mission_request_list_send(*s.target, 0)
        c = s.recv("MISSION_COUNT", 3.0)
        # ArduPilot keeps home as item 0: a cleared mission still has that one item.
        check(c is not None and c.count == 1, f"count after clear {c}, expected 1 (home)")
        s.gcs.mav.mission_request_int_send(*s.target, 0, 0)
        home = s.recv("MISSION_ITEM_INT", 3.0)
        check(home is not None and home.seq == 0 and home.command == M.MAV_CMD_NAV_WAYPOINT
              and home.x == -353632610 and home.y == 1491652300,
              f"item 0 after clear {home}, expected home")
        s.gcs.mav.mission_ack_send(*s.target, M.MAV_MISSION_ACCEPTED, 0)
    finally:
        s.close()
    return ("12-item mission and 4-item fence uploaded/downloaded, set current, cleared "
            "(home stays as item 0)")


def scenario_commands(binary):
    s = Session(binary, "--autopilot", "ardupilot")
    try:
        a = s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"arm ack {a}")
        check(s.heartbeat(lambda h: h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED) is not None,
              "no armed HEARTBEAT")
        a = s.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"mode ack {a}")
        check(s.heartbeat(lambda h: h.custom_mode == 4) is not None, "no GUIDED HEARTBEAT")
        a = s.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 12)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"takeoff ack {a}")
        # A retry of the same command (confirmation 1) is answered, not run again.
        a = s.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 12, confirmation=1)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"retry ack {a}")
        m = s.recv("GLOBAL_POSITION_INT", 12.0, lambda m: m.relative_alt > 10000)
        check(m is not None, "never climbed past 10 m")
        a = s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0)
        check(a is not None and a.result == M.MAV_RESULT_DENIED, f"disarm in the air: {a}")
        a = s.command(M.MAV_CMD_DO_FLIGHTTERMINATION, 1)
        check(a is not None and a.result == M.MAV_RESULT_UNSUPPORTED, f"unknown command: {a}")
        a = s.command(M.MAV_CMD_NAV_LAND)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"land ack {a}")
        check(s.heartbeat(lambda h: h.custom_mode == 9) is not None, "no LAND HEARTBEAT")
        e = s.recv("EXTENDED_SYS_STATE", 5.0,
                   lambda e: e.landed_state == M.MAV_LANDED_STATE_LANDING)
        check(e is not None, "never LANDING")
        hb = s.heartbeat(lambda h: not h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 40.0)
        check(hb is not None, "did not land and disarm")
        m = s.recv("GLOBAL_POSITION_INT", 3.0)
        check(m is not None and abs(m.relative_alt) < 100, f"not on the ground: {m}")
    finally:
        s.close()
    return "arm, GUIDED, takeoff 12 m, retry deduplicated, disarm refused aloft, land, disarm"


def until(s, cond):
    """Every message received until one that meets cond (included), or all until DEADLINE."""
    got = []
    deadline = time.time() + DEADLINE
    while time.time() < deadline:
        m = s.gcs.recv_match(blocking=True, timeout=deadline - time.time())
        if m is None:
            break
        got.append(m)
        if cond(m):
            break
    return got


def check_interval(s, msg_type, every_ms, what, n=21):
    """The next n messages of msg_type come every every_ms on the vehicle's own clock
    (time_boot_ms), whatever the machine's load does to when they leave and arrive. The stream
    scheduler keeps the cadence (a message is due every_ms after the one before, leaves at or
    after that, and before the next is due; after a stall longer than that the cadence starts
    again): n messages span more than n - 2 intervals (never faster than asked, a bound that
    holds however late each one left), and the closest two are less than 1.5 intervals apart
    (the stream runs at the asked rate, not at a slower one: only a vehicle held up for longer
    than an interval at every other message would fail this)."""
    times = []
    while len(times) < n:
        m = s.recv(msg_type)
        if not check(m is not None, f"{what}: {len(times)} {msg_type} of {n}"):
            return
        times.append(m.time_boot_ms)
    gaps = [b - a for a, b in zip(times, times[1:])]
    # time_boot_ms is cut to whole milliseconds: 1 ms of slack.
    check(times[-1] - times[0] >= (n - 2) * every_ms - 1,
          f"{what}: {n} {msg_type} within {times[-1] - times[0]} ms of the vehicle's time, asked one every "
          f"{every_ms} ms (gaps {gaps})")
    check(min(gaps) < 1.5 * every_ms,
          f"{what}: {msg_type} at least {min(gaps)} ms apart on the vehicle's clock, asked every {every_ms} ms "
          f"(gaps {gaps})")


def scenario_intervals(binary):
    s = Session(binary)
    try:
        # What comes after the ACK was sent after the vehicle changed the interval.
        a = s.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, 30, 50000)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"interval ack {a}")
        check_interval(s, "ATTITUDE", 50, "SET_MESSAGE_INTERVAL 50 ms")
        a = s.command(M.MAV_CMD_REQUEST_MESSAGE, 244, 30)
        m = s.recv("MESSAGE_INTERVAL", cond=lambda m: m.message_id == 30)
        check(m is not None and m.interval_us == 50000, f"MESSAGE_INTERVAL {m}")
        a = s.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, 30, -1)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"disable ack {a}")
        # From the ACK to the vehicle's third HEARTBEAT after it: two seconds of its own time,
        # and its scheduler ran at the second with ATTITUDE long due, had it been on.
        after = []
        for _ in range(3):
            after += until(s, lambda m: m.get_type() == "HEARTBEAT")
        n_hb = sum(m.get_type() == "HEARTBEAT" for m in after)
        check(n_hb == 3, f"{n_hb} HEARTBEATs of 3 after the stream was turned off")
        check(not [m for m in after if m.get_type() == "ATTITUDE"], "ATTITUDE still streaming after -1")
        a = s.command(M.MAV_CMD_REQUEST_MESSAGE, 242)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"request ack {a}")
        h = s.recv("HOME_POSITION")
        check(h is not None and abs(h.latitude / 1e7 - HOME[0]) < 1e-6
              and abs(h.longitude / 1e7 - HOME[1]) < 1e-6, f"HOME_POSITION {h}")
        # No ACK for REQUEST_DATA_STREAM: a command after it is answered after it took effect.
        s.gcs.mav.request_data_stream_send(*s.target, M.MAV_DATA_STREAM_POSITION, 10, 1)
        a = s.command(M.MAV_CMD_REQUEST_MESSAGE, 242)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"request ack {a}")
        check_interval(s, "GLOBAL_POSITION_INT", 100, "REQUEST_DATA_STREAM(POSITION, 10 Hz)")
    finally:
        s.close()
    return ("SET_MESSAGE_INTERVAL 50 ms on the vehicle's clock, MESSAGE_INTERVAL, off, HOME_POSITION, "
            "data stream 100 ms")


# what the vehicle's time since its start may exceed our time since we started it by (the
# process start lies between the two)
CLOCK_SLACK_S = 1.0


def scenario_clock(binary):
    for autopilot in ("ardupilot", "px4"):
        s = Session(binary, "--autopilot", autopilot)
        try:
            def ran(scale):
                """The time since the vehicle was started, plus the slack, in 1/scale s."""
                return (time.monotonic() - s.started + CLOCK_SLACK_S) * scale

            boot_ms = {"ATTITUDE": [], "GLOBAL_POSITION_INT": []}
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and min(map(len, boot_ms.values())) < 8:
                m = s.recv(list(boot_ms), 3.0)
                if not check(m is not None, f"{autopilot}: no ATTITUDE/GLOBAL_POSITION_INT"):
                    break
                limit = ran(1e3)
                boot_ms[m.get_type()].append(m.time_boot_ms)
                check(m.time_boot_ms <= limit,
                      f"{autopilot}: {m.get_type()}.time_boot_ms {m.time_boot_ms}, above the "
                      f"{limit:.0f} ms the vehicle can have run (1 s slack included)")
            for name, values in boot_ms.items():
                check(len(values) >= 8, f"{autopilot}: {len(values)} {name} received, expected 8")
                check(all(a < b for a, b in zip(values, values[1:])),
                      f"{autopilot}: {name}.time_boot_ms does not rise: {values}")
            g = s.recv("GPS_RAW_INT", 5.0)
            limit = ran(1e6)
            if check(g is not None, f"{autopilot}: no GPS_RAW_INT"):
                check(g.time_usec <= limit,
                      f"{autopilot}: GPS_RAW_INT.time_usec {g.time_usec}, above the {limit:.0f} "
                      "us the vehicle can have run (1 s slack included)")
            s.gcs.mav.timesync_send(0, 1234567)
            t = s.recv("TIMESYNC", 3.0, lambda m: m.ts1 == 1234567 and m.tc1 != 0)
            limit = ran(1e9)
            if check(t is not None, f"{autopilot}: no answer to TIMESYNC"):
                check(t.tc1 <= limit,
                      f"{autopilot}: TIMESYNC tc1 {t.tc1}, above the {limit:.0f} ns the vehicle "
                      "can have run (1 s slack included)")
        finally:
            s.close()
    return ("ATTITUDE, GLOBAL_POSITION_INT, GPS_RAW_INT and TIMESYNC times count from the "
            "vehicle's start and rise (ardupilot, px4)")


def scenario_mission(binary):
    s = Session(binary, "--autopilot", "px4")
    try:
        t = s.target
        north = lambda metres: int((HOME[0] + metres / 111319.49) * 1e7)  # noqa: E731
        lon = int(HOME[1] * 1e7)
        frame = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        items = [
            M.MAVLink_mission_item_int_message(*t, 0, frame, M.MAV_CMD_NAV_TAKEOFF, 0, 1,
                                               0, 0, 0, float("nan"), north(0), lon, 8.0, 0),
            M.MAVLink_mission_item_int_message(*t, 1, frame, M.MAV_CMD_NAV_WAYPOINT, 0, 1,
                                               0, 0, 0, float("nan"), north(15), lon, 8.0, 0),
            M.MAVLink_mission_item_int_message(*t, 2, frame, M.MAV_CMD_NAV_WAYPOINT, 0, 1,
                                               0, 0, 0, float("nan"), north(30), lon, 6.0, 0),
            M.MAVLink_mission_item_int_message(*t, 3, frame, M.MAV_CMD_NAV_LAND, 0, 1,
                                               0, 0, 0, float("nan"), north(30), lon, 0.0, 0),
        ]
        upload(s, items)
        b0 = s.recv("BATTERY_STATUS", 3.0)
        a = s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"arm {a}")
        a = s.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 4)
        check(a is not None and a.result == M.MAV_RESULT_ACCEPTED, f"AUTO.MISSION {a}")
        reached = []
        currents = set()
        deadline = time.time() + 60
        while time.time() < deadline and len(reached) < 4:
            m = s.recv(["MISSION_ITEM_REACHED", "MISSION_CURRENT"], 5.0)
            if m is None:
                break
            if m.get_type() == "MISSION_ITEM_REACHED":
                reached.append(m.seq)
            else:
                currents.add(m.seq)
        check(reached == [0, 1, 2, 3], f"MISSION_ITEM_REACHED {reached}")
        check({1, 2, 3} <= currents, f"MISSION_CURRENT seen {sorted(currents)}")
        hb = s.heartbeat(lambda h: not h.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 10.0)
        check(hb is not None, "not disarmed after landing")
        p = s.recv("GLOBAL_POSITION_INT", 3.0)
        if check(p is not None, "no position"):
            metres = (p.lat / 1e7 - HOME[0]) * 111319.49
            check(abs(metres - 30) < 1.5 and abs(p.relative_alt) < 100,
                  f"landed {metres:.1f} m north at {p.relative_alt} mm")
        b1 = s.recv("BATTERY_STATUS", 3.0)
        check(b0 is not None and b1 is not None and b1.current_consumed > b0.current_consumed
              and b1.battery_remaining <= b0.battery_remaining, f"battery {b0} -> {b1}")
    finally:
        s.close()
    return "4-item PX4 mission flown: reached 0..3, landed 30 m north, disarmed, battery drained"


class PymavlinkVehicle:
    """A vehicle written with pymavlink alone (ArduPilot-like: C-cast parameters, MISSION_ITEM_INT
    protocol), serving one ground station on udpin, in a thread. With `loss`, it ignores that
    share of what it receives and drops that share of what it sends (seeded)."""

    def __init__(self, params, loss=0.0, seed=7):
        import random
        import threading
        self.port = free_port()
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{self.port}", source_system=1, source_component=1)
        self.params = list(params)  # [(name, value, type)]
        self.mission = []
        self.loss = loss
        self.rng = random.Random(seed)
        self.stop = False
        self.upload = None
        self.commands = []
        self.sent_values = 0
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def send(self, msg):
        if self.rng.random() < self.loss:
            return
        try:
            self.conn.mav.send(msg)
        except OSError:
            pass

    def value(self, i):
        name, value, ty = self.params[i]
        self.sent_values += 1
        return M.MAVLink_param_value_message(name.encode(), float(value), ty, len(self.params), i)

    def run(self):
        next_beat = 0
        while not self.stop:
            now = time.time()
            # udpin: pymavlink writes to every client heard, so beat once a GCS has spoken.
            if now >= next_beat and self.conn.clients:
                self.send(M.MAVLink_heartbeat_message(
                    M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                    M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, M.MAV_STATE_STANDBY, 3))
                next_beat = now + 1
            m = self.conn.recv_match(blocking=True, timeout=0.05)
            if m is None or self.rng.random() < self.loss:
                continue
            self.handle(m)

    def handle(self, m):
        t = m.get_type()
        if t == "PARAM_REQUEST_LIST":
            for i in range(len(self.params)):
                self.send(self.value(i))
        elif t == "PARAM_REQUEST_READ":
            if m.param_index >= 0:
                i = m.param_index
            else:
                names = [p[0] for p in self.params]
                i = names.index(m.param_id) if m.param_id in names else None
            if i is not None and i < len(self.params):
                self.send(self.value(i))
        elif t == "PARAM_SET":
            for i, (name, _, ty) in enumerate(self.params):
                if name == m.param_id:
                    v = m.param_value if ty == M.MAV_PARAM_TYPE_REAL32 else float(int(m.param_value))
                    self.params[i] = (name, v, ty)
                    self.send(self.value(i))
        elif t == "MISSION_COUNT":
            self.upload = [None] * m.count
            if m.count == 0:
                self.mission = []
                self.send(M.MAVLink_mission_ack_message(255, 190, M.MAV_MISSION_ACCEPTED, 0))
            else:
                self.send(M.MAVLink_mission_request_int_message(255, 190, 0, 0))
        elif t == "MISSION_ITEM_INT" and self.upload is None:
            # The last item again: our ACK was lost. ACK again, as autopilots do.
            if self.mission and m.seq == len(self.mission) - 1:
                self.send(M.MAVLink_mission_ack_message(255, 190, M.MAV_MISSION_ACCEPTED, 0))
        elif t == "MISSION_ITEM_INT":
            if m.seq < len(self.upload):
                self.upload[m.seq] = m
            missing = [i for i, x in enumerate(self.upload) if x is None]
            if missing:
                self.send(M.MAVLink_mission_request_int_message(255, 190, missing[0], 0))
            else:
                self.mission = self.upload
                self.upload = None
                self.send(M.MAVLink_mission_ack_message(255, 190, M.MAV_MISSION_ACCEPTED, 0))
        elif t == "MISSION_REQUEST_LIST":
            self.send(M.MAVLink_mission_count_message(255, 190, len(self.mission), 0))
        elif t in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            if m.seq < len(self.mission):
                it = self.mission[m.seq]
                self.send(M.MAVLink_mission_item_int_message(
                    255, 190, it.seq, it.frame, it.command, it.current, it.autocontinue,
                    it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, 0))
        elif t == "MISSION_CLEAR_ALL":
            self.mission = []
            self.send(M.MAVLink_mission_ack_message(255, 190, M.MAV_MISSION_ACCEPTED, 0))
        elif t == "COMMAND_LONG":
            self.commands.append((m.command, m.param1, m.confirmation))
            result = M.MAV_RESULT_ACCEPTED if m.command == 400 else M.MAV_RESULT_UNSUPPORTED
            self.send(M.MAVLink_command_ack_message(m.command, result, 0, 0, 255, 190))

    def close(self):
        self.stop = True
        self.thread.join(timeout=2)
        self.conn.close()


def cli(binary, port, *args):
    cmd = [binary, args[0]]
    rest = list(args[1:])
    if args[0] in ("param", "mission"):
        cmd.append(rest.pop(0))
    cmd += [f"udpout:127.0.0.1:{port}", *rest, "--timeout", "10"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    return out


def table(n):
    rows = []
    for i in range(n):
        if i % 3 == 0:
            rows.append((f"PY_REAL_{i:04d}", 0.5 * i - 7.25, M.MAV_PARAM_TYPE_REAL32))
        else:
            rows.append((f"PY_INT_{i:04d}", float(i * 11 - 300), M.MAV_PARAM_TYPE_INT32))
    return rows


def scenario_cli_params(binary, loss=0.0):
    import json
    rows = table(300)
    v = PymavlinkVehicle(rows, loss=loss)
    try:
        started = time.time()
        out = cli(binary, v.port, "param", "list", "--json")
        took = time.time() - started
        if not check(out.returncode == 0, f"param list: {out.returncode} {out.stderr}"):
            return "param list failed"
        got = [json.loads(line) for line in out.stdout.splitlines()]
        check(len(got) == len(rows), f"{len(got)} parameters listed of {len(rows)}")
        for i, (g, (name, value, ty)) in enumerate(zip(got, rows)):
            check(g["name"] == name and g["index"] == i, f"row {i}: {g} vs {name}")
            check(float(g["value"]) == value, f"{name}: {g['value']} != {value}")
            want_ty = "REAL32" if ty == M.MAV_PARAM_TYPE_REAL32 else "INT32"
            check(g["type"] == want_ty, f"{name}: type {g['type']}")
        out = cli(binary, v.port, "param", "set", "PY_INT_0004", "-1234", "--json")
        check(out.returncode == 0, f"param set: {out.stderr}")
        check(v.params[4][1] == -1234.0, f"vehicle holds {v.params[4]}")
        out = cli(binary, v.port, "param", "get", "PY_REAL_0003", "--json")
        check(out.returncode == 0 and json.loads(out.stdout)["value"] == -5.75,
              f"param get: {out.stdout} {out.stderr}")
    finally:
        v.close()
    return f"mavstack param list/set/get against a pymavlink vehicle: 300 params in {took:.2f} s" + (
        f" with {loss:.0%} loss" if loss else "")


def scenario_cli_mission(binary, loss=0.0):
    v = PymavlinkVehicle([("A", 1.0, M.MAV_PARAM_TYPE_INT32)], loss=loss)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            # The plan is written by pymavlink's own MAVWPLoader.
            loader = mavwp.MAVWPLoader(target_system=1, target_component=1)
            for it in make_items((1, 1), 40):
                # MAVWPLoader keeps float MISSION_ITEMs (degrees), as its files do.
                loader.add(M.MAVLink_mission_item_message(
                    1, 1, it.seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, it.command, it.current,
                    it.autocontinue, it.param1, it.param2, it.param3, it.param4,
                    it.x / 1e7, it.y / 1e7, it.z, 0))
            path = os.path.join(tmp, "plan.waypoints")
            loader.save(path)
            started = time.time()
            out = cli(binary, v.port, "mission", "upload", path)
            took = time.time() - started
            check(out.returncode == 0, f"mission upload: {out.stdout} {out.stderr}")
            reread = mavwp.MAVWPLoader()
            reread.load(path)
            sent = [reread.wp(i) for i in range(reread.count())]
            check(len(v.mission) == len(sent), f"vehicle stored {len(v.mission)} of {len(sent)}")
            for a, b in zip(sent, v.mission):
                check(a.command == b.command and a.frame == b.frame,
                      f"item {a.seq} kind {a.command}/{a.frame} vs {b.command}/{b.frame}")
                check(abs(a.x * 1e7 - b.x) <= 1 and abs(a.y * 1e7 - b.y) <= 1,
                      f"item {a.seq} position {a.x},{a.y} vs {b.x},{b.y}")
                same_z = a.z == b.z
                check(same_z and (a.param1 == b.param1 or (math.isnan(a.param1) and math.isnan(b.param1))),
                      f"item {a.seq} z/param1")
            back = os.path.join(tmp, "back.waypoints")
            out = cli(binary, v.port, "mission", "download", back)
            check(out.returncode == 0, f"mission download: {out.stderr}")
            # pymavlink reads what we wrote.
            got = mavwp.MAVWPLoader()
            got.load(back)
            check(got.count() == len(sent), f"pymavlink read {got.count()} items back")
            for i in range(min(got.count(), len(sent))):
                a, b = sent[i], got.wp(i)
                check((a.command, a.frame, round(a.x, 7), round(a.y, 7), a.z)
                      == (b.command, b.frame, round(b.x, 7), round(b.y, 7), b.z),
                      f"downloaded item {i}: {b} vs {a}")
            out = cli(binary, v.port, "mission", "clear")
            check(out.returncode == 0 and v.mission == [], f"clear: {out.stderr}")
            out = cli(binary, v.port, "command", "arm", "--json")
            check(out.returncode == 0 and v.commands and v.commands[-1][:2] == (400, 1.0),
                  f"arm: {out.stdout} {out.stderr} {v.commands}")
            out = cli(binary, v.port, "command", "DO_FLIGHTTERMINATION", "1")
            check(out.returncode == 1 and "UNSUPPORTED" in out.stdout, f"nack: {out.stdout}")
    finally:
        v.close()
    return f"mavstack mission upload/download/clear, command against a pymavlink vehicle: 40 items up in {took:.2f} s" + (
        f" with {loss:.0%} loss" if loss else "")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario")
    ap.add_argument("--mavstack", required=True)
    args = ap.parse_args()
    scenarios = {
        "params": lambda b: scenario_params(b, "ardupilot"),
        "params_px4": lambda b: scenario_params(b, "px4"),
        "waypoints": scenario_waypoints,
        "commands": scenario_commands,
        "intervals": scenario_intervals,
        "clock": scenario_clock,
        "mission": scenario_mission,
        "cli_params": scenario_cli_params,
        "cli_params_lossy": lambda b: scenario_cli_params(b, loss=0.2),
        "cli_mission": scenario_cli_mission,
        "cli_mission_lossy": lambda b: scenario_cli_mission(b, loss=0.2),
    }
    if args.scenario not in scenarios:
        print(f"unknown scenario {args.scenario}; one of {', '.join(scenarios)}", file=sys.stderr)
        return 2
    started = time.time()
    summary = scenarios[args.scenario](args.mavstack)
    if FAILS:
        return 1
    print(f"{args.scenario}: {summary} ({time.time() - started:.1f} s) ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
