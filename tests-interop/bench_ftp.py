#!/usr/bin/env python3
"""Side-by-side benchmark for the README: mavstack's ground-station commands against MAVProxy
1.8.75, MAVSDK 4.1.0 (its native asyncio binding) and pymavlink 2.4.50, all against
`mavstack vehicle`, on a clean loopback link and through lossy_relay.py. Not run in CI.

    bench_ftp.py [--mavstack BIN] [--rounds N] [--only params|files|logs] [--out FILE]
                 [--keep DIR] [--seed S]

Every measurement gets a vehicle of its own,

    BIN vehicle udpout:127.0.0.1:PORT --autopilot ardupilot --params FILE --ftp-root DIR
        [--log-dir DIR2]

sending either straight to the ground station's udpin port ("clean") or to a LossyRelay
(tests-interop/lossy_relay.py, in this process: loss 0.2 and delay 0.1 s each way, seeded)
that forwards to it ("lossy"). Nothing runs in parallel.

1. params: the whole table, 1,350 parameters (the ArduPilot flavour's own 35 and 1,315 more
   with ArduPilot-style names, INT8, INT16, INT32 and REAL32, one QGroundControl line each):
   `mavstack param list --via ftp` and `--via list` (seconds from process start to exit,
   the heartbeat wait included; the CLI's own time from stderr beside it), MAVProxy's
   `param ftp` (with `module load ftp`, `set param_ftp 1`) and `param fetch` (`set param_ftp
   0`), each timed from the command to "Received N parameters" (after the fetch MAVProxy makes
   by itself on connecting), MAVSDK's `Param.get_all_params`. Each must return all 1,350
   names with their values (MAVProxy's checked with `param save`).
2. files: a 10 MiB file on the clean link and a 128 KiB one (--lossy-kib) on the lossy one
   (1 MiB there took every client more than 150 s, hence the default): `mavstack ftp
   get` (process start to exit; it also asks the server's CRC32), MAVProxy's `ftp get` (its
   ftp module, from the command to "Wrote N bytes"), MAVSDK's `Ftp.download` (burst reads),
   pymavlink's `mavftp.MAVFTP` `get` (library default settings). Every file is compared byte
   for byte with the original.
3. logs (LOG_REQUEST_DATA): a 1 MiB log clean, 128 KiB (--lossy-kib) lossy, from `--log-dir`:
   `mavstack log download ID --via log` (and `--via ftp`, /APM/LOGS as ArduPilot keeps them),
   MAVSDK's `LogFiles.download_log_file`, MAVProxy's `log download ID FILE`. Left as a
   marked placeholder when `mavstack log --help` does not list `download`.

The Python peers other than MAVProxy run in a child process each (this script with --worker),
so that a peer that hangs (MAVSDK's calls run in C++ threads that cannot be cancelled) is
killed at its deadline and reported as timed out. Peers connect first; their timing starts at
the operation. mavstack's starts at process start, so it includes waiting for the vehicle's
1 Hz HEARTBEAT: the table shows both.

Output: one JSON document (--out FILE, default bench_ftp.json in the work directory) with
every round of every measurement; on stdout, progress lines and a Markdown table (medians
over the rounds) with the time ratio to mavstack (>1: slower than mavstack). Every failure or
timeout is printed as FAIL and makes the exit status 1. There are no timing assertions:
counts and contents are checked.
"""

import argparse
import asyncio
import json
import os
import platform
import random
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import traceback

os.environ.setdefault("MAVLINK20", "1")
HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, HERE)

from ftp_interop import diff_bytes, read  # noqa: E402
from gcs_common import Failure, Vehicle, fail, free_udp_port  # noqa: E402

LOSS, DELAY = 0.2, 0.1
EXTRA_PARAMS = 1315
FILE_CLEAN = 10 << 20   # bytes, clean link
FILE_LOSSY_KIB = 128    # lossy link (--lossy-kib): 1 MiB takes every client minutes there
LOG_CLEAN = 1 << 20     # bytes (not a multiple of 90: MAVProxy ends on a short chunk)
# deadlines (s) per measurement, from the operation's start; a peer over it is "timed out"
TIMEOUT = {
    ("params", "clean"): 60, ("params", "lossy"): 75,
    ("files", "clean"): 120, ("files", "lossy"): 90,
    ("logs", "clean"): 90, ("logs", "lossy"): 90,
}
CONNECT_TIMEOUT = 30

# MAV_PARAM_TYPE numbers
INT8, INT16, INT32, REAL32 = 2, 4, 6, 9
TYPE_NAME = {INT8: "INT8", INT16: "INT16", INT32: "INT32", REAL32: "REAL32"}

# The ArduPilot flavour's own table (crates/mavstack-sim/src/params.rs): `--params` replaces
# it, so the file starts with these.
ARDUPILOT_OWN = [
    ("MAV_SYSID", INT16, 1), ("MAV_GCS_SYSID", INT16, 255), ("FORMAT_VERSION", INT16, 120),
    ("FRAME_CLASS", INT8, 1), ("FRAME_TYPE", INT8, 1), ("ARMING_CHECK", INT32, 1),
    ("DISARM_DELAY", INT8, 10), ("PILOT_TKOFF_ALT", REAL32, 0.0),
    ("WPNAV_SPEED", REAL32, 500.0), ("WPNAV_SPEED_UP", REAL32, 250.0),
    ("WPNAV_SPEED_DN", REAL32, 150.0), ("WPNAV_RADIUS", REAL32, 200.0),
    ("LAND_SPEED", INT16, 50), ("RTL_ALT", INT32, 1500), ("RTL_SPEED", INT16, 0),
    ("LOIT_SPEED", REAL32, 1250.0), ("ANGLE_MAX", INT16, 3000), ("BATT_MONITOR", INT8, 4),
    ("BATT_CAPACITY", INT32, 5000), ("BATT_LOW_VOLT", REAL32, 14.0),
    ("FENCE_ENABLE", INT8, 0), ("FENCE_ALT_MAX", REAL32, 100.0),
    ("FENCE_RADIUS", REAL32, 300.0), ("FS_THR_ENABLE", INT8, 1), ("FS_GCS_ENABLE", INT8, 0),
    ("MOT_SPIN_ARM", REAL32, 0.1), ("MOT_SPIN_MIN", REAL32, 0.15),
    ("ATC_RAT_RLL_P", REAL32, 0.135), ("ATC_RAT_PIT_P", REAL32, 0.135),
    ("ATC_RAT_YAW_P", REAL32, 0.18), ("COMPASS_USE", INT8, 1), ("GPS1_TYPE", INT8, 1),
    ("SERIAL0_BAUD", INT32, 115), ("MAV1_POSITION", INT16, 4), ("MAV1_EXTRA1", INT16, 4),
]

# ArduPilot-style families: (pattern, instances, suffixes)
_XYZ = ["X", "Y", "Z"]
FAMILIES = [
    ("SERVO{}_{}", range(1, 33), ["MIN", "MAX", "TRIM", "REVERSED", "FUNCTION"]),
    ("RC{}_{}", range(1, 17), ["MIN", "MAX", "TRIM", "REVERSED", "DZ", "OPTION"]),
    ("SERIAL{}_{}", range(0, 9), ["BAUD", "PROTOCOL", "OPTIONS"]),
    ("MAV{}_{}", range(1, 4), ["RAW_SENS", "EXT_STAT", "RC_CHAN", "RAW_CTRL", "POSITION",
                               "EXTRA1", "EXTRA2", "EXTRA3", "PARAMS", "ADSB", "OPTIONS"]),
    ("BATT{}_{}", range(2, 10), ["MONITOR", "CAPACITY", "LOW_VOLT", "CRT_VOLT", "VOLT_PIN",
                                 "CURR_PIN", "VOLT_MULT", "AMP_PERVLT", "AMP_OFFSET",
                                 "ARM_VOLT", "FS_LOW_ACT", "FS_CRT_ACT", "SERIAL_NUM",
                                 "OPTIONS"]),
    ("INS_ACC{}OFFS_{}", ["", "2", "3"], _XYZ), ("INS_ACC{}SCAL_{}", ["", "2", "3"], _XYZ),
    ("INS_GYR{}OFFS_{}", ["", "2", "3"], _XYZ),
    ("COMPASS_OFS{}_{}", ["", "2", "3"], _XYZ), ("COMPASS_DIA{}_{}", ["", "2", "3"], _XYZ),
    ("COMPASS_ODI{}_{}", ["", "2", "3"], _XYZ), ("COMPASS_MOT{}_{}", ["", "2", "3"], _XYZ),
    ("ATC_RAT_{}_{}", ["RLL", "PIT", "YAW"], ["P", "I", "D", "FF", "IMAX", "FLTT", "FLTE",
                                              "FLTD", "SMAX", "PDMX", "D_FF", "NTF", "NEF"]),
    ("PSC_{}_{}", ["POSXY", "VELXY", "POSZ", "VELZ", "ACCZ"],
     ["P", "I", "D", "IMAX", "FF", "FLTE", "FLTD"]),
    ("EK3_SRC{}_{}", range(1, 4), ["POSXY", "VELXY", "POSZ", "VELZ", "YAW"]),
    ("RNGFND{}_{}", [*range(1, 10), "A"], ["TYPE", "PIN", "SCALING", "OFFSET", "FUNCTION",
                                          "MIN_CM", "MAX_CM", "STOP_PIN", "RMETRIC", "PWRRNG",
                                          "GNDCLEAR", "ADDR", "POS_X", "POS_Y", "POS_Z",
                                          "ORIENT"]),
    ("OSD{}_{}", range(1, 5), [f"{item}_{f}" for item in
                              ["ALTITUDE", "BAT_VOLT", "RSSI", "CURRENT", "BATUSED", "SATS",
                               "FLTMODE", "MESSAGE", "GSPEED", "HORIZON", "HOME", "HEADING",
                               "THROTTLE", "COMPASS", "WIND", "ASPEED", "VSPEED", "ARMING",
                               "POWER", "GPSLAT", "GPSLONG", "ROLL", "PITCH", "TEMP", "DIST",
                               "STAT", "FLTIME", "CLIMBEFF", "EFF", "BTEMP"]
                              for f in ("EN", "X", "Y")]),
    ("MNT{}_{}", range(1, 3), ["TYPE", "DEFLT_MODE", "RC_RATE", "ROLL_MIN", "ROLL_MAX",
                               "PITCH_MIN", "PITCH_MAX", "YAW_MIN", "YAW_MAX", "RETRACT_X",
                               "RETRACT_Y", "RETRACT_Z", "NEUTRAL_X", "NEUTRAL_Y",
                               "NEUTRAL_Z", "LEAD_RLL", "LEAD_PTCH", "SYSID_DFLT",
                               "DEVID", "OPTIONS"]),
    ("CAM{}_{}", range(1, 3), ["TYPE", "DURATN", "SERVO_ON", "SERVO_OFF", "TRIGG_DIST",
                               "RELAY_ON", "INTRVAL_MIN", "OPTIONS", "PIN", "FEEDBAK_PIN",
                               "HFOV", "VFOV", "MNT_INST"]),
    ("RELAY{}_{}", range(1, 7), ["FUNCTION", "PIN", "DEFAULT", "INVERTED"]),
    ("PRX{}_IGN_{}", range(1, 3), [f"{k}{n}" for k in ("ANG", "WID") for n in range(1, 7)]),
    ("SCR_USER{}{}", range(1, 7), [""]),
    ("FLTMODE{}{}", range(1, 7), [""]),
    ("EK3_{}{}", ["ENABLE", "IMU_MASK", "GPS_CHECK", "VELNE_M_NSE", "VELD_M_NSE",
                  "POSNE_M_NSE", "ALT_M_NSE", "MAG_M_NSE", "EAS_M_NSE", "YAW_M_NSE",
                  "GYRO_P_NSE", "ACC_P_NSE", "GBIAS_P_NSE", "ABIAS_P_NSE", "WIND_P_NSE",
                  "MAG_CAL", "GLITCH_RAD", "RNG_USE_HGT", "TERR_GRAD", "ERR_THRESH",
                  "AFFINITY", "DRAG_BCOEF_X", "DRAG_BCOEF_Y", "OGN_HGT_MASK", "FLOW_DELAY",
                  "HRT_FILT", "OPTIONS", "PRIMARY", "LOG_LEVEL", "GSF_RUN_MASK"], [""]),
    ("LOG_{}{}", ["BITMASK", "BACKEND_TYPE", "FILE_BUFSIZE", "DISARMED", "REPLAY",
                  "FILE_DSRMROT", "MAV_BUFSIZE", "FILE_TIMEOUT", "FILE_MB_FREE",
                  "FILE_RATEMAX", "MAV_RATEMAX", "BLK_RATEMAX", "DARM_RATEMAX"], [""]),
    ("GPS{}_{}", range(1, 3), ["TYPE", "GNSS_MODE", "RATE_MS", "POS_X", "POS_Y", "POS_Z",
                               "DELAY_MS", "COM_PORT", "CAN_NODEID"]),
    ("SERVO_{}{}", ["BLH_MASK", "BLH_OTYPE", "BLH_PORT", "BLH_POLES", "BLH_TRATE",
                    "BLH_DEBUG", "BLH_OFFSET", "BLH_AUTO", "BLH_TEST", "BLH_TMOUT",
                    "BLH_3DMASK", "BLH_BDMASK", "BLH_RVMASK", "FTW_MASK", "FTW_RVMASK",
                    "FTW_POLES", "ROB_POSMIN", "ROB_POSMAX", "VOLZ_MASK", "SBUS_RATE",
                    "RATE", "DSHOT_RATE", "DSHOT_ESC", "GPIO_MASK", "32_ENABLE",
                    "AUTO_TRIM"], [""]),
    ("NTF_{}{}", ["LED_BRIGHT", "LED_OVERRIDE", "LED_LEN", "LED_TYPES", "BUZZ_TYPES",
                  "BUZZ_VOLUME", "BUZZ_ON_LVL", "BUZZ_PIN", "DISPLAY_TYPE", "OREO_THEME"], [""]),
    ("BRD_{}{}", ["SAFETYENABLE", "SAFETY_MASK", "SAFETYOPTION", "SER1_RTSCTS", "SER2_RTSCTS",
                  "IO_ENABLE", "PWM_VOLT_SEL", "RTC_TYPES", "RTC_TZ_MIN", "VBUS_MIN",
                  "VSERVO_MIN", "OPTIONS", "BOOT_DELAY", "HEAT_TARG", "HEAT_P", "HEAT_I",
                  "HEAT_IMAX", "HEAT_LOWMGN", "SD_SLOWCLK", "SD_MISSION"], [""]),
]


def extra_param_names(n, taken):
    names = []
    seen = set(taken)
    for pattern, instances, suffixes in FAMILIES:
        for inst in instances:
            for suf in suffixes:
                name = pattern.format(inst, suf)
                if len(name) > 16 or name in seen:
                    continue
                seen.add(name)
                names.append(name)
                if len(names) == n:
                    return names
    raise AssertionError(f"only {len(names)} extra parameter names, {n} wanted")


def param_table():
    """[(name, type, value)]: the flavour's own 35, then EXTRA_PARAMS more, types in turn."""
    table = list(ARDUPILOT_OWN)
    for i, name in enumerate(extra_param_names(EXTRA_PARAMS, [p[0] for p in table])):
        kind = (INT8, INT16, INT32, REAL32)[i % 4]
        value = {INT8: (i * 37) % 256 - 128,
                 INT16: (i * 1237) % 65536 - 32768,
                 INT32: i * 12_347 - 8_000_000,  # within ±2^24: exact as a C-cast float
                 REAL32: (i % 4001) * 0.375 - 750.125}[kind]  # exact in float32
        table.append((name, kind, value))
    return table


def write_param_file(path, table):
    """QGroundControl lines (`SYSID COMPID NAME VALUE TYPE`, tab-separated): the type each
    way of writing `NAME VALUE` (gcs_common.write_params_file) cannot say."""
    with open(path, "w") as f:
        f.write("# generated by tests-interop/bench_ftp.py\n")
        for name, kind, value in table:
            f.write(f"1\t1\t{name}\t{value!r}\t{kind}\n")


def f32(v):
    import struct
    return struct.unpack("<f", struct.pack("<f", v))[0]


def compare_params(table, got, what):
    """got: {name: value}; every name of the table with its value (REAL32 as float32)."""
    want = {n: (f32(v) if k == REAL32 else v) for n, k, v in table}
    missing = [n for n in want if n not in got]
    extra = [n for n in got if n not in want]
    wrong = [(n, want[n], got[n]) for n in want
             if n in got and abs(float(got[n]) - want[n]) > 1e-6 * max(1.0, abs(want[n]))]
    if missing or extra or wrong:
        fail(f"{what}: {len(got)} parameters, {len(want)} expected; {len(missing)} missing "
             f"{missing[:4]}, {len(extra)} unexpected {extra[:4]}, {len(wrong)} with another "
             f"value (name, want, got) {wrong[:4]}")


# ---------------------------------------------------------------------------- link

class Link:
    """A vehicle for one measurement, clean or behind a LossyRelay; gcs_port is where the
    ground station listens (udpin)."""

    def __init__(self, binary, case, vehicle_args, work, seed):
        self.case = case
        self.gcs_port = free_udp_port()
        self.relay = None
        if case == "lossy":
            from lossy_relay import LossyRelay

            self.relay = LossyRelay(("127.0.0.1", 0), ("127.0.0.1", self.gcs_port), loss=LOSS,
                                    seed=seed, delay=DELAY).start()
            vport = self.relay.listen_port
        else:
            vport = self.gcs_port
        os.makedirs(work, exist_ok=True)
        self.work = work
        try:
            self.vehicle = Vehicle(binary, f"udpout:127.0.0.1:{vport}",
                                   ["--autopilot", "ardupilot", *vehicle_args], work)
        except Failure:
            if self.relay is not None:
                self.relay.stop()
            raise

    def close(self):
        self.vehicle.stop()
        if self.relay is not None:
            self.relay.stop()
            return self.relay.stats
        return None


# ---------------------------------------------------------------------------- measurements

class TimedOut(Exception):
    pass


def run_cli(cmd, timeout):
    """(rc, stdout, stderr, wall seconds); TimedOut past timeout."""
    t = time.monotonic()
    try:
        p = subprocess.run(cmd, capture_output=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        raise TimedOut(f"{' '.join(cmd)} still running after {timeout} s") from None
    dt = time.monotonic() - t
    return p.returncode, p.stdout.decode(errors="replace"), p.stderr.decode(errors="replace"), dt


def own_seconds(text):
    m = re.search(r"(?:done )?in ([0-9.]+) s\b", text)
    return float(m.group(1)) if m else None


def m_mavstack_params(ctx, link, via, timeout):
    cmd = [ctx.binary, "param", "list", f"udpin:127.0.0.1:{link.gcs_port}", "--via", via,
           "--json", "--timeout", str(CONNECT_TIMEOUT)]
    rc, out, err, dt = run_cli(cmd, timeout + CONNECT_TIMEOUT)
    if rc != 0:
        fail(f"`{' '.join(cmd)}` exited {rc}: {err.strip()[-600:]}")
    got = {}
    for line in out.splitlines():
        if line.strip():
            o = json.loads(line)
            got[o["name"]] = o["value"]
    compare_params(ctx.table, got, f"mavstack param list --via {via}")
    way = "MAVFTP" if via == "ftp" else "PARAM_REQUEST_LIST"
    if way not in err:
        fail(f"mavstack param list --via {via}: stderr does not say {way}: {err.strip()}")
    return {"seconds": dt, "own_seconds": own_seconds(err), "count": len(got),
            "detail": err.strip().splitlines()[-1] if err.strip() else ""}


def m_mavstack_get(ctx, link, remote, data, timeout):
    local = os.path.join(link.work, "got.bin")
    cmd = [ctx.binary, "ftp", "get", f"udpin:127.0.0.1:{link.gcs_port}", remote, local,
           "--timeout", str(CONNECT_TIMEOUT)]
    rc, out, err, dt = run_cli(cmd, timeout + CONNECT_TIMEOUT)
    if rc != 0:
        fail(f"`{' '.join(cmd)}` exited {rc}: {err.strip()[-600:]}")
    got = read(local) if os.path.exists(local) else None
    if got != data:
        fail(f"mavstack ftp get {remote}: {diff_bytes(got, data)}")
    return {"seconds": dt, "own_seconds": own_seconds(err), "bytes": len(data)}


def m_mavstack_log(ctx, link, via, data, timeout):
    out_dir = os.path.join(link.work, f"logs-{via}")
    cmd = [ctx.binary, "log", "download", f"udpin:127.0.0.1:{link.gcs_port}", "1", "--via",
           via, "--out", out_dir, "--json", "--timeout", str(CONNECT_TIMEOUT)]
    rc, out, err, dt = run_cli(cmd, timeout + CONNECT_TIMEOUT)
    if rc != 0:
        fail(f"`{' '.join(cmd)}` exited {rc}: {err.strip()[-600:]}")
    res = [json.loads(x) for x in out.splitlines() if x.strip()]
    path = os.path.join(out_dir, "log_1.bin")
    got = read(path) if os.path.exists(path) else None
    if got != data:
        fail(f"mavstack log download --via {via}: {diff_bytes(got, data)}")
    how = res[0].get("via") if res else None
    if how != via:
        fail(f"mavstack log download --via {via}: it says it went via {how}")
    return {"seconds": dt, "own_seconds": res[0].get("seconds") if res else None,
            "bytes": len(data)}


# -------------------------------------------------- MAVProxy (headless in a pty, as gcs_mavproxy)

class MavProxy:
    def __init__(self, port, work, modules, cmds, link):
        import pexpect

        self.pexpect = pexpect
        self.link = link
        exe = os.path.join(os.path.dirname(sys.executable), "mavproxy.py")
        if not os.path.exists(exe):
            fail(f"MAVProxy is not installed next to {sys.executable}; run scripts/setup-peers.sh")
        self.out_path = os.path.join(work, "mavproxy.out")
        self.out = open(self.out_path, "w")  # noqa: SIM115
        state = os.path.join(work, "state")
        os.makedirs(state, exist_ok=True)
        env = dict(os.environ, HOME=work, TERM="dumb", PYTHONUNBUFFERED="1")
        args = [exe, f"--master=udpin:127.0.0.1:{port}", f"--state-basedir={state}",
                "--aircraft=gcs", f"--default-modules={modules}",
                *[f"--cmd={c}" for c in cmds]]
        self.p = pexpect.spawn(sys.executable, args, cwd=work, env=env, encoding="utf-8",
                               codec_errors="replace", timeout=30, maxread=65536,
                               searchwindowsize=None)
        self.p.logfile_read = self.out

    def tail(self, n=1500):
        self.out.flush()
        with open(self.out_path, errors="replace") as f:
            return f.read()[-n:]

    def drain(self):
        while True:
            try:
                self.p.read_nonblocking(65536, timeout=0.05)
            except self.pexpect.TIMEOUT:
                return
            except self.pexpect.EOF:
                fail(f"MAVProxy exited:\n{self.tail()}")

    def cmd(self, line):
        self.drain()
        self.p.sendline(line)

    def expect(self, patterns, timeout, what, timed=False):
        try:
            i = self.p.expect(patterns, timeout=timeout)
        except self.pexpect.TIMEOUT:
            self.link.vehicle.check_alive()
            msg = (f"{what}: MAVProxy did not print /{patterns}/ within {timeout} s; its "
                   f"output (tail): {self.tail(800)!r}")
            if timed:
                raise TimedOut(msg) from None
            fail(msg)
        except self.pexpect.EOF:
            fail(f"{what}: MAVProxy exited: {self.tail()!r}")
        return i, self.p.match

    def close(self):
        if self.p.isalive():
            self.p.terminate(force=True)
        self.out.close()


def read_parm(path):
    out = {}
    with open(path) as f:
        for line in f:
            a = line.split()
            if len(a) >= 2 and not a[0].startswith("#"):
                out[a[0]] = float(a[1])
    return out


def m_mavproxy_params(ctx, link, via, timeout):
    """One MAVProxy session per row. MAVProxy fetches the whole table by itself once it sees
    the vehicle (over MAVFTP with param_ftp 1, else PARAM_REQUEST_LIST); that first fetch is
    waited for (at most a third of the deadline, untimed), then the command is timed: `param ftp`
    (param_ftp 1) or `param fetch` (param_ftp 0). When MAVFTP's first fetch did not finish,
    `param ftp` is not tried (MAVProxy's ftp module is still busy with it): FAIL. When the
    list's first fetch did not finish, `param fetch` starts the list again and is timed."""
    n = len(ctx.table)
    ftp = via == "ftp"
    mp = MavProxy(link.gcs_port, link.work, "param",
                  ["module load ftp", f"set param_ftp {1 if ftp else 0}"], link)
    try:
        mp.expect(r"Detected vehicle 1:1", CONNECT_TIMEOUT, "MAVProxy: connect")
        t = time.monotonic()
        first = None
        wait = round(timeout / 3)
        try:
            mp.expect([r"Received (\d+) parameters"], wait, "MAVProxy's own first fetch",
                      timed=True)
            first = round(time.monotonic() - t, 3)
        except TimedOut as e:
            if ftp:
                fail(f"MAVProxy's own first fetch over MAVFTP (param_ftp 1) did not finish "
                     f"within {wait} s of connecting, so `param ftp` was not tried. {e}")
        time.sleep(0.5)
        command = "param ftp" if ftp else "param fetch"
        mp.cmd(command)
        t = time.monotonic()
        pattern = r"Received (\d+) parameters \(ftp\)" if ftp else r"Received (\d+) parameters\r?\n"
        _, m = mp.expect([pattern], timeout, f"MAVProxy {command}", timed=True)
        dt = time.monotonic() - t
        got_n = int(m.group(1))
        if got_n != n:
            fail(f"MAVProxy {command}: Received {got_n} parameters, {n} expected")
        saved = os.path.join(link.work, "saved.parm")
        mp.cmd(f"param save {saved}")
        mp.expect([rf"Saved (\d+) parameters to {re.escape(saved)}"], 30,
                  f"MAVProxy param save after {command}")
        compare_params(ctx.table, read_parm(saved), f"MAVProxy {command} (param save)")
        return {"seconds": dt, "count": got_n,
                "detail": f"its own first fetch: {first} s" if first is not None else
                f"its own first fetch: not finished in {wait} s"}
    finally:
        mp.close()


def m_mavproxy_get(ctx, link, remote, data, timeout):
    mp = MavProxy(link.gcs_port, link.work, "ftp", [], link)
    try:
        mp.expect(r"Detected vehicle 1:1", CONNECT_TIMEOUT, "MAVProxy: connect")
        time.sleep(1.0)
        local = os.path.join(link.work, "mavproxy-got.bin")
        mp.cmd(f"ftp get {remote} {local}")
        t = time.monotonic()
        i, m = mp.expect([rf"Wrote (\d+) bytes to {re.escape(local)} in ([\d.]+)s",
                          r"ftp open failed", r"Read failed with \d+ gaps.*"],
                         timeout, f"MAVProxy ftp get {remote}", timed=True)
        dt = time.monotonic() - t
        if i != 0:
            fail(f"MAVProxy ftp get {remote}: {m.group(0)}")
        got = None
        for _ in range(20):  # the file is closed just after the line
            got = read(local) if os.path.exists(local) else None
            if got == data:
                break
            time.sleep(0.1)
        if got != data:
            fail(f"MAVProxy ftp get {remote}: {diff_bytes(got, data)}")
        return {"seconds": dt, "own_seconds": float(m.group(2)), "bytes": len(data)}
    finally:
        mp.close()


def m_mavproxy_log(ctx, link, data, timeout):
    mp = MavProxy(link.gcs_port, link.work, "log", [], link)
    try:
        mp.expect(r"Detected vehicle 1:1", CONNECT_TIMEOUT, "MAVProxy: connect")
        mp.cmd("log list")
        _, m = mp.expect([r"Log 1\s+numLogs (\d+) lastLog (\d+) size (\d+)"], 30,
                         "MAVProxy log list")
        if int(m.group(3)) != len(data):
            fail(f"MAVProxy log list: log 1 of {m.group(3)} bytes, {len(data)} served")
        time.sleep(0.5)
        local = os.path.join(link.work, "mavproxy-log1.bin")
        mp.cmd(f"log download 1 {local}")
        t = time.monotonic()
        _, m = mp.expect([rf"Finished downloading {re.escape(local)} \((\d+) bytes ([\d.]+) "
                          rf"seconds, ([\d.]+) kbyte/sec (\d+) retries\)"],
                         timeout, "MAVProxy log download", timed=True)
        dt = time.monotonic() - t
        got = read(local) if os.path.exists(local) else None
        if got != data:
            fail(f"MAVProxy log download 1: {diff_bytes(got, data)}")
        return {"seconds": dt, "own_seconds": float(m.group(2)), "bytes": len(data),
                "detail": f"{m.group(4)} MAVProxy retries"}
    finally:
        mp.close()


# ------------------------------------- MAVSDK and pymavlink: in a child process each (--worker)

def run_worker(kind, spec, timeout):
    """This script with --worker KIND SPEC in a session of its own; its last stdout line is
    the result. Killed (and TimedOut) at timeout plus the connection allowance."""
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", kind, json.dumps(spec)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout + CONNECT_TIMEOUT + 15)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        p.communicate()
        raise TimedOut(f"{kind} worker still running after {timeout + CONNECT_TIMEOUT + 15} s; "
                       "killed") from None
    out, err = out.decode(errors="replace"), err.decode(errors="replace")
    lines = [x for x in out.splitlines() if x.startswith("{")]
    if not lines:
        fail(f"{kind} worker exited {p.returncode} without a result: {err.strip()[-800:]}")
    res = json.loads(lines[-1])
    if res.get("timed_out"):
        raise TimedOut(res["error"])
    if not res.get("ok"):
        fail(res.get("error", "?") + (f" [stderr: {err.strip()[-300:]}]" if err.strip() else ""))
    return res


async def _mavsdk_system(url):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

    mav = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await mav.add_any_connection(url)
    system = await mav.first_autopilot(timeout_s=CONNECT_TIMEOUT)
    if system is None:
        raise RuntimeError(f"MAVSDK: no autopilot on {url} within {CONNECT_TIMEOUT} s")
    return mav, system


async def _timed(coro, timeout, what):
    t = time.monotonic()
    try:
        r = await asyncio.wait_for(coro, timeout)
    except asyncio.TimeoutError:
        raise TimedOut(f"{what}: no result within {timeout} s") from None
    return r, time.monotonic() - t


async def w_mavsdk(spec):
    url = f"udpin://127.0.0.1:{spec['port']}"
    mav, system = await _mavsdk_system(url)
    timeout = spec["timeout"]
    await asyncio.sleep(1.0)
    if spec["op"] == "params":
        from mavsdk.asyncio.plugins.param import ParamAsync

        param = ParamAsync(system)
        allp, dt = await _timed(param.get_all_params(), timeout, "MAVSDK get_all_params")
        got = {p.name: p.value for p in [*allp.int_params, *allp.float_params]}
        got.update({p.name: p.value for p in getattr(allp, "custom_params", [])})
        return {"seconds": dt, "count": len(got), "values": got}
    if spec["op"] == "ftp":
        from mavsdk.asyncio.plugins.ftp import FtpAsync

        ftp = FtpAsync(system)

        async def download():
            async for _result, _prog in ftp.download(spec["remote"], spec["local_dir"], True):
                pass

        _, dt = await _timed(download(), timeout, f"MAVSDK ftp download {spec['remote']}")
        return {"seconds": dt}
    if spec["op"] == "log":
        from mavsdk.asyncio.plugins.log_files import LogFilesAsync

        lf = LogFilesAsync(system)
        # get_entries is not retried by MAVSDK (a lost LOG_ENTRY: TIMEOUT); asked up to 3
        # times here, untimed, as a user would
        for attempt in range(3):
            try:
                entries, _ = await _timed(lf.get_entries(), 30, "MAVSDK log_files get_entries")
                break
            except Exception:  # noqa: BLE001
                if attempt == 2:
                    raise
        entry = next((e for e in entries if e.id == 1), None)
        if entry is None:
            raise RuntimeError(f"MAVSDK get_entries: no log 1 in {[e.id for e in entries]}")
        if entry.size_bytes != spec["size"]:
            raise RuntimeError(f"MAVSDK get_entries: log 1 of {entry.size_bytes} bytes, "
                               f"{spec['size']} served")

        async def download():
            async for _result, _prog in lf.download_log_file(entry, spec["local"]):
                pass

        _, dt = await _timed(download(), timeout, "MAVSDK download_log_file")
        return {"seconds": dt}
    raise ValueError(spec["op"])


def w_pymavlink(spec):
    import logging

    from pymavlink import mavutil
    from pymavlink.mavftp import MAVFTP

    logging.basicConfig(level=logging.WARNING)
    master = mavutil.mavlink_connection(f"udpin:127.0.0.1:{spec['port']}", source_system=255,
                                        source_component=190)
    try:
        if master.wait_heartbeat(timeout=CONNECT_TIMEOUT) is None:
            raise RuntimeError(f"pymavlink: no HEARTBEAT within {CONNECT_TIMEOUT} s")
        time.sleep(1.0)
        ftp = MAVFTP(master, master.target_system, master.target_component)
        t = time.monotonic()
        ftp.cmd_ftp(["get", spec["remote"], spec["local"]])
        ret = ftp.process_ftp_reply("get", timeout=spec["timeout"])
        dt = time.monotonic() - t
        if ret is None or int(ret.error_code) != 0:
            if dt >= spec["timeout"] - 1:
                raise TimedOut(f"pymavlink mavftp get: not done within {spec['timeout']} s "
                               f"({ret.error_code!r})")
            raise RuntimeError(f"pymavlink mavftp get: {ret.error_code!r}" if ret else
                               "pymavlink mavftp get: no result")
        return {"seconds": dt}
    finally:
        master.close()


def worker_main(kind, spec_text):
    spec = json.loads(spec_text)
    try:
        if kind == "mavsdk":
            try:
                from mavsdk.logging import log_subscribe

                log_subscribe(lambda *a: True)  # MAVSDK's own log: not on our stdout
            except Exception:  # noqa: BLE001
                pass
            res = asyncio.run(w_mavsdk(spec))
        elif kind == "pymavlink":
            res = w_pymavlink(spec)
        else:
            raise ValueError(kind)
        res["ok"] = True
    except TimedOut as e:
        res = {"ok": False, "timed_out": True, "error": str(e)}
    except Exception as e:  # noqa: BLE001
        tb = traceback.format_exc(limit=3).strip().splitlines()
        res = {"ok": False, "error": f"{type(e).__name__}: {e} [{' | '.join(tb[-2:])}]"}
    sys.stdout.write(json.dumps(res) + "\n")
    sys.stdout.flush()
    os._exit(0)  # no waiting for MAVSDK's threads


def m_mavsdk_params(ctx, link, timeout):
    res = run_worker("mavsdk", {"op": "params", "port": link.gcs_port, "timeout": timeout},
                     timeout)
    compare_params(ctx.table, res["values"], "MAVSDK get_all_params")
    return {"seconds": res["seconds"], "count": res["count"]}


def m_mavsdk_get(ctx, link, remote, data, timeout):
    local_dir = os.path.join(link.work, "mavsdk")
    os.makedirs(local_dir, exist_ok=True)
    res = run_worker("mavsdk", {"op": "ftp", "port": link.gcs_port, "timeout": timeout,
                                "remote": remote, "local_dir": local_dir}, timeout)
    local = os.path.join(local_dir, os.path.basename(remote))
    got = read(local) if os.path.exists(local) else None
    if got != data:
        fail(f"MAVSDK ftp download {remote}: {diff_bytes(got, data)}")
    return {"seconds": res["seconds"], "bytes": len(data)}


def m_pymavlink_get(ctx, link, remote, data, timeout):
    local = os.path.join(link.work, "pymavlink-got.bin")
    res = run_worker("pymavlink", {"port": link.gcs_port, "timeout": timeout,
                                   "remote": remote, "local": local}, timeout)
    got = read(local) if os.path.exists(local) else None
    if got != data:
        fail(f"pymavlink mavftp get {remote}: {diff_bytes(got, data)}")
    return {"seconds": res["seconds"], "bytes": len(data)}


def m_mavsdk_log(ctx, link, data, timeout):
    local = os.path.join(link.work, "mavsdk-log1.bin")
    res = run_worker("mavsdk", {"op": "log", "port": link.gcs_port, "timeout": timeout,
                                "local": local, "size": len(data)}, timeout)
    got = read(local) if os.path.exists(local) else None
    if got != data:
        fail(f"MAVSDK download_log_file 1: {diff_bytes(got, data)}")
    return {"seconds": res["seconds"], "bytes": len(data)}


# ---------------------------------------------------------------------------- the run

class Ctx:
    def __init__(self, binary, work, seed):
        self.binary = binary
        self.work = work
        self.seed = seed
        self.table = param_table()
        self.rows = []
        self.n = 0

    def record(self, section, case, tool, what, ref, rnd, outcome, relay=None, size=None):
        row = {"section": section, "case": case, "tool": tool, "what": what, "ref": ref,
               "round": rnd, "size_bytes": size}
        if isinstance(outcome, TimedOut):
            row.update(status="timeout", error=str(outcome))
        elif isinstance(outcome, BaseException):
            row.update(status="FAIL", error=str(outcome))
        else:
            row.update(status="ok", **{k: (round(v, 3) if isinstance(v, float) else v)
                                       for k, v in outcome.items()})
            if row.get("bytes") and row.get("seconds"):
                row["kib_s"] = round(row["bytes"] / 1024 / row["seconds"], 1)
        if relay is not None:
            row["relay"] = relay
        self.rows.append(row)
        label = f"{section}/{case} r{rnd} {tool} {what}"
        if row["status"] == "ok":
            extra = f" ({row['kib_s']} KiB/s)" if "kib_s" in row else ""
            own = f", own timer {row['own_seconds']} s" if row.get("own_seconds") is not None \
                else ""
            print(f"ok    {label}: {row['seconds']} s{extra}{own}", flush=True)
        else:
            print(f"FAIL  {label}: {row['status']}: {row['error'][:1500]}", flush=True)
        return row

    def measure(self, section, case, tool, what, ref, rnd, vehicle_args, fn, *args, size=None):
        """A fresh vehicle (and relay) for fn(ctx, link, *args, timeout) -> dict, recorded."""
        self.n += 1
        work = os.path.join(self.work, f"{self.n:03d}-{section}-{case}-{slug(tool)}-{slug(what)}")
        timeout = TIMEOUT[(section, case)]
        link = None
        relay = None
        try:
            link = Link(self.binary, case, vehicle_args, work, self.seed + rnd)
            outcome = fn(self, link, *args, timeout)
            link.vehicle.check_alive()
        except (Failure, TimedOut) as e:
            outcome = e
        except Exception as e:  # noqa: BLE001
            outcome = Failure(f"{type(e).__name__}: {e} "
                              f"[{' | '.join(traceback.format_exc(limit=3).strip().splitlines()[-2:])}]")
        finally:
            if link is not None:
                relay = link.close()
        return self.record(section, case, tool, what, ref, rnd, outcome, relay, size)


def slug(s):
    return re.sub(r"[^A-Za-z0-9]+", "-", str(s)).strip("-")[:40]


MS_FTP = "param list --via ftp"
MS_LIST = "param list --via list"
MS_GET = "ftp get"
MS_LOG = "log download --via log"


def run_params(ctx, rnd, params_file):
    va = ["--params", params_file]
    for case in ("clean", "lossy"):
        ctx.measure("params", case, "mavstack", MS_FTP, MS_FTP, rnd, va, m_mavstack_params, "ftp")
        ctx.measure("params", case, "mavstack", MS_LIST, MS_LIST, rnd, va, m_mavstack_params,
                    "list")
        ctx.measure("params", case, "MAVProxy 1.8.75", "param ftp", MS_FTP, rnd, va,
                    m_mavproxy_params, "ftp")
        ctx.measure("params", case, "MAVProxy 1.8.75", "param fetch", MS_LIST, rnd, va,
                    m_mavproxy_params, "list")
        ctx.measure("params", case, "MAVSDK 4.1.0", "get_all_params", MS_LIST, rnd, va,
                    m_mavsdk_params)


def run_files(ctx, rnd, params_file, ftp_root, files):
    va = ["--params", params_file, "--ftp-root", ftp_root]
    for case, name in (("clean", "clean.bin"), ("lossy", "lossy.bin")):
        data = files[name]
        remote = f"/{name}"
        for tool, what, fn in (("mavstack", MS_GET, m_mavstack_get),
                               ("MAVProxy 1.8.75", "ftp get", m_mavproxy_get),
                               ("MAVSDK 4.1.0", "Ftp.download", m_mavsdk_get),
                               ("pymavlink 2.4.50", "mavftp get", m_pymavlink_get)):
            ctx.measure("files", case, tool, what, MS_GET, rnd, va, fn, remote, data,
                        size=len(data))


def run_logs(ctx, rnd, params_file, log_dirs, logs):
    for case in ("clean", "lossy"):
        data = logs[case]
        va = ["--params", params_file, "--log-dir", log_dirs[case]]
        ctx.measure("logs", case, "mavstack", MS_LOG, MS_LOG, rnd, va, m_mavstack_log, "log",
                    data, size=len(data))
        ctx.measure("logs", case, "mavstack", "log download --via ftp", MS_LOG, rnd, va,
                    m_mavstack_log, "ftp", data, size=len(data))
        ctx.measure("logs", case, "MAVSDK 4.1.0", "LogFiles.download_log_file", MS_LOG, rnd, va,
                    m_mavsdk_log, data, size=len(data))
        ctx.measure("logs", case, "MAVProxy 1.8.75", "log download", MS_LOG, rnd, va,
                    m_mavproxy_log, data, size=len(data))


# ---------------------------------------------------------------------------- the table

def summarize(rows):
    """One entry per (section, case, tool, what): status, median seconds over the ok rounds,
    and the ratio to the median of the mavstack row named by ref."""
    groups = {}
    for r in rows:
        groups.setdefault((r["section"], r["case"], r["tool"], r["what"]), []).append(r)
    out = []
    for (section, case, tool, what), rs in groups.items():
        ok = [r for r in rs if r["status"] == "ok"]
        e = {"section": section, "case": case, "tool": tool, "what": what, "ref": rs[0]["ref"],
             "rounds": len(rs), "ok_rounds": len(ok),
             "status": "ok" if len(ok) == len(rs) else
             ("timeout" if any(r["status"] == "timeout" for r in rs) else "FAIL"),
             "size_bytes": rs[0].get("size_bytes")}
        if ok:
            e["seconds"] = round(statistics.median(r["seconds"] for r in ok), 3)
            owns = [r["own_seconds"] for r in ok if r.get("own_seconds") is not None]
            if owns:
                e["own_seconds"] = round(statistics.median(owns), 3)
            if e["size_bytes"]:
                e["kib_s"] = round(e["size_bytes"] / 1024 / e["seconds"], 1)
            counts = {r.get("count") for r in ok if r.get("count") is not None}
            if counts:
                e["count"] = sorted(counts)
        out.append(e)
    by = {(e["section"], e["case"], e["what"]): e for e in out if e["tool"] == "mavstack"}
    for e in out:
        ref = by.get((e["section"], e["case"], e["ref"]))
        if ref and "seconds" in e and "seconds" in ref:
            e["ratio_wall"] = round(e["seconds"] / ref["seconds"], 2)
            if (ref.get("own_seconds") or 0) >= 0.05:  # the CLI prints 2 decimals
                e["ratio_own"] = round(e["seconds"] / ref["own_seconds"], 2)
    return out


def size_label(n):
    return f"{n / (1 << 20):.3g} MiB" if n >= 1 << 20 else f"{n / 1024:.0f} KiB"


def markdown(summary, meta, logs_pending):
    lines = []
    cases = {"clean": "clean loopback",
             "lossy": f"lossy: {LOSS:.0%} loss and {DELAY * 1000:.0f} ms each way"}
    titles = {"params": f"Parameter table ({meta['params']} parameters)",
              "files": "MAVFTP file download",
              "logs": "Log download (LOG_*)"}
    for section in ("params", "files", "logs"):
        rows = [e for e in summary if e["section"] == section]
        if section == "logs" and logs_pending:
            lines += ["", f"### {titles[section]}", "",
                      "<!-- LOG DOWNLOAD NUMBERS GO HERE -->",
                      f"_Pending: `{meta['mavstack']} log --help` does not list `download` "
                      "yet; rerun `bench_ftp.py --only logs` once it does._"]
            continue
        if not rows:
            continue
        lines += ["", f"### {titles[section]}", "",
                  "| case | tool | operation | s | KiB/s | × mavstack | note |",
                  "| --- | --- | --- | ---: | ---: | ---: | --- |"]
        for e in rows:
            case = cases[e["case"]]
            if e.get("size_bytes"):
                case += f", {size_label(e['size_bytes'])}"
            if e["status"] != "ok" and "seconds" not in e:
                word = "timed out" if e["status"] == "timeout" else "FAIL"
                lines.append(f"| {case} | {e['tool']} | {e['what']} | **{word}** | | | "
                             f"{e['ok_rounds']}/{e['rounds']} rounds ok |")
                continue
            kib = f"{e['kib_s']:.0f}" if "kib_s" in e else ""
            ratio = f"{e['ratio_wall']:.2f}" if "ratio_wall" in e else ""
            if e["tool"] == "mavstack" and e["what"] == e["ref"]:
                ratio = "1"
            notes = []
            if e["tool"] == "mavstack":
                if e.get("own_seconds") is not None:
                    own_kib = (f", {e['size_bytes'] / 1024 / e['own_seconds']:.0f} KiB/s"
                               if e.get("size_bytes") and e["own_seconds"] > 0 else "")
                    own = (f"{e['own_seconds']:.2f} s" if e["own_seconds"] >= 0.005
                           else "<0.01 s")
                    notes.append(f"process start to exit; own timer {own}{own_kib}")
                else:
                    notes.append("process start to exit")
            else:
                notes.append("from the operation")
                if "ratio_own" in e:
                    notes.append(f"× mavstack's own timer {e['ratio_own']:.2f}")
            if e.get("count"):
                notes.append(f"{'/'.join(map(str, e['count']))} parameters")
            if e["status"] != "ok":
                notes.append(f"**{e['status']} in {e['rounds'] - e['ok_rounds']} of "
                             f"{e['rounds']} rounds**")
            lines.append(f"| {case} | {e['tool']} | {e['what']} | {e['seconds']:.2f} | {kib} | "
                         f"{ratio} | {'; '.join(notes)} |")
    lines += ["", f"× mavstack: this row's seconds over mavstack's for the same case "
                  f"(its `param list --via ftp` for `param ftp`, `--via list` for the other "
                  f"parameter fetches, `ftp get`, `log download --via log`); above 1 is slower. "
                  f"Medians of {meta['rounds']} round(s); {meta['host']}."]
    return "\n".join(lines)


def mavstack_version(binary):
    try:
        return subprocess.run([binary, "--version"], capture_output=True, text=True,
                              timeout=10).stdout.strip()
    except Exception:  # noqa: BLE001
        return None


def logs_available(binary):
    p = subprocess.run([binary, "log", "--help"], capture_output=True, text=True, timeout=10,
                       check=False)
    return p.returncode == 0 and re.search(r"^\s+download\s", p.stdout, re.M) is not None


def main():
    if len(sys.argv) >= 2 and sys.argv[1] == "--worker":
        worker_main(sys.argv[2], sys.argv[3])
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mavstack", default=os.path.join(ROOT, "target", "release", "mavstack"))
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--only", choices=["params", "files", "logs"])
    ap.add_argument("--out", help="the JSON document (default: bench_ftp.json in the work dir)")
    ap.add_argument("--keep", help="work directory (kept); default a temporary one, removed "
                                   "unless something failed")
    ap.add_argument("--seed", type=int, default=1, help="relay seed (round r: seed + r)")
    ap.add_argument("--lossy-kib", type=int, default=FILE_LOSSY_KIB,
                    help=f"size of the file and the log downloaded over the lossy link "
                         f"(default {FILE_LOSSY_KIB})")
    ap.add_argument("--timeout-scale", type=float, default=1.0,
                    help="multiply every deadline (for --lossy-kib 1024, say 6)")
    args = ap.parse_args()
    binary = os.path.abspath(args.mavstack)
    if not (os.path.isfile(binary) and os.access(binary, os.X_OK)):
        print(f"FAIL  mavstack binary {binary} is not an executable file", flush=True)
        return 1
    for mod in ("pexpect", "pymavlink.mavftp", "mavsdk"):
        try:
            __import__(mod)
        except Exception as e:  # noqa: BLE001
            print(f"FAIL  import {mod}: {e} (run scripts/setup-peers.sh)", flush=True)
            return 1
    if args.keep:
        os.makedirs(args.keep, exist_ok=True)
    work = os.path.abspath(args.keep or tempfile.mkdtemp(prefix="bench-ftp-"))
    t0 = time.monotonic()
    ctx = Ctx(binary, work, args.seed)
    params_file = os.path.join(work, "bench.parm")
    write_param_file(params_file, ctx.table)
    rng = random.Random(20240601)
    ftp_root = os.path.join(work, "ftp-root")
    os.makedirs(ftp_root, exist_ok=True)
    for k in TIMEOUT:
        TIMEOUT[k] = round(TIMEOUT[k] * args.timeout_scale)
    lossy_size = args.lossy_kib * 1024
    lossy_size += lossy_size % 90 == 0  # MAVProxy's log download ends on a short chunk
    files = {"clean.bin": rng.randbytes(FILE_CLEAN), "lossy.bin": rng.randbytes(lossy_size)}
    for name, data in files.items():
        with open(os.path.join(ftp_root, name), "wb") as f:
            f.write(data)
    logs = {"clean": rng.randbytes(LOG_CLEAN), "lossy": rng.randbytes(lossy_size)}
    log_dirs = {}
    for case, data in logs.items():
        log_dirs[case] = os.path.join(work, f"logs-{case}")
        os.makedirs(log_dirs[case], exist_ok=True)
        with open(os.path.join(log_dirs[case], "00000001.BIN"), "wb") as f:
            f.write(data)
    sections = [args.only] if args.only else ["params", "files", "logs"]
    logs_pending = "logs" in sections and not logs_available(binary)
    meta = {
        "script": "tests-interop/bench_ftp.py", "command": sys.argv,
        "mavstack": binary, "mavstack_version": mavstack_version(binary),
        "peers": {"MAVProxy": "1.8.75", "mavsdk": "4.1.0 (native binding)",
                  "pymavlink": "2.4.50"},
        "rounds": args.rounds, "sections": sections, "params": len(ctx.table),
        "link": {"clean": "loopback UDP, vehicle udpout -> ground station udpin",
                 "lossy": {"relay": "tests-interop/lossy_relay.py LossyRelay", "loss": LOSS,
                           "delay_s": DELAY, "seed": f"{args.seed} + round"}},
        "sizes": {"file_clean": FILE_CLEAN, "file_lossy": lossy_size, "log_clean": LOG_CLEAN,
                  "log_lossy": lossy_size},
        "timeouts_s": {f"{s}/{c}": v for (s, c), v in TIMEOUT.items()},
        "host": f"{platform.node()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f} at start",
        "work": work,
    }
    print(f"bench_ftp: {binary} ({meta['mavstack_version']}), {args.rounds} round(s), "
          f"{', '.join(sections)}; work {work}", flush=True)
    if logs_pending:
        print("note  logs: `mavstack log --help` lists no `download`: the log section is left "
              "as a placeholder", flush=True)
    for rnd in range(args.rounds):
        if "params" in sections:
            run_params(ctx, rnd, params_file)
        if "files" in sections:
            run_files(ctx, rnd, params_file, ftp_root, files)
        if "logs" in sections and not logs_pending:
            run_logs(ctx, rnd, params_file, log_dirs, logs)
    summary = summarize(ctx.rows)
    failed = [r for r in ctx.rows if r["status"] != "ok"]
    meta["seconds"] = round(time.monotonic() - t0, 1)
    meta["load_at_end"] = round(os.getloadavg()[0], 2)
    doc = {**meta, "ok": not failed, "logs_pending": logs_pending, "summary": summary,
           "results": ctx.rows}
    out = args.out or os.path.join(work, "bench_ftp.json")
    with open(out, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    print(markdown(summary, meta, logs_pending), flush=True)
    print("", flush=True)
    for r in failed:
        print(f"FAIL  {r['section']}/{r['case']} round {r['round']} {r['tool']} {r['what']}: "
              f"{r['status']}: {r['error'][:300]}", flush=True)
    print(f"bench_ftp: {len(ctx.rows) - len(failed)} ok, {len(failed)} failed or timed out, "
          f"{meta['seconds']} s; JSON: {out}", flush=True)
    if not failed and not args.keep:
        # keep the JSON when it was written into the work directory
        if os.path.dirname(os.path.abspath(out)) != work:
            shutil.rmtree(work, ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
