#!/usr/bin/env python3
"""Times beside MAVProxy and MAVSDK against one running vehicle (ArduPilot SITL, PX4 SITL or
`mavstack vehicle`), on a clean UDP link and through tests-interop/lossy_relay.py.

usage: flight_bench.py --mavstack BIN --name NAME --port P [--out FILE.json] [--md FILE.md]
                       [--timeout S] [--links clean,lossy] [--tools mavstack,mavproxy,mavsdk]
       flight_bench.py --combine FILE.json... [--md FILE.md]

The vehicle sends UDP to 127.0.0.1:P (PX4: 14550; ArduPilot: a serial port as
`--serial1 udpclient:127.0.0.1:P`; the simulator: `mavstack vehicle udpout:127.0.0.1:P`).
Clean: each tool listens on P itself (`udpin`). Lossy: LossyRelay listens on P and forwards to
the tool's port, dropping 20 % of the datagrams each way (seeded) and holding the rest 100 ms
each way (loss=0.2, delay=0.1).

Per tool and link, three times, each from the tool's start (connection included):
  params    the whole parameter table. mavstack: `param list CONN --json` (default `--via auto`:
            MAVFTP where offered) and `--via list` (PARAM_REQUEST_LIST), the process's wall
            time. MAVProxy 1.8.75 (`set param_ftp 0`, its fetch at connect): from its launch to
            `Received N parameters` (the time from `Detected vehicle` in brackets). MAVSDK
            4.1.0 native: from `Mavsdk()` to get_all_params' answer.
  mission   a plan of home + 100 waypoints uploaded. mavstack: `mission upload CONN FILE --json`
            (wall time); MAVProxy: `wp load FILE` to MISSION_ACK ACCEPTED (connected already);
            MAVSDK: upload_mission of the 100 waypoints (connected already).
  attitude  from the start to the first ATTITUDE, the tool asking for 10 Hz: mavstack `listen
            CONN --rate ATTITUDE:10`; MAVProxy `--streamrate=10` (REQUEST_DATA_STREAM), the
            first ATTITUDE in its telemetry log; MAVSDK set_rate_attitude_euler(10), the first
            attitude_euler.
A step that does not finish within --timeout (default 60 s; attitude 30 s) is 'timed out'.
Prints one Markdown table; --out writes the rows as JSON, --md the table.
"""
import argparse
import asyncio
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from lossy_relay import LossyRelay  # noqa: E402

HOMES = {"px4": (47.397742, 8.545594, 488.0), "default": (-35.363261, 149.165230, 584.0)}
N_ITEMS = 100


def free_udp():
    import socket
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def write_plan(path, home):
    lines = ["QGC WPL 110", "0\t1\t0\t16\t0\t0\t0\t0\t%.7f\t%.7f\t%.2f\t1" % home]
    for i in range(1, N_ITEMS + 1):
        row, col = divmod(i - 1, 20)
        lines.append("%d\t0\t3\t16\t0\t0\t0\t0\t%.7f\t%.7f\t%d\t1" % (
            i, home[0] + 0.0001 * row, home[1] + 0.0001 * col, 20 + i % 5))
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


class Bench:
    def __init__(self, args):
        self.a = args
        self.rows = []
        self.expected_params = None
        self.work = tempfile.mkdtemp(prefix="flight-bench-")
        self.home = HOMES["px4"] if args.name.startswith("px4") else HOMES["default"]
        self.plan = os.path.join(self.work, "plan.waypoints")
        write_plan(self.plan, self.home)

    def complete(self, n):
        """A whole table: at least the count of the first fetch (mavstack's, clean). PX4's table
        grows while its modules start (904 at first, 907 a minute later)."""
        return self.expected_params is None or n >= self.expected_params

    def row(self, link, tool, metric, status, seconds=None, detail=""):
        r = {"target": self.a.name, "link": link, "tool": tool, "metric": metric, "status": status,
             "seconds": None if seconds is None else round(seconds, 2), "detail": detail}
        self.rows.append(r)
        print("%s %s %s %s: %s %s %s" % (self.a.name, link, tool, metric, status,
                                        "" if seconds is None else "%.2f s" % seconds, detail), flush=True)

    # ----- mavstack (the CLI) -------------------------------------------------------------------

    def mavstack(self, link, conn):
        T = self.a.timeout
        # attitude: `listen --rate ATTITUDE:10`, the first ATTITUDE line
        t0 = time.monotonic()
        p = subprocess.Popen([self.a.mavstack, "listen", conn, "--rate", "ATTITUDE:10"],
                             stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        got = None
        try:
            import selectors
            sel = selectors.DefaultSelector()
            sel.register(p.stdout, selectors.EVENT_READ)
            while time.monotonic() - t0 < self.a.attitude_timeout and got is None:
                if not sel.select(0.5):
                    continue
                line = p.stdout.readline()
                if not line:
                    break
                if '"name":"ATTITUDE"' in line:
                    got = time.monotonic() - t0
        finally:
            p.kill()
            p.wait()
        if got is None:
            self.row(link, "mavstack", "attitude", "timed out", None, "> %d s" % self.a.attitude_timeout)
        else:
            self.row(link, "mavstack", "attitude", "ok", got)
        time.sleep(0.5)
        # params: --via auto (MAVFTP where offered), then --via list
        for tool, via in (("mavstack", "auto"), ("mavstack --via list", "list")):
            t0 = time.monotonic()
            try:
                r = subprocess.run([self.a.mavstack, "param", "list", conn, "--json", "--via", via],
                                   capture_output=True, text=True, timeout=T)
            except subprocess.TimeoutExpired:
                self.row(link, tool, "params", "timed out", None, "> %d s" % T)
                continue
            s = time.monotonic() - t0
            n = sum(1 for line in r.stdout.splitlines() if line.startswith("{"))
            if r.returncode != 0:
                self.row(link, tool, "params", "failed", s, "exit %d: %s" % (r.returncode, r.stderr.strip()[-200:]))
                continue
            if self.expected_params is None:
                self.expected_params = n
            self.row(link, tool, "params", "ok" if self.complete(n) else "incomplete", s,
                     "%d parameters; %s" % (n, r.stderr.strip().splitlines()[-1] if r.stderr.strip() else ""))
            time.sleep(0.5)
        # mission
        t0 = time.monotonic()
        try:
            r = subprocess.run([self.a.mavstack, "mission", "upload", conn, self.plan, "--json"],
                               capture_output=True, text=True, timeout=T)
            s = time.monotonic() - t0
            if r.returncode == 0:
                j = json.loads(r.stdout)
                self.row(link, "mavstack", "mission", "ok", s,
                         "%s items; upload %.2f s after connect" % (j.get("uploaded", "?"),
                                                                     j.get("seconds", float("nan"))))
            else:
                self.row(link, "mavstack", "mission", "failed", s,
                         "exit %d: %s" % (r.returncode, r.stderr.strip()[-200:]))
        except subprocess.TimeoutExpired:
            self.row(link, "mavstack", "mission", "timed out", None, "> %d s" % T)

    # ----- MAVProxy -----------------------------------------------------------------------------

    def mavproxy(self, link, port):
        import pexpect
        from flight_stacks import _NoVehicle, _tlog_msgs
        from gcs_mavproxy import MavProxy
        T = self.a.timeout
        work = tempfile.mkdtemp(prefix="mavproxy-", dir=self.work)
        wall0, t0 = time.time(), time.monotonic()
        mp = MavProxy("udpin:127.0.0.1:%d" % port, work, _NoVehicle(), extra=("--streamrate=10",))
        try:
            try:
                mp.p.expect(r"Detected vehicle \d+:\d+", timeout=T)
                t_det = time.monotonic() - t0
            except pexpect.TIMEOUT:
                for m in ("params", "mission", "attitude"):
                    self.row(link, "MAVProxy", m, "timed out", None, "no vehicle detected in %d s" % T)
                return
            try:
                mp.p.expect(r"Received (\d+) parameters\r?\n", timeout=T)
                s = time.monotonic() - t0
                n = int(mp.p.match.group(1))
                self.row(link, "MAVProxy", "params", "ok" if self.complete(n) else "incomplete", s,
                         "%d parameters (%.2f s after Detected vehicle at %.2f s)" % (n, s - t_det, t_det))
            except pexpect.TIMEOUT:
                self.row(link, "MAVProxy", "params", "timed out", None, "> %d s" % T)
            # attitude: the first ATTITUDE in the telemetry log
            first = None
            for m in _tlog_msgs(mp.tlog()):
                if m.get_type() == "ATTITUDE":
                    first = m._timestamp - wall0
                    break
            if first is None:
                self.row(link, "MAVProxy", "attitude", "timed out", None, "no ATTITUDE in its log")
            else:
                self.row(link, "MAVProxy", "attitude", "ok", first, "detected vehicle at %.2f s" % t_det)
            # mission: wp load to MISSION_ACK
            mp.cmd("wp load %s" % self.plan)
            t1 = time.monotonic()
            try:
                mp.p.expect(r"Got MISSION_ACK: (?:TYPE_)?MISSION: (\w+)", timeout=T)
                res = mp.p.match.group(1)
                self.row(link, "MAVProxy", "mission", "ok" if res == "ACCEPTED" else "failed",
                         time.monotonic() - t1, "%d items, MISSION_ACK %s" % (N_ITEMS + 1, res))
            except pexpect.TIMEOUT:
                self.row(link, "MAVProxy", "mission", "timed out", None,
                         "> %d s (MAVProxy 1.8.75 never resends MISSION_COUNT nor its last item)" % T)
        finally:
            mp.close()

    # ----- MAVSDK (native binding) --------------------------------------------------------------

    async def _mavsdk(self, link, url):
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
        from mavsdk.asyncio.plugins.mission import MissionAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
        from mavsdk.plugins.mission import MissionItem, MissionPlan
        T = self.a.timeout
        t0 = time.monotonic()
        sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        try:
            await sdk.add_any_connection(url)
            system = await sdk.first_autopilot(timeout_s=float(self.a.attitude_timeout))
            if system is None:
                for m in ("attitude", "params", "mission"):
                    self.row(link, "MAVSDK", m, "timed out", None, "no autopilot in %d s" % self.a.attitude_timeout)
                return
            t_conn = time.monotonic() - t0
            tel, param, mission = TelemetryAsync(system), ParamAsync(system), MissionAsync(system)
            try:
                await asyncio.wait_for(tel.set_rate_attitude_euler(10.0), 10)
                rate = "rate set"
            except Exception as e:
                rate = "set_rate_attitude_euler: %s" % type(e).__name__

            async def first_att():
                async for _ in tel.subscribe_attitude_euler():
                    return time.monotonic() - t0
            try:
                s = await asyncio.wait_for(first_att(), self.a.attitude_timeout)
                self.row(link, "MAVSDK", "attitude", "ok", s, "connected at %.2f s, %s" % (t_conn, rate))
            except asyncio.TimeoutError:
                self.row(link, "MAVSDK", "attitude", "timed out", None, "> %d s" % self.a.attitude_timeout)
            try:
                allp = await asyncio.wait_for(param.get_all_params(), T)
                s = time.monotonic() - t0
                n = len(list(allp.int_params)) + len(list(allp.float_params)) + \
                    len(list(getattr(allp, "custom_params", [])))
                self.row(link, "MAVSDK", "params", "ok" if self.complete(n) else "incomplete", s,
                         "%d parameters" % n)
            except asyncio.TimeoutError:
                self.row(link, "MAVSDK", "params", "timed out", None, "> %d s" % T)
            except Exception as e:
                self.row(link, "MAVSDK", "params", "failed", None, "%s: %s" % (type(e).__name__, str(e)[-200:]))
            items = []
            for i in range(1, N_ITEMS + 1):
                row, col = divmod(i - 1, 20)
                items.append(MissionItem(
                    latitude_deg=round(self.home[0] + 0.0001 * row, 7),
                    longitude_deg=round(self.home[1] + 0.0001 * col, 7),
                    relative_altitude_m=float(20 + i % 5), speed_m_s=float("nan"), is_fly_through=True,
                    gimbal_pitch_deg=float("nan"), gimbal_yaw_deg=float("nan"),
                    camera_action=MissionItem.CameraAction.NONE, loiter_time_s=float("nan"),
                    camera_photo_interval_s=float("nan"), acceptance_radius_m=float("nan"),
                    yaw_deg=float("nan"), camera_photo_distance_m=float("nan"),
                    vehicle_action=MissionItem.VehicleAction.NONE))
            t1 = time.monotonic()
            try:
                await asyncio.wait_for(mission.upload_mission(MissionPlan(items)), T)
                self.row(link, "MAVSDK", "mission", "ok", time.monotonic() - t1, "%d items" % N_ITEMS)
            except asyncio.TimeoutError:
                self.row(link, "MAVSDK", "mission", "timed out", None, "> %d s" % T)
            except Exception as e:
                self.row(link, "MAVSDK", "mission", "failed", time.monotonic() - t1,
                         "%s: %s" % (type(e).__name__, str(e)[-200:]))
        finally:
            try:
                await asyncio.wait_for(sdk.destroy(), 5)
            except Exception:
                pass

    def mavsdk(self, link, port):
        try:
            asyncio.run(self._mavsdk(link, "udpin://127.0.0.1:%d" % port))
        except Exception as e:
            self.row(link, "MAVSDK", "all", "failed", None, "%s: %s" % (type(e).__name__, str(e)[-200:]))

    # ----- the runs -----------------------------------------------------------------------------

    def run(self):
        tools = self.a.tools.split(",")
        for link in self.a.links.split(","):
            relay = None
            if link == "lossy":
                port = free_udp()
                relay = LossyRelay(("127.0.0.1", self.a.port), ("127.0.0.1", port), loss=0.2, seed=1,
                                   delay=0.1).start()
            else:
                port = self.a.port
            try:
                for tool in tools:
                    if tool == "mavstack":
                        self.mavstack(link, "udpin:127.0.0.1:%d" % port)
                    elif tool == "mavproxy":
                        self.mavproxy(link, port)
                    elif tool == "mavsdk":
                        self.mavsdk(link, port)
                    last = [r for r in self.rows if r["metric"] == "mission"][-1:]
                    if last and last[0]["status"] != "ok":
                        # an upload left unfinished on the vehicle's side would answer the next
                        # tool's MISSION_COUNT (ArduPilot: OPERATION_CANCELLED): let it time out
                        time.sleep(10.0)
                    time.sleep(1.0)
            finally:
                if relay is not None:
                    relay.stop()
                    print("%s lossy relay: %s" % (self.a.name, json.dumps(relay.stats)), flush=True)
            time.sleep(0.5)


def table(rows):
    """One Markdown table: a row per target, link and tool; a column per metric."""
    keys, cells = [], {}
    for r in rows:
        k = (r["target"], r["link"], r["tool"])
        if k not in keys:
            keys.append(k)
        if r["status"] == "ok":
            c = "%.2f" % r["seconds"]
            if r["tool"] == "MAVProxy" and r["metric"] == "params" and "after Detected" in r["detail"]:
                c += " (%s)" % r["detail"].split("(")[1].split(" after")[0]
        elif r["status"] == "incomplete":
            c = "%.2f, %s" % (r["seconds"], r["detail"].split(";")[0])
        else:
            c = r["status"]
        cells[k + (r["metric"],)] = c
    out = ["| target | link | tool | full parameter table (s) | mission upload, 100 items (s) | first ATTITUDE (s) |",
           "| --- | --- | --- | --- | --- | --- |"]
    for k in keys:
        out.append("| %s | %s | %s | %s |" % (k[0], k[1], k[2], " | ".join(
            cells.get(k + (m,), "—") for m in ("params", "mission", "attitude"))))
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mavstack")
    ap.add_argument("--name")
    ap.add_argument("--port", type=int, help="the UDP port the vehicle sends to")
    ap.add_argument("--out")
    ap.add_argument("--md")
    ap.add_argument("--timeout", type=int, default=60)
    ap.add_argument("--attitude-timeout", type=int, default=30)
    ap.add_argument("--links", default="clean,lossy")
    ap.add_argument("--tools", default="mavstack,mavproxy,mavsdk")
    ap.add_argument("--combine", nargs="+", help="JSON files of earlier runs: one table of them all")
    a = ap.parse_args()
    if a.combine:
        rows = []
        for path in a.combine:
            rows += json.load(open(path))
    else:
        if not (a.mavstack and a.name and a.port):
            ap.error("--mavstack, --name and --port are needed (or --combine)")
        b = Bench(a)
        b.run()
        rows = b.rows
        if a.out:
            with open(a.out, "w") as f:
                json.dump(rows, f, indent=1)
    md = table(rows)
    print(md)
    if a.md:
        with open(a.md, "w") as f:
            f.write(md + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
