#!/usr/bin/env python3
"""`mavstack vehicle`'s `@PARAM/param.pck` read by pymavlink 2.4.50's MAVFTP, compared with
the table PARAM_REQUEST_LIST gives.

Usage: param_pck_interop.py --mavstack BIN

For each flavour (ardupilot, px4): the vehicle on `udpout` towards pymavlink's `udpin`;
pymavlink's ground station sets one float parameter (PARAM_SET), fetches the table with
PARAM_REQUEST_LIST (C-cast values for ArduPilot, bytewise for PX4, as pymavlink users decode
them), then with MAVFTP:

  - `cmd_get("@PARAM/param.pck")` and pymavlink's own `MAVFTP.ftp_param_decode` on the bytes:
    the same names in the same order, the same values bit for bit (float32), the types
    (1 int8, 2 int16, 3 int32, 4 float) matching PARAM_VALUE's;
  - `cmd_getparams([values, defaults])` (the path with `?withdefaults=1`): the files it writes
    name every parameter with its value, and the defaults file has the value the vehicle
    started with for the parameter that was set.

Uploads (the ArduPilot flavour; ArduPilot sets the parameters of a `param.pck` written to it):

  - MAVProxy 1.8.75's `param ftpload FILE` (its own packing, sent by its ftp module) changes
    one parameter of each type; MAVProxy's `param fetch NAME` (PARAM_REQUEST_READ) then reads
    each new value from the vehicle;
  - `mavstack param load CONN FILE --via ftp`, then `--via set` with other values: pymavlink's
    PARAM_REQUEST_READ reads every new value back, and a name the vehicle does not have is
    reported and skipped.

Exit 0 with "param_pck_interop: ... ok" lines, or 1 with FAIL lines.
"""

import argparse
import os
import struct
import subprocess
import sys
import tempfile
import time

os.environ["MAVLINK20"] = "1"
os.environ.setdefault("MAVLINK_DIALECT", "ardupilotmega")
from pymavlink import mavutil  # noqa: E402
from pymavlink.mavftp import MAVFTP  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from gcs_common import free_udp_port  # noqa: E402

M = mavutil.mavlink

# MAV_PARAM_TYPE -> param.pck type code.
PCK_TYPE = {
    M.MAV_PARAM_TYPE_INT8: 1,
    M.MAV_PARAM_TYPE_INT16: 2,
    M.MAV_PARAM_TYPE_INT32: 3,
    M.MAV_PARAM_TYPE_REAL32: 4,
}

FAILS = []


def fail(msg):
    FAILS.append(msg)
    print(f"FAIL {msg}", flush=True)


def f32(x):
    """x rounded to float32, as bits."""
    return struct.unpack("<I", struct.pack("<f", x))[0]


def bytewise(value, ptype):
    """A PX4 (bytewise) PARAM_VALUE float as the integer it carries."""
    raw = struct.pack("<f", value)
    if ptype == M.MAV_PARAM_TYPE_INT8:
        return struct.unpack("<b", raw[:1])[0]
    if ptype == M.MAV_PARAM_TYPE_INT16:
        return struct.unpack("<h", raw[:2])[0]
    if ptype == M.MAV_PARAM_TYPE_INT32:
        return struct.unpack("<i", raw)[0]
    return value


def param_list(master, autopilot):
    """The table by PARAM_REQUEST_LIST: [(name, value, type)] by index."""
    master.mav.param_request_list_send(master.target_system, master.target_component)
    got = {}
    count = None
    deadline = time.time() + 20
    while time.time() < deadline and (count is None or len(got) < count):
        m = master.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
        if m is None:
            if count is not None:
                for i in range(count):
                    if i not in got:
                        master.mav.param_request_read_send(
                            master.target_system, master.target_component, b"", i
                        )
            continue
        count = m.param_count
        value = m.param_value
        if autopilot == "px4":
            value = bytewise(value, m.param_type)
        got[m.param_index] = (m.param_id, value, m.param_type)
    if count is None or len(got) != count:
        fail(f"{autopilot}: PARAM_REQUEST_LIST incomplete: {len(got)} of {count}")
    return [got[i] for i in sorted(got)]


def set_param(master, name, value):
    master.mav.param_set_send(
        master.target_system,
        master.target_component,
        name.encode(),
        value,
        M.MAV_PARAM_TYPE_REAL32,
    )
    deadline = time.time() + 5
    while time.time() < deadline:
        m = master.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
        if m is not None and m.param_id == name:
            return m.param_value
    fail(f"PARAM_SET {name}: no answer")
    return None


def ftp_bytes(ftp, path):
    """The file at `path`, through pymavlink's cmd_get with a callback."""
    box = {}

    def keep(fh):
        box["data"] = fh.read()

    ftp.cmd_get([path], callback=keep)
    ret = ftp.process_ftp_reply("OpenFileRO", timeout=20)
    if ret.error_code != 0 or "data" not in box:
        fail(f"get {path}: {ret.error_code} {ret.operation_name}")
        return b""
    return box["data"]


def read_saved(path):
    """cmd_getparams' missionplanner-sorted `NAME,value` lines."""
    table = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith("#"):
                name, value = line.split(",", 1)
                table[name] = float(value)
    return table


def check(autopilot, binary):
    port = free_udp_port()
    vehicle = subprocess.Popen(
        [binary, "vehicle", f"udpout:127.0.0.1:{port}", "--autopilot", autopilot],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        master = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        if master.wait_heartbeat(timeout=10) is None:
            fail(f"{autopilot}: no HEARTBEAT")
            return
        changed = "WPNAV_SPEED" if autopilot == "ardupilot" else "MPC_XY_CRUISE"
        listed0 = {n: v for n, v, _ in param_list(master, autopilot)}
        if changed not in listed0:
            fail(f"{autopilot}: no {changed}")
            return
        start_value = listed0[changed]
        set_param(master, changed, start_value + 1.5)

        t = time.time()
        listed = param_list(master, autopilot)
        list_s = time.time() - t

        ftp = MAVFTP(master, master.target_system, master.target_component)
        t = time.time()
        data = ftp_bytes(ftp, "@PARAM/param.pck")
        ftp_s = time.time() - t
        pdata = MAVFTP.ftp_param_decode(data)
        if pdata is None:
            fail(f"{autopilot}: pymavlink cannot decode {len(data)} bytes")
            return
        decoded = [(n.decode(), v, t) for n, v, t in pdata.params]
        if [n for n, _, _ in decoded] != [n for n, _, _ in listed]:
            fail(f"{autopilot}: names differ:\n{decoded}\n{listed}")
        for (n, v, t), (ln, lv, lt) in zip(decoded, listed):
            if t != PCK_TYPE.get(lt):
                fail(f"{autopilot}: {n}: type {t} in the file, {lt} by PARAM_VALUE")
            if t == 4:
                if f32(v) != f32(lv):
                    fail(f"{autopilot}: {n}: {v!r} in the file, {lv!r} by PARAM_VALUE")
            elif int(v) != int(lv) or int(lv) != lv:
                fail(f"{autopilot}: {n}: {v!r} in the file, {lv!r} by PARAM_VALUE")
        print(
            f"ok {autopilot}: {len(decoded)} parameters, param.pck {len(data)} bytes "
            f"in {ftp_s:.3f} s, PARAM_REQUEST_LIST {list_s:.3f} s, same names, types and values",
            flush=True,
        )

        with tempfile.TemporaryDirectory() as tmp:
            values_path = os.path.join(tmp, "values.param")
            defaults_path = os.path.join(tmp, "defaults.param")
            ftp.cmd_getparams([values_path, defaults_path])
            ret = ftp.process_ftp_reply("getparams", timeout=20)
            if ret.error_code != 0 or not os.path.exists(values_path):
                fail(f"{autopilot}: getparams: {ret.error_code}")
                return
            values = read_saved(values_path)
            defaults = read_saved(defaults_path)
            if sorted(values) != sorted(n for n, _, _ in listed):
                fail(f"{autopilot}: getparams names differ: {sorted(values)}")
            for n, v, _ in listed:
                if n in values and abs(values[n] - v) > 1e-5 * max(1.0, abs(v)):
                    fail(f"{autopilot}: getparams {n} = {values[n]}, PARAM_VALUE {v}")
            if abs(values.get(changed, 0) - (start_value + 1.5)) > 1e-4:
                fail(f"{autopilot}: getparams {changed} = {values.get(changed)}")
            if abs(defaults.get(changed, 0) - start_value) > 1e-4:
                fail(f"{autopilot}: default of {changed} = {defaults.get(changed)}, not {start_value}")
            print(
                f"ok {autopilot}: getparams with defaults: {len(values)} values, "
                f"{changed} {values.get(changed)} (default {defaults.get(changed)})",
                flush=True,
            )
    finally:
        vehicle.terminate()
        try:
            vehicle.wait(timeout=5)
        except subprocess.TimeoutExpired:
            vehicle.kill()


def read_param(master, name):
    """One value by PARAM_REQUEST_READ (C-cast, the ArduPilot flavour)."""
    for _ in range(5):
        master.mav.param_request_read_send(
            master.target_system, master.target_component, name.encode(), -1
        )
        deadline = time.time() + 1
        while time.time() < deadline:
            m = master.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            if m is not None and m.param_id == name:
                return m.param_value
    fail(f"PARAM_REQUEST_READ {name}: no answer")
    return None


def one_of_each_type(table):
    """{pck type: (name, value)}: the first parameter of each type in the table."""
    picked = {}
    for name, value, ptype in table:
        t = PCK_TYPE.get(ptype)
        if t is not None and t not in picked and name not in ("MAV_SYSID", "MAV_GCS_SYSID", "FORMAT_VERSION"):
            picked[t] = (name, value)
    return picked


def new_values(picked, step):
    """A new value per picked parameter that its type holds."""
    out = {}
    for t, (name, value) in picked.items():
        if t == 4:
            out[name] = value + 1.25 * step
        elif t == 1:
            out[name] = value + step if value + step <= 127 else value - step
        else:
            out[name] = value + 100 * step
    return out


def write_file(path, values):
    with open(path, "w", encoding="utf-8") as f:
        for name, value in values.items():
            f.write(f"{name} {value:g}\n" if float(value).is_integer() else f"{name} {value!r}\n")


def same(got, want, name, what):
    if got is None or abs(got - want) > 1e-5 * max(1.0, abs(want)):
        fail(f"{what}: {name} = {got}, expected {want}")
        return False
    return True


def uploads(binary):
    from gcs_common import Vehicle
    from gcs_mavproxy import MavProxy, param_read_back

    port = free_udp_port()
    with tempfile.TemporaryDirectory(prefix="param-pck-upload-") as tmp:
        vehicle = Vehicle(binary, f"udpout:127.0.0.1:{port}", ["--autopilot", "ardupilot"], tmp)
        try:
            master = mavutil.mavlink_connection(
                f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
            )
            if master.wait_heartbeat(timeout=10) is None:
                fail("upload: no HEARTBEAT")
                return
            table = param_list(master, "ardupilot")
            picked = one_of_each_type(table)
            if sorted(picked) != [1, 2, 3, 4]:
                fail(f"upload: the vehicle lacks a parameter of some type: {picked}")
                return
            master.close()

            # MAVProxy's `param ftpload`.
            wanted = new_values(picked, 1)
            path = os.path.join(tmp, "mavproxy.parm")
            write_file(path, wanted)
            mp = MavProxy(f"udpin:127.0.0.1:{port}", tmp, vehicle, extra=["--cmd=module load ftp"])
            try:
                mp.expect(r"Detected vehicle", 20, "MAVProxy connect")
                mp.cmd("param fetch")
                mp.expect(r"Received \d+ parameters", 30, "MAVProxy param fetch")
                mp.cmd(f"param ftpload {path}")
                mp.expect(r"Sending 4 params", 10, "MAVProxy param ftpload")
                mp.expect(r"Parameter upload done", 30, "MAVProxy param ftpload")
                for name, value in wanted.items():
                    param_read_back(mp, name, value, f"MAVProxy ftpload {name}")
            finally:
                mp.close()
            print(f"ok upload: MAVProxy param ftpload set {', '.join(wanted)} (read back)", flush=True)

            # mavstack param load, by MAVFTP and by PARAM_SET.
            for step, via in ((2, "ftp"), (3, "set")):
                wanted = new_values(picked, step)
                path = os.path.join(tmp, f"{via}.parm")
                write_file(path, {**wanted, "NO_SUCH_PARAM": 1})
                run = subprocess.run(
                    [binary, "param", "load", f"udpin:127.0.0.1:{port}", path, "--via", via,
                     "--timeout", "10"],
                    capture_output=True, text=True, timeout=60,
                )
                if run.returncode != 0:
                    fail(f"param load --via {via}: exit {run.returncode}\n{run.stdout}\n{run.stderr}")
                    continue
                if "NO_SUCH_PARAM" not in run.stderr:
                    fail(f"param load --via {via}: the unknown name was not reported: {run.stderr}")
                master = mavutil.mavlink_connection(
                    f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
                )
                if master.wait_heartbeat(timeout=10) is None:
                    fail("upload: no HEARTBEAT after param load")
                    return
                ok = all(same(read_param(master, n), v, n, f"param load --via {via}")
                         for n, v in wanted.items())
                master.close()
                if ok:
                    print(f"ok upload: mavstack param load --via {via} set {len(wanted)} "
                          f"parameters (pymavlink reads them back): {run.stdout.strip().splitlines()[-1]}",
                          flush=True)
        finally:
            vehicle.stop()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--mavstack", required=True)
    args = parser.parse_args()
    for autopilot in ("ardupilot", "px4"):
        check(autopilot, args.mavstack)
    try:
        uploads(args.mavstack)
    except Exception as e:  # a gcs_common Failure, or MAVProxy gone
        fail(f"upload: {e}")
    if FAILS:
        return 1
    print("param_pck_interop: all ok", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
