#!/usr/bin/env python3
"""The flight-stack scenarios: `mavstack` against one running vehicle (ArduPilot SITL, PX4 SITL
or `mavstack vehicle` in either flavour), with pymavlink as the independent peer where a
scenario compares.

usage: flight_stacks.py --mavstack BIN --name NAME --conn CONN [--out FILE.json] [--only S,...]

CONN is the ground station's side (`tcp:127.0.0.1:5760` for ArduPilot's SERIAL0,
`udpin:127.0.0.1:14550` for PX4 and the simulator on udpout). Each scenario prints one line
`NAME scenario: pass|fail|n/a (seconds) detail`; --out writes them all as JSON. Exit 0 when
none failed.

Scenarios (in this order, each independent of the ones before but the flight, last):
  probe        the handshake: PROTOCOL_VERSION, or the documents' fallback (AUTOPILOT_VERSION
               in MAVLink 2) where the system refuses it
  conform      `mavstack conform --json`: no must or should rule fails
  params       the whole table, timed; the same names, values and count as pymavlink's fetch
               (PARAM_REQUEST_LIST, gaps re-read) of the same vehicle
  param_set    an integer and a float parameter set to another value, read back, set back
  mission      a 60-item plan (QGC WPL: home, take-off, 57 waypoints, RTL) uploaded and read
               back equal under the autopilot's convention (ArduPilot's home at 0, PX4's none)
  arm_refused  right after start, arming is refused with the reason shown (STATUSTEXT); n/a
               when the vehicle is ready at once
  signing      `mavstack signing setup` proven by a signed answer, then removed
  router       the vehicle behind `mavstack router` (CONN as its vehicle link), with peers on
               links of their own: `mavstack param list`, MAVProxy (param fetch count, `wp
               list`), MAVSDK's native binding (get_all_params count) and, on a `version=1`
               link, a MAVLink 1 peripheral (pymavlink's v1.0 codec, compid 158): its HEARTBEAT
               reaches MAVProxy and the vehicle link (converted to MAVLink 2), and it receives
               the vehicle's HEARTBEAT in MAVLink 1. Passes when each peer got the full
               parameter count of a direct fetch (`mavstack param list` on CONN, first)
  record       `mavstack record CONN FILE.tlog --duration 10`, then `mavstack log summary
               --json FILE` and pymavlink's reading of the same tlog agree on the count of
               every message type (per system and component)
  aio          mavstack.aio's ground-station session (tests-interop/flight_aio.py): the
               vehicle found, the whole parameter table (the count `params` got), a get, a
               20-item plan up and down, ATTITUDE asked at 10 Hz and seen at 8-12 Hz, arming
               accepted or refused with the reasons, a mode change there and back
  pymavlink_scripts  the scripts written for pymavlink only (crates/mavstack-python/tests/
               pymavlink_scripts), each run with pymavlink and then unchanged with
               mavstack.mavutil: the same lines printed (arm_mode and signing on ArduPilot)
  flight       (with --flight BIN, the `flight` example of crates/mavstack) telemetry at
               requested rates (ATTITUDE 10 Hz, GLOBAL_POSITION_INT 5 Hz, within 20 % over 5 s),
               then arm (refusals waited out), take off, a 4-item mission flown to its end
               (MISSION_ITEM_REACHED for every item), RTL, landed and disarmed
  signed_router (with --signed-link CONN2, a second link of the vehicle's, ArduPilot's SERIAL1;
               n/a without) signing set up on CONN, then: an unsigned PARAM_REQUEST_READ straight
               on CONN2 goes unanswered (ArduPilot takes unsigned frames on its USB port only),
               and through `mavstack router 'CONN2?key=K&link_id=2' 'udpout:...?trusted=true'`
               `mavstack param get` from an unsigned ground link is answered; the router's
               vehicle link counts signed frames in and out; signing removed at the end
  modes, takeoff_goto, offboard, manual
               mavstack.aio's flying API (tests-interop/flight_flying.py, whose docstring says
               what each checks): the vehicle's modes set by name and by standard name; take
               off 10 m, goto 30 m north, land; offboard velocity and position setpoints; sticks
               in a position mode
  shell        `mavstack shell CONN --command "ver all"` (SERIAL_CONTROL to the SHELL device):
               the version lines PX4's `ver all` prints; n/a on ArduPilot, which has no SHELL
               device (its SERIAL_CONTROL reaches serial ports only) and does not answer
  rtk          `mavstack rtk CONN --from FILE`: an RTCM3 stream (frames of 25, 360, 720 and 20
               bytes between garbage) sent as 9 GPS_RTCM_DATA (360 bytes ending with an empty
               fragment); on PX4, `listener gps_inject_data` through the shell then shows the
               last one as sent (length, flags and bytes); elsewhere the vehicle gives no
               readout (ArduPilot counts the fragments it used in its log, GPA.RTCMFU)
  gimbal, camera
               `mavstack gimbal` and `mavstack camera` (tests-interop/flight_payload.py, whose
               docstring says what each checks and what each stack is told first): a manager
               found, angles set and read back, a location pointed at and cleared; a camera
               found, a photo announced by CAMERA_IMAGE_CAPTURED, its settings where it has a
               definition; n/a with what the stack was asked and answered where it lacks them
               (with --camera-restart CMD, a command that starts the vehicle again with its
               camera, for the simulator)
  restart      (with --restart CMD, a command that kills the vehicle and starts it again; last)
               `mavstack listen CONN --rate ATTITUDE:4` running while the vehicle is restarted:
               it keeps running (a TCP link reconnects), hears the new instance's HEARTBEAT
               and, since ArduPilot streams nothing unasked, its ATTITUDE again (the rate asked
               anew); then `mavstack param get` answers from the new instance
"""
import argparse
import asyncio
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time

from pymavlink import mavutil

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import flight_payload  # noqa: E402
KEY = "a1" * 32
PERIPHERAL_COMPID = 158  # MAV_COMP_ID_PERIPHERAL


def run(argv, timeout=120, env=None):
    t = time.monotonic()
    try:
        p = subprocess.run(argv, capture_output=True, text=True, timeout=timeout, env=env)
    except subprocess.TimeoutExpired:
        return None, "", "timed out after %d s" % timeout, time.monotonic() - t
    return p.returncode, p.stdout, p.stderr, time.monotonic() - t


class Runner:
    def __init__(self, bin_, name, conn, flight=None, restart=None, signed_link=None, camera_restart=None):
        self.bin, self.name, self.conn, self.flight_bin = bin_, name, conn, flight
        self.restart_cmd = restart
        self.camera_restart = camera_restart
        self.signed_link = signed_link
        self.results = []

    def mavstack(self, *args, timeout=120):
        return run([self.bin, *args], timeout)

    def report(self, scenario, status, seconds, detail):
        self.results.append({"target": self.name, "scenario": scenario, "status": status,
                             "seconds": round(seconds, 2), "detail": detail})
        print("%s %s: %s (%.2f s) %s" % (self.name, scenario, status, seconds, detail), flush=True)

    # ----- scenarios ------------------------------------------------------------------------

    def probe(self):
        rc, out, err, s = self.mavstack("probe", self.conn, "--timeout", "15")
        try:
            r = json.loads(out.splitlines()[0])
        except (ValueError, IndexError):
            return self.report("probe", "fail", s, "no report (exit %s): %s" % (rc, err.strip()[-300:]))
        hs = r.get("handshake", {})
        ok = rc == 0 and hs.get("result") in ("protocol_version", "message_v2")
        self.report("probe", "pass" if ok else "fail", s,
                    "%s -> %s, MAVLink %s -> %s, mavlink2_capability %s%s" % (
                        hs.get("method"), hs.get("result"), r.get("version_before"), r.get("version_after"),
                        r.get("mavlink2_capability"),
                        ", protocol_version_supported false" if r.get("protocol_version_supported") is False
                        else ""))

    def conform(self):
        rc, out, err, s = self.mavstack("conform", self.conn, "--json", "--timeout", "15")
        try:
            r = json.loads(out)
        except ValueError:
            return self.report("conform", "fail", s, "no report (exit %s): %s" % (rc, err.strip()[-300:]))
        failed = ["%s (%s): %s" % (x["id"], x["level"], x["evidence"]) for x in r["rules"]
                  if x["status"] == "fail" and x["level"] != "info"]
        info = [x["id"] for x in r["rules"] if x["status"] == "fail" and x["level"] == "info"]
        sm = r["summary"]
        detail = "%d pass, %d fail, %d n/a" % (sm["pass"], sm["fail"], sm["n/a"])
        if info:
            detail += "; info: %s" % ", ".join(info)
        if failed:
            detail += "; failing: " + "; ".join(failed)
        self.report("conform", "pass" if rc == 0 and not failed else "fail", s, detail)

    def our_params(self):
        rc, out, err, s = self.mavstack("param", "list", self.conn, "--json", timeout=180)
        if rc != 0:
            return None, s, err.strip()[-300:]
        table = {}
        for line in out.splitlines():
            p = json.loads(line)
            table[p["name"]] = (p["value"], p["type"])
        return table, s, ""

    def pymavlink_params(self, timeout=60.0):
        """pymavlink's fetch: PARAM_REQUEST_LIST, then PARAM_REQUEST_READ for the gaps."""
        m = mavutil.mavlink_connection(self.conn, source_system=254, source_component=190,
                                       dialect="ardupilotmega")
        try:
            hb = m.wait_heartbeat(timeout=15)
            if hb is None:
                return None
            target = (hb.get_srcSystem(), hb.get_srcComponent())
            bytewise = hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4
            m.mav.param_request_list_send(*target)
            got, count = {}, None
            deadline = time.monotonic() + timeout
            last_new = time.monotonic()
            while time.monotonic() < deadline:
                msg = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
                if msg is not None and msg.get_srcSystem() == target[0]:
                    count = msg.param_count
                    if msg.param_index not in got or msg.param_index == 65535:
                        last_new = time.monotonic()
                    got[msg.param_index] = (msg.param_id, msg.param_value, msg.param_type)
                if count is not None and all(i in got for i in range(count)):
                    break
                if count is not None and time.monotonic() - last_new > 1.0:
                    for i in range(count):
                        if i not in got:
                            m.mav.param_request_read_send(target[0], target[1], b"", i)
                    last_new = time.monotonic()
            return {name: (decode_value(value, ptype, bytewise), ptype)
                    for i, (name, value, ptype) in got.items() if i != 65535}
        finally:
            m.close()

    def params(self):
        ours, s, err = self.our_params()
        if ours is None:
            return self.report("params", "fail", s, "param list failed: %s" % err)
        theirs = self.pymavlink_params()
        if theirs is None:
            return self.report("params", "fail", s, "pymavlink heard no vehicle")
        missing = sorted(set(theirs) - set(ours))
        extra = sorted(set(ours) - set(theirs))
        def same(a, b):
            return a == b or (isinstance(a, float) and isinstance(b, float) and
                              (math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-6) or (math.isnan(a) and math.isnan(b))))
        differ = [name for name in set(ours) & set(theirs) if not same(ours[name][0], theirs[name][0])]
        # A value the vehicle changed itself between the two reads (ArduPilot sets COMPASS_DEC
        # once its GPS has a fix): read again, ours must now agree with pymavlink's.
        changed = []
        if differ:
            again, _, _ = self.our_params()
            changed = [n for n in differ if again and n in again and same(again[n][0], theirs[n][0])]
        differ = ["%s %r vs %r" % (n, ours[n][0], theirs[n][0]) for n in sorted(differ) if n not in changed]
        ok = not missing and not extra and not differ
        self.report("params", "pass" if ok else "fail", s,
                    "%d parameters in %.2f s (pymavlink: %d)%s%s" % (
                        len(ours), s, len(theirs),
                        "; changed by the vehicle between the reads, read again equal: %s" % changed
                        if changed else "",
                        "" if ok else "; missing %s, extra %s, differ %s" % (missing[:5], extra[:5], differ[:5])))
        self.table = ours

    def param_set(self):
        table = getattr(self, "table", None)
        if not table:
            return self.report("param_set", "n/a", 0.0, "no parameter table")
        int_name = next((n for n, (v, t) in sorted(table.items()) if t in ("INT32", "INT16", "UINT8", "INT8")
                         and isinstance(v, int) and 1 <= v < 100 and not n.startswith(("SYSID", "MAV_SYS", "SERIAL",
                                                                                         "SR", "MAV_"))), None)
        float_name = next((n for n, (v, t) in sorted(table.items()) if t == "REAL32" and isinstance(v, float)
                           and 1.0 <= v < 1000.0), None)
        done, t0 = [], time.monotonic()
        for name in (int_name, float_name):
            if name is None:
                continue
            old = table[name][0]
            new = old + 1 if isinstance(old, int) else round(old * 1.5, 3)
            rc, out, err, _ = self.mavstack("param", "set", self.conn, name, str(new), "--json")
            rc2, out2, _, _ = self.mavstack("param", "get", self.conn, name, "--json")
            back = json.loads(out2.splitlines()[0])["value"] if rc2 == 0 and out2 else None
            self.mavstack("param", "set", self.conn, name, str(old))
            ok = rc == 0 and back is not None and math.isclose(float(back), float(new), rel_tol=1e-6)
            done.append((name, old, new, back, ok, err.strip()[-200:]))
        s = time.monotonic() - t0
        if not done:
            return self.report("param_set", "n/a", s, "no suitable int/float parameter")
        ok = all(d[4] for d in done)
        self.report("param_set", "pass" if ok else "fail", s,
                    "; ".join("%s %s -> %s, read back %s%s" % (d[0], d[1], d[2], d[3], "" if d[4] else " FAIL " + d[5])
                              for d in done))

    def mission(self, n=60):
        home = (-35.363261, 149.165230, 584.0)
        if self.name.startswith("px4"):
            home = (47.397742, 8.545594, 488.0)
        lines = ["QGC WPL 110", "0\t1\t0\t16\t0\t0\t0\t0\t%.7f\t%.7f\t%.2f\t1" % home,
                 "1\t0\t3\t22\t0\t0\t0\t0\t%.7f\t%.7f\t20\t1" % home[:2]]
        for i in range(2, n - 1):
            lines.append("%d\t0\t3\t16\t0\t0\t0\t0\t%.7f\t%.7f\t%d\t1" % (
                i, home[0] + 0.0001 * i, home[1] + 0.00005 * i, 20 + i % 7))
        lines.append("%d\t0\t2\t20\t0\t0\t0\t0\t0\t0\t0\t1" % (n - 1))
        with tempfile.TemporaryDirectory() as d:
            plan = os.path.join(d, "plan.waypoints")
            back = os.path.join(d, "back.waypoints")
            with open(plan, "w") as f:
                f.write("\n".join(lines) + "\n")
            rc, out, err, s_up = self.mavstack("mission", "upload", self.conn, plan, "--json")
            if rc != 0:
                return self.report("mission", "fail", s_up, "upload: %s" % err.strip()[-300:])
            up = json.loads(out)["seconds"]
            rc, out, err, s_down = self.mavstack("mission", "download", self.conn, back)
            if rc != 0:
                return self.report("mission", "fail", s_down, "download: %s" % err.strip()[-300:])
            sent = [l.split("\t") for l in lines[1:]]
            with open(back) as f:
                got = [l.rstrip("\n").split("\t") for l in f.read().splitlines()[1:]]
        diffs = compare_plans(sent, got)
        self.report("mission", "pass" if not diffs else "fail", s_up + s_down,
                    "%d items, upload %.2f s, read back %s" % (n, up, "equal" if not diffs else "different: %s" % diffs[:3]))

    def arm_refused(self):
        rc, out, err, s = self.mavstack("command", self.conn, "arm", "--json", timeout=60)
        try:
            r = json.loads(out.splitlines()[0])
        except (ValueError, IndexError):
            return self.report("arm_refused", "fail", s, "no answer: %s" % err.strip()[-300:])
        if r["result"] == "ACCEPTED":
            self.mavstack("command", self.conn, "disarm", "--force")
            return self.report("arm_refused", "n/a", s, "armed at once (ready)")
        ok = bool(r.get("statustext"))
        self.report("arm_refused", "pass" if ok else "fail", s,
                    "%s, reason: %s" % (r["result"], r.get("statustext")))

    def signing(self):
        rc, out, err, s = self.mavstack("signing", "setup", self.conn, "--key", KEY, "--link-id", "1", timeout=60)
        if rc != 0 and self.name == "px4":
            # PX4 (1.16) has no message signing: its mavlink module ignores SETUP_SIGNING.
            return self.report("signing", "n/a", s, "no signing in PX4's mavlink module: %s" % out.strip())
        if rc != 0:
            return self.report("signing", "fail", s, "setup: %s %s" % (out.strip(), err.strip()[-300:]))
        rc2, out2, err2, s2 = self.mavstack("signing", "remove", self.conn, "--key", KEY, "--link-id", "1", timeout=60)
        ok = rc2 == 0
        self.report("signing", "pass" if ok else "fail", s + s2,
                    "%s; %s" % (out.strip(), (out2.strip() or err2.strip()[-300:])))

    def router(self):
        """The vehicle behind `mavstack router`, peers on links of their own (see the docstring)."""
        t0 = time.monotonic()
        # A fresh direct count: PX4's table grows after start (904, then 907 parameters).
        table, _, err = self.our_params()
        if table is None:
            return self.report("router", "fail", time.monotonic() - t0, "direct param list failed: %s" % err)
        direct = len(table)
        with tempfile.TemporaryDirectory(prefix="fs-router-") as work:
            try:
                detail, ok = router_session(self.bin, self.conn, work, direct)
            except Exception as e:  # gcs_common.Failure and the peers' own errors
                detail, ok = "%s: %s" % (type(e).__name__, str(e).strip()[:700]), False
        self.report("router", "pass" if ok else "fail", time.monotonic() - t0,
                    "direct %d; %s" % (direct, detail))

    def aio(self):
        """mavstack.aio's session (tests-interop/flight_aio.py): every step passes."""
        table = self.our_params()[0]  # a fresh count, as router's
        argv = [sys.executable, os.path.join(HERE, "flight_aio.py"), self.conn]
        if table:
            argv += ["--params", str(len(table))]
        rc, out, err, s = run(argv, timeout=300)
        try:
            steps = json.loads(out.splitlines()[-1])
        except (ValueError, IndexError):
            return self.report("aio", "fail", s, "no report (exit %s): %s" % (rc, err.strip()[-300:]))
        detail = "; ".join("%s %s%s (%.1f s)" % (x["step"], x["detail"], "" if x["ok"] else " FAILED",
                                                  x["seconds"]) for x in steps)
        self.report("aio", "pass" if rc == 0 else "fail", s, detail)

    def flying(self, scenario):
        """One scenario of tests-interop/flight_flying.py (mavstack.aio's flying API)."""
        argv = [sys.executable, os.path.join(HERE, "flight_flying.py"), self.conn, scenario]
        rc, out, err, s = run(argv, timeout=600)
        try:
            steps = json.loads(out.splitlines()[-1])
        except (ValueError, IndexError):
            return self.report(scenario, "fail", s, "no report (exit %s): %s" % (rc, err.strip()[-300:]))
        detail = "; ".join("%s %s%s" % (x["step"], x["detail"], "" if x["ok"] else " FAILED") for x in steps)
        self.report(scenario, "pass" if rc == 0 else "fail", s, detail)

    def modes(self):
        self.flying("modes")

    def takeoff_goto(self):
        self.flying("takeoff_goto")

    def offboard(self):
        self.flying("offboard")

    def manual(self):
        self.flying("manual")

    def shell(self):
        rc, out, err, s = self.mavstack("shell", self.conn, "--command", "ver all", "--json", "--timeout", "15")
        if rc != 0 and "no answer from the shell" in err and "ardupilot" in self.name:
            return self.report("shell", "n/a", s, "ArduPilot has no SHELL device: %s" % err.strip()[-160:])
        try:
            output = json.loads(out.splitlines()[0])["output"]
        except (ValueError, IndexError, KeyError):
            return self.report("shell", "fail", s, "exit %s: %s" % (rc, err.strip()[-300:]))
        version = [line for line in output.splitlines() if line.startswith("PX4 version:")]
        ok = rc == 0 and bool(version) and "nsh>" not in output and "pxh>" not in output
        self.report("shell", "pass" if ok else "fail", s, "%d lines, %s" % (len(output.splitlines()),
                                                                           version or output[:200]))

    def rtk(self):
        frames = [rtcm3_frame(1005, 25), rtcm3_frame(1077, 360), rtcm3_frame(1087, 720), rtcm3_frame(1230, 20)]
        with tempfile.TemporaryDirectory(prefix="fs-rtk-") as work:
            path = os.path.join(work, "base.rtcm3")
            with open(path, "wb") as f:
                f.write(b"garbage" + frames[0] + frames[1] + b"\x00\xd3" + frames[2] + frames[3])
            rc, out, err, s = self.mavstack("rtk", self.conn, "--from", path, "--json", "--timeout", "15")
        try:
            r = json.loads(out.splitlines()[-1])
        except (ValueError, IndexError):
            return self.report("rtk", "fail", s, "exit %s: %s" % (rc, err.strip()[-300:]))
        sent = (r.get("sent"), r.get("messages"), r.get("sent_bytes"))
        if rc != 0 or sent != (4, 9, 1125):
            return self.report("rtk", "fail", s, "exit %s, sent %s: %s" % (rc, r, err.strip()[-200:]))
        detail = "4 frames in 9 GPS_RTCM_DATA"
        rc2, out2, err2, s2 = self.mavstack("shell", self.conn, "--command", "listener gps_inject_data",
                                            "--timeout", "15")
        if rc2 == 0 and "TOPIC: gps_inject_data" in out2:
            # The listener may print an older message first: the last one printed is the newest.
            last = out2.split("TOPIC: gps_inject_data")[-1]
            want_data = ", ".join(str(b) for b in frames[3])
            ok = "len: 20" in last and ("data: [%s," % want_data) in last and "flags: " in last
            return self.report("rtk", "pass" if ok else "fail", s + s2,
                               "%s; PX4's gps_inject_data %s" % (detail, "holds the last one as sent" if ok
                                                                 else "differs: %s" % last[:300]))
        self.report("rtk", "pass", s, "%s; no readout on this vehicle" % detail)

    def pymavlink_scripts(self):
        """The scripts written for pymavlink (crates/mavstack-python/tests/pymavlink_scripts),
        each run with pymavlink, then unchanged with mavstack.mavutil in its place: the same
        lines printed. arm_mode (pymavlink's ArduPilot helpers) and signing on ArduPilot
        only; what a script changes is put back after each run."""
        scripts_dir = os.path.join(HERE, "..", "crates", "mavstack-python", "tests", "pymavlink_scripts")
        shim = os.path.join(scripts_dir, "run_with_mavstack.py")
        names = ["heartbeat.py", "attitude.py", "params.py", "mission.py", "interval.py"]
        if "ardupilot" in self.name:
            names += ["arm_mode.py", "signing.py"]
        env = dict(os.environ, MAVLINK20="1", MAVLINK_DIALECT="ardupilotmega")
        t0 = time.monotonic()
        table = getattr(self, "table", None) or self.our_params()[0] or {}
        # What a script changes is put back after each run, so that both runs meet the same
        # vehicle: the parameter params.py sets (as it chooses it), the mode arm_mode.py
        # leaves, the key signing.py sets up.
        param = "RTL_ALT" if "RTL_ALT" in table else next(
            (n for n in sorted(table) if table[n][1] == "REAL32"), None)
        modes = []

        def restore(script):
            if script == "params.py" and param:
                self.mavstack("param", "set", self.conn, param, str(table[param][0]), timeout=60)
            elif script == "arm_mode.py" and modes:
                self.mavstack("command", self.conn, "mode", modes[0], timeout=60)
            elif script == "signing.py":
                self.mavstack("signing", "remove", self.conn, "--key", bytes(range(32)).hex(), "--link-id", "1",
                              timeout=60)

        same, differ = [], []
        for script in names:
            outs = []
            for shimmed in (False, True):
                argv = [sys.executable] + ([shim] if shimmed else []) + [os.path.join(scripts_dir, script), self.conn]
                outs.append(run(argv, timeout=120, env=env)[:3])
                if script == "arm_mode.py" and not modes and outs[-1][1].startswith("mode "):
                    modes.append(outs[-1][1].split()[1])
                restore(script)
            (rc1, o1, e1), (rc2, o2, e2) = outs
            # The same observable result: the same lines and the same exit status (a script
            # that stops the same way with both, as interval.py on PX4, which does not answer
            # REQUEST_MESSAGE for MESSAGE_INTERVAL, counts as the same; its status is shown).
            if rc1 == rc2 and rc1 is not None and o1 == o2 and (o1.strip() or e1.strip()):
                last = (e1.strip().splitlines() or [""])[-1]
                same.append(script[:-3] + ("" if rc1 == 0 else " (both exit %d: %s)" % (rc1, last[-80:])))
            else:
                a, b = o1.splitlines(), o2.splitlines()
                lines = [("%r vs %r" % (x, y)) for x, y in zip(a, b) if x != y][:2]
                differ.append("%s: pymavlink exit %s, mavstack exit %s%s%s" % (
                    script[:-3], rc1, rc2, "; " + "; ".join(lines) if lines else "",
                    "; " + (e1 or e2).strip()[-200:] if rc1 or rc2 else ""))
        self.report("pymavlink_scripts", "fail" if differ else "pass", time.monotonic() - t0,
                    "same output: %s%s" % (", ".join(same) or "none", "; differ: " + " | ".join(differ)
                                           if differ else ""))

    def record(self, seconds=10):
        with tempfile.TemporaryDirectory(prefix="fs-record-") as d:
            path = os.path.join(d, "rec.tlog")
            rc, out, err, s = self.mavstack("record", self.conn, path, "--duration", str(seconds),
                                            timeout=seconds + 30)
            if rc != 0 or not os.path.exists(path):
                return self.report("record", "fail", s, "record (exit %s): %s" % (rc, err.strip()[-300:]))
            rc, out, err, _ = self.mavstack("log", "summary", path, "--json")
            if rc != 0:
                return self.report("record", "fail", s, "log summary (exit %s): %s" % (rc, err.strip()[-300:]))
            summary = json.loads(out)
            ours = {}
            for sysrow in summary.get("systems", []):
                for name, t in sysrow.get("types", {}).items():
                    ours[(sysrow["sysid"], sysrow["compid"], name)] = t["count"]
            theirs, bad = pymavlink_tlog_counts(path)
        differ = sorted("%d/%d %s: %s vs %s" % (k[0], k[1], k[2], ours.get(k), theirs.get(k))
                        for k in set(ours) | set(theirs) if ours.get(k) != theirs.get(k))
        frames = sum(ours.values())
        ok = frames > 0 and not differ and summary.get("bad_frames", 0) == 0
        self.report("record", "pass" if ok else "fail", s,
                    "%d frames, %d types in %.1f s (MAVLink 2: %s, MAVLink 1: %s); pymavlink %d frames, "
                    "%d bad%s" % (frames, len(ours), summary.get("duration_s", 0),
                                  summary.get("versions", {}).get("2"), summary.get("versions", {}).get("1"),
                                  sum(theirs.values()), bad,
                                  "; counts agree per type" if not differ else "; differ: %s" % differ[:6]))

    def unsigned_param_read(self, conn, name, wait=4.0):
        """pymavlink, unsigned, on CONN: whether a PARAM_REQUEST_READ of NAME is answered."""
        m = mavutil.mavlink_connection(conn, source_system=254, source_component=190,
                                       dialect="ardupilotmega")
        try:
            hb = m.wait_heartbeat(timeout=15)
            if hb is None:
                return None
            deadline = time.monotonic() + wait
            m.mav.param_request_read_send(hb.get_srcSystem(), hb.get_srcComponent(), name.encode(), -1)
            while time.monotonic() < deadline:
                msg = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
                if msg is not None and msg.param_id == name:
                    return True
            return False
        finally:
            m.close()

    def signed_router(self):
        """A signed link between `mavstack router` and the vehicle (see the docstring)."""
        if not self.signed_link:
            return self.report("signed_router", "n/a", 0.0, "no --signed-link (a second vehicle link)")
        t0 = time.monotonic()
        name = "RTL_ALT"
        rc, out, err, _ = self.mavstack("signing", "setup", self.conn, "--key", KEY, "--link-id", "1", timeout=60)
        if rc != 0:
            return self.report("signed_router", "fail", time.monotonic() - t0,
                               "setup: %s %s" % (out.strip(), err.strip()[-300:]))
        parts, ok = ["signing set up on %s" % self.conn], True
        try:
            direct = self.unsigned_param_read(self.signed_link, name)
            ok &= direct is False
            parts.append("unsigned PARAM_REQUEST_READ on %s: %s" % (
                self.signed_link, {None: "no HEARTBEAT", True: "answered (should not be)",
                                   False: "unanswered"}[direct]))
            port = free_udp()
            link = self.signed_link
            with tempfile.TemporaryDirectory(prefix="fs-signed-") as work:
                from gcs_common import Router, link_stats
                router = Router(self.bin, ["%s?key=%s&link_id=2&name=vehicle" % (link, KEY),
                                           "udpout:127.0.0.1:%d?trusted=true&name=gcs" % port], work)
                stats = None
                try:
                    rc, out, err, s = self.mavstack("param", "get", "udpin:127.0.0.1:%d" % port, name,
                                                    "--json", timeout=90)
                    got = json.loads(out.splitlines()[0])["value"] if rc == 0 and out else None
                    ok &= got is not None
                    parts.append("through the router, unsigned ground link: param get %s = %s in %.1f s%s" % (
                        name, got, s, "" if rc == 0 else " (exit %s: %s)" % (rc, err.strip()[-200:])))
                finally:
                    try:
                        stats = router.stop()
                    except Exception as e:
                        router.kill()
                        ok = False
                        parts.append("router stop: %s" % str(e)[-200:])
                if stats:
                    veh = link_stats(stats, "vehicle")
                    version = sorted({str(e.get("version")) for e in veh})
                    verified = sum(int(e.get("rx_frames") or 0) for e in veh)
                    signed_out = sum(int((e.get("conversions") or {}).get("signed") or 0) for e in veh)
                    dropped = {}
                    for e in veh:
                        for k, v in (e.get("dropped") or {}).items():
                            dropped[k] = dropped.get(k, 0) + int(v)
                    ok &= version == ["signed"] and verified > 0 and signed_out > 0
                    parts.append("router vehicle link %s: %d frames in (each verified), %d of the ground "
                                 "link's signed onto it; dropped %s" % ("/".join(version), verified,
                                                                        signed_out, dropped or "none"))
        finally:
            rc2, out2, err2, _ = self.mavstack("signing", "remove", self.conn, "--key", KEY, "--link-id", "1",
                                               timeout=60)
            ok &= rc2 == 0
            parts.append("signing removed" if rc2 == 0 else "remove failed: %s" % (out2.strip() or err2.strip()[-200:]))
        self.report("signed_router", "pass" if ok else "fail", time.monotonic() - t0, "; ".join(parts))

    def restart(self):
        """The vehicle restarted under a running `mavstack listen` (see the docstring)."""
        if not self.restart_cmd:
            return self.report("restart", "n/a", 0.0, "no --restart command")
        t0 = time.monotonic()
        p = subprocess.Popen([self.bin, "listen", self.conn, "--filter", "HEARTBEAT,ATTITUDE",
                              "--rate", "ATTITUDE:4"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
        heard = []  # (monotonic time, message name)

        def read():
            for line in p.stdout:
                try:
                    heard.append((time.monotonic(), json.loads(line)["name"]))
                except (ValueError, KeyError, TypeError):
                    pass
        reader = threading.Thread(target=read, daemon=True)
        reader.start()

        def seen(name, since, timeout):
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                if any(t >= since and n == name for t, n in heard):
                    return True
                time.sleep(0.1)
            return False
        try:
            before = seen("ATTITUDE", t0, 30)
            if not before:
                return self.report("restart", "fail", time.monotonic() - t0,
                                   "no ATTITUDE before the restart (%d frames)" % len(heard))
            rc = subprocess.run(self.restart_cmd, shell=True, timeout=120).returncode
            restarted = time.monotonic()
            if rc != 0:
                return self.report("restart", "fail", restarted - t0, "the restart command failed (%d)" % rc)
            hb = seen("HEARTBEAT", restarted, 90)
            att = hb and seen("ATTITUDE", restarted, 30)
            alive = p.poll() is None
            gap = [t for t, n in heard if t >= restarted and n == "ATTITUDE"]
            back = (gap[0] - restarted) if gap else None
        finally:
            p.terminate()
            try:
                _, err = p.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                _, err = p.communicate()
        # The system id parameter by the names of ArduPilot 4.7 (and the simulator), earlier
        # ArduPilot, PX4.
        table = getattr(self, "table", None) or {}
        names = [n for n in ("MAV_SYSID", "SYSID_THISMAV", "MAV_SYS_ID") if not table or n in table]
        for name in names:
            rc2, out2, err2, _ = self.mavstack("param", "get", self.conn, name, "--json", timeout=60)
            if rc2 == 0:
                break
        ok = alive and hb and att and rc2 == 0
        self.report("restart", "pass" if ok else "fail", time.monotonic() - t0,
                    "listen %s; HEARTBEAT after restart %s, ATTITUDE %s%s; param get %s%s" % (
                        "kept running" if alive else "exited: %s" % err.strip()[-200:],
                        "yes" if hb else "no", "yes" if att else "no",
                        " (%.1f s after the restart command)" % back if back is not None else "",
                        "ok" if rc2 == 0 else "failed", "" if rc2 == 0 else ": " + err2.strip()[-200:]))


def pymavlink_tlog_counts(path):
    """{(sysid, compid, type): count} of a tlog as pymavlink reads it, and its BAD_DATA count."""
    import mavstack_dialect
    extra = mavstack_dialect.load()
    m = mavutil.mavlink_connection(path, dialect="ardupilotmega", robust_parsing=True)
    counts, bad = {}, 0
    while True:
        msg = m.recv_msg()
        if msg is None:
            break
        t = msg.get_type()
        if t == "BAD_DATA":
            bad += 1
            continue
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if t.startswith("UNKNOWN_"):
            # pymavlink's unknown message has no header of its own: the frame's bytes have it
            buf = bytes(msg.get_msgbuf())
            sysid, compid = (buf[5], buf[6]) if buf[:1] == b"\xfd" else (buf[3], buf[4])
            # A message of the definitions mavstack adds to common (the events protocol) by its
            # name there, as pymavlink's generator names it from the same XML.
            known = extra.mavlink_map.get(int(t[len("UNKNOWN_"):]))
            if known is not None:
                t = known.msgname
        k = (sysid, compid, t)
        counts[k] = counts.get(k, 0) + 1
    m.close()
    return counts, bad


class Peripheral:
    """A MAVLink 1 only component (pymavlink's v1.0 codec, so never MAVLink 2): a HEARTBEAT once
    a second to a router's `udpin` link; counts what it receives by framing, and the vehicle's
    HEARTBEATs (MAVLink 1, checksum checked by the v1.0 decoder)."""

    def __init__(self, port, sysid=1, compid=PERIPHERAL_COMPID):
        from pymavlink.dialects.v10 import ardupilotmega as v1
        self.v1 = v1
        self.mav = v1.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.sysid, self.compid = sysid, compid
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.dest = ("127.0.0.1", port)
        self.sent = 0
        self.got = {"mavlink1": 0, "mavlink2": 0, "vehicle_heartbeats_v1": 0, "undecodable": 0}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        nxt = 0.0
        while not self._stop.is_set():
            if time.monotonic() >= nxt:
                hb = self.mav.heartbeat_encode(self.v1.MAV_TYPE_ONBOARD_CONTROLLER,
                                               self.v1.MAV_AUTOPILOT_INVALID, 0, 0,
                                               self.v1.MAV_STATE_ACTIVE)
                try:
                    self.sock.sendto(hb.pack(self.mav), self.dest)
                    self.sent += 1
                except OSError:
                    pass
                nxt = time.monotonic() + 1.0
            try:
                data = self.sock.recv(65535)
            except (socket.timeout, OSError):
                continue
            i = 0
            while i < len(data):
                if data[i] == 0xFE and i + 8 <= len(data):
                    n = 8 + data[i + 1]
                    frame = data[i:i + n]
                    self.got["mavlink1"] += 1
                    if frame[5] == 0 and frame[4] == 1:
                        try:
                            self.mav.decode(bytearray(frame))
                            self.got["vehicle_heartbeats_v1"] += 1
                        except Exception:
                            self.got["undecodable"] += 1
                    i += n
                elif data[i] == 0xFD and i + 12 <= len(data):
                    self.got["mavlink2"] += 1
                    i += 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
                else:
                    i += 1

    def stop(self):
        self._stop.set()
        self._thread.join(2)
        self.sock.close()


class _NoVehicle:
    """What gcs_mavproxy.MavProxy asks of its vehicle when the vehicle is not ours."""

    def check_alive(self):
        pass

    def log(self, tail=0):
        return "(the vehicle is not a process of this script)"


async def mavsdk_native_params(url, timeout=120.0):
    """MAVSDK's native binding: connect, get_all_params; returns (count, seconds)."""
    from gcs_mavsdk import Native
    api = Native()
    await asyncio.wait_for(api.connect(url), 30)
    try:
        t = time.monotonic()
        allp = await asyncio.wait_for(api.param.get_all_params(), timeout)
        n = len(list(allp.int_params)) + len(list(allp.float_params)) + len(list(getattr(allp, "custom_params", [])))
        return n, time.monotonic() - t
    finally:
        try:
            await asyncio.wait_for(api.close(), 5)
        except Exception:
            pass


def free_udp():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def router_session(binary, conn, work, direct):
    """One router between CONN and the peers; returns (detail, ok)."""
    from gcs_common import Router, link_stats
    from gcs_mavproxy import MavProxy, fetch_all
    ports = {k: free_udp() for k in ("mavstack", "mavproxy", "mavsdk", "legacy")}
    links = ["%s?name=vehicle" % conn,
             "udpout:127.0.0.1:%d?name=mavstack" % ports["mavstack"],
             "udpout:127.0.0.1:%d?name=mavproxy" % ports["mavproxy"],
             "udpout:127.0.0.1:%d?name=mavsdk" % ports["mavsdk"],
             "udpin:127.0.0.1:%d?version=1&name=legacy" % ports["legacy"]]
    router = Router(binary, links, work)
    periph = Peripheral(ports["legacy"])
    mp = None
    parts, ok = [], True
    try:
        mp = MavProxy("udpin:127.0.0.1:%d" % ports["mavproxy"], work, _NoVehicle(), router=router)
        mp.expect(r"Detected vehicle \d+:\d+", 30, "MAVProxy connect through the router")
        # mavstack param list on its own link
        t = time.monotonic()
        p = subprocess.run([binary, "param", "list", "udpin:127.0.0.1:%d" % ports["mavstack"], "--json"],
                           capture_output=True, text=True, timeout=180)
        n = sum(1 for line in p.stdout.splitlines() if line.startswith("{"))
        ok &= p.returncode == 0 and n == direct
        parts.append("mavstack param list %d in %.1f s%s" % (n, time.monotonic() - t,
                                                             "" if p.returncode == 0 else " (exit %d: %s)" % (
                                                                 p.returncode, p.stderr.strip()[-200:])))
        # MAVProxy: a full fetch, then wp list
        n, secs = fetch_all(mp, 120, "MAVProxy param fetch through the router")
        ok &= n == direct
        parts.append("MAVProxy param fetch %d in %.1f s" % (n, secs))
        mp.cmd("wp list")
        _, m = mp.expect(r"Requesting (\d+) waypoints", 20, "MAVProxy wp list: MISSION_COUNT")
        count = int(m.group(1))
        if count > 0:  # an empty mission (PX4's at start) ends at MISSION_COUNT 0
            _, m = mp.expect(r"Saved (\d+) waypoints to", 60, "MAVProxy wp list: the items")
            ok &= int(m.group(1)) == count
        parts.append("MAVProxy wp list %d/%d items" % (int(m.group(1)), count))
        # MAVSDK (native binding)
        try:
            n, secs = asyncio.run(mavsdk_native_params("udpin://127.0.0.1:%d" % ports["mavsdk"]))
            ok &= n == direct
            parts.append("MAVSDK get_all_params %d in %.1f s" % (n, secs))
        except Exception as e:
            ok = False
            parts.append("MAVSDK: %s %s" % (type(e).__name__, str(e)[-200:]))
        # the MAVLink 1 peripheral, both ways
        time.sleep(1.5)
        seen = sum(1 for m in _tlog_msgs(mp.tlog()) if m.get_type() == "HEARTBEAT"
                   and m.get_srcComponent() == PERIPHERAL_COMPID)
        g = periph.got
        p_ok = seen > 0 and g["vehicle_heartbeats_v1"] > 0 and g["mavlink2"] == 0
        ok &= p_ok
        parts.append("peripheral (MAVLink 1): sent %d HEARTBEATs, MAVProxy saw %d; received %d vehicle "
                     "HEARTBEATs in MAVLink 1, %d frames in MAVLink 1, %d in MAVLink 2" % (
                         periph.sent, seen, g["vehicle_heartbeats_v1"], g["mavlink1"], g["mavlink2"]))
    finally:
        if mp is not None:
            mp.close()
        periph.stop()
        try:
            stats = router.stop()
        except Exception as e:
            router.kill()
            stats, ok = None, False
            parts.append("router stop: %s" % str(e)[-200:])
    if stats:
        veh = link_stats(stats, "vehicle")
        to2 = sum(int((e.get("conversions") or {}).get("to_mavlink2") or 0) for e in veh)
        leg = link_stats(stats, "legacy")
        to1 = sum(int((e.get("conversions") or {}).get("to_mavlink1") or 0) for e in leg)
        drops = {}
        for e in stats.get("links", []):
            for k, v in (e.get("dropped") or {}).items():
                if v:
                    drops["%s.%s" % (e.get("name"), k)] = drops.get("%s.%s" % (e.get("name"), k), 0) + v
        ok &= to2 > 0
        parts.append("router: vehicle link got %d frames converted to MAVLink 2, legacy link %d to "
                     "MAVLink 1; drops %s" % (to2, to1, drops or "none"))
    return "; ".join(parts), ok


def _tlog_msgs(path):
    m = mavutil.mavlink_connection(path, dialect="ardupilotmega", robust_parsing=True)
    while True:
        msg = m.recv_msg()
        if msg is None:
            break
        yield msg
    m.close()



def rtcm3_frame(number, total):
    """An RTCM3 frame of `total` bytes whose message number is `number` (CRC-24Q here)."""
    payload = bytes([number >> 4, (number & 15) << 4]) + bytes((i * 37 + number) % 256 for i in range(total - 8))
    head = bytes([0xD3, (len(payload) >> 8) & 3, len(payload) & 0xFF]) + payload
    crc = 0
    for b in head:
        crc ^= b << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= 0x1864CFB
    return head + (crc & 0xFFFFFF).to_bytes(3, "big")


def flight_steps(runner):
    """The `flight` example's steps, each a scenario row: rates, then the flight."""
    if not runner.flight_bin:
        return runner.report("flight", "n/a", 0.0, "no --flight binary")
    rc, out, err, s = run([runner.flight_bin, runner.conn], timeout=600)
    steps = []
    for line in out.splitlines():
        try:
            steps.append(json.loads(line))
        except ValueError:
            pass
    by = {x["step"]: x for x in steps}
    r = by.get("rates")
    if r is None:
        return runner.report("rates", "fail", s, "no rates step (exit %s): %s" % (rc, err.strip()[-300:]))
    runner.report("rates", "pass" if r["ok"] else "fail", 5.0,
                  "ATTITUDE %.1f Hz (asked 10, by %s), GLOBAL_POSITION_INT %.1f Hz (asked 5, by %s)" % (
                      r["attitude_hz"], r["attitude_by"], r["global_position_int_hz"], r["global_position_int_by"]))
    names = ["mission", "armed", "takeoff", "mission_flown", "landed_disarmed"]
    done = [n for n in names if n in by]
    ok = rc == 0 and all(by[n]["ok"] for n in done) and "landed_disarmed" in by
    detail = ", ".join("%s %s at %.0f s" % (n, "ok" if by[n]["ok"] else "FAILED", by[n]["t_s"]) for n in done)
    if "armed" in by and by["armed"].get("refusals"):
        detail += "; arming refused first: %s" % by["armed"]["refusals"][:3]
    if "mission_flown" in by:
        detail += "; MISSION_ITEM_REACHED %s" % by["mission_flown"]["reached"]
    if not ok:
        detail += "; exit %s %s" % (rc, err.strip()[-200:])
    runner.report("flight", "pass" if ok else "fail", s, detail)


def decode_value(value, ptype, bytewise):
    """A PARAM_VALUE's float as the parameter's value: integers C-cast (ArduPilot) or their bytes
    in the float (PX4, MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)."""
    import struct
    ints = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}
    if ptype not in ints:
        return value
    if not bytewise:
        return int(value)
    raw = struct.pack("<f", value)
    fmt = ints[ptype]
    return struct.unpack(fmt, raw[:struct.calcsize(fmt)])[0]


def compare_plans(sent, got):
    """Differences between two plans (WPL rows, item 0 home) under the autopilots' conventions:
    home's position is the vehicle's; GLOBAL and GLOBAL_INT (3 and 6, 0 and 5) are the same
    frame; the frame of an item without a position (RTL, 20) does not count; `current`
    does not count."""
    same_frame = {"5": "0", "6": "3", "11": "10"}
    if len(sent) != len(got):
        return ["%d items sent, %d read back" % (len(sent), len(got))]
    diffs = []
    for i, (a, b) in enumerate(zip(sent, got)):
        if i == 0:
            continue
        if int(a[3]) != int(b[3]):
            diffs.append("item %d: command %s vs %s" % (i, a[3], b[3]))
            continue
        if a[3] != "20" and same_frame.get(a[2], a[2]) != same_frame.get(b[2], b[2]):
            diffs.append("item %d: frame %s vs %s" % (i, a[2], b[2]))
        for k, what in ((8, "lat"), (9, "lon"), (10, "alt")):
            if a[3] == "20":
                continue
            if abs(float(a[k]) - float(b[k])) > (1e-6 if k < 10 else 1e-3):
                diffs.append("item %d: %s %s vs %s" % (i, what, a[k], b[k]))
    return diffs


SCENARIOS = ["probe", "conform", "params", "param_set", "mission", "arm_refused", "signing", "router", "record",
             "aio", "pymavlink_scripts", "signed_router", "modes", "takeoff_goto", "offboard", "manual",
             "shell", "rtk", "gimbal", "camera", "flight", "restart"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--name", required=True)
    ap.add_argument("--conn", required=True)
    ap.add_argument("--out")
    ap.add_argument("--only")
    ap.add_argument("--flight", help="the flight example's binary")
    ap.add_argument("--restart", help="a shell command that kills the vehicle and starts it again")
    ap.add_argument("--signed-link", help="a second link of the vehicle's (ArduPilot's SERIAL1), for signed_router")
    ap.add_argument("--camera-restart", help="a shell command that starts the vehicle again with a camera (the "
                    "simulator's --camera), for the camera scenario; --restart undoes it")
    a = ap.parse_args()
    r = Runner(a.mavstack, a.name, a.conn, a.flight, a.restart, a.signed_link, a.camera_restart)
    chosen = a.only.split(",") if a.only else SCENARIOS
    # arm_refused needs the vehicle fresh: it goes first when asked for.
    order = (["arm_refused"] if "arm_refused" in chosen else []) + [s for s in chosen if s != "arm_refused"]
    for s in order:
        if s == "flight":
            flight_steps(r)
        elif s in ("gimbal", "camera"):
            getattr(flight_payload, s)(r)
        else:
            getattr(r, s)()
    if a.out:
        with open(a.out, "w") as f:
            json.dump(r.results, f, indent=1)
    return 1 if any(x["status"] == "fail" for x in r.results) else 0


if __name__ == "__main__":
    sys.exit(main())
