#!/usr/bin/env python3
"""First contact: from process start to the target known (and a first answer), for the
`mavstack` CLI, MAVSDK 4.1.0 (native binding), pymavlink 2.4.50 and MAVProxy 1.8.75, against
`mavstack vehicle --autopilot ardupilot` listening on UDP (its HEARTBEAT once a second, as
the flight stacks send it), the ground station connecting with `udpout`.

    first_contact.py --mavstack target/release/mavstack [--runs 10] [--md FILE]

Each run is a new process (the way a user runs a command), timed from its start (the
interpreter's start for the Python tools) to:
  mavstack   `mavstack param get udpout:... ANGLE_MAX --json` printing the value: the
             CLI asks for the HEARTBEAT of component 1 of any system at connect
             (REQUEST_MESSAGE, broadcast), then reads one parameter
  mavsdk     `Mavsdk.add_any_connection("udpout://...")` and `first_autopilot()` returning
  pymavlink  `mavlink_connection("udpout:...")`, a HEARTBEAT sent (the vehicle learns the
             address), `wait_heartbeat()` returning
  mavproxy   `mavproxy.py --master=udpout:... --non-interactive` printing its
             "Detected vehicle" line (then stopped)
Reported: median and spread of the runs per tool, and each tool's median beside mavstack's.
No tool waits for anything but the vehicle; the vehicle's 1 Hz HEARTBEAT makes a tool that
waits for it take 0.5 s more on average. The Python tools' times include the interpreter's
start and their imports (about 0.2 s for MAVSDK and pymavlink on this kind of machine), as a
user's script pays them.
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from scenario import free_port  # noqa: E402

PY = sys.executable

MAVSDK = r"""
import asyncio, sys
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
async def main():
    m = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await m.add_any_connection(sys.argv[1])
    await m.first_autopilot(timeout_s=20)
    print("found")
    m.destroy()
asyncio.run(main())
"""

PYMAVLINK = r"""
import sys
from pymavlink import mavutil
c = mavutil.mavlink_connection(sys.argv[1], source_system=255, source_component=190)
c.mav.heartbeat_send(6, 8, 0, 0, 0)
hb = c.wait_heartbeat(timeout=20)
print("found" if hb else "none")
"""


def timed(argv, want, timeout=30):
    t = time.monotonic()
    p = subprocess.run(argv, capture_output=True, text=True, timeout=timeout)
    took = time.monotonic() - t
    if p.returncode != 0 or want not in p.stdout:
        raise SystemExit("first_contact: %s failed (exit %d): %s %s" % (
            argv[0], p.returncode, p.stdout[-300:], p.stderr[-300:]))
    return took


def until_line(argv, want, cwd, timeout=60):
    """Seconds from starting `argv` (in `cwd`) to a line of its output holding `want`; then
    stops it."""
    t = time.monotonic()
    p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         cwd=cwd)
    try:
        for line in p.stdout:
            if want in line:
                return time.monotonic() - t
            if time.monotonic() - t > timeout:
                break
        raise SystemExit("first_contact: %s never printed %r" % (argv[0], want))
    finally:
        p.kill()
        p.wait()


def until_line(argv, want, cwd, timeout=60):
    """Seconds from starting `argv` (in `cwd`) to a line of its output holding `want`; then
    stops it."""
    t = time.monotonic()
    p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         cwd=cwd)
    try:
        for line in p.stdout:
            if want in line:
                return time.monotonic() - t
            if time.monotonic() - t > timeout:
                break
        raise SystemExit("first_contact: %s never printed %r" % (argv[0], want))
    finally:
        p.kill()
        p.wait()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--tools", default="mavstack,mavsdk,pymavlink,mavproxy")
    ap.add_argument("--md")
    a = ap.parse_args()
    port = free_port()
    vehicle = subprocess.Popen([a.mavstack, "vehicle", "udpin:127.0.0.1:%d" % port,
                                "--autopilot", "ardupilot"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    bindir = os.path.dirname(PY)
    # MAVProxy writes its tlog and state where it runs.
    work = tempfile.mkdtemp(prefix="first-contact-")
    runs = {}
    try:
        time.sleep(1.0)
        for _ in range(a.runs):
            for tool in a.tools.split(","):
                if tool == "mavstack":
                    t = timed([a.mavstack, "param", "get", "udpout:127.0.0.1:%d" % port,
                               "ANGLE_MAX", "--json"], "ANGLE_MAX")
                elif tool == "mavsdk":
                    t = timed([PY, "-c", MAVSDK, "udpout://127.0.0.1:%d" % port], "found")
                elif tool == "pymavlink":
                    t = timed([PY, "-c", PYMAVLINK, "udpout:127.0.0.1:%d" % port], "found")
                elif tool == "mavproxy":
                    t = until_line([os.path.join(bindir, "mavproxy.py"),
                                    "--master=udpout:127.0.0.1:%d" % port, "--non-interactive"],
                                   "Detected vehicle", work)
                else:
                    raise SystemExit("first_contact: unknown tool %s" % tool)
                runs.setdefault(tool, []).append(t)
                # Each tool's process has left: let the vehicle drop nothing of the next.
                time.sleep(0.2)
    finally:
        vehicle.terminate()
        vehicle.wait(timeout=10)
    ours = statistics.median(runs["mavstack"]) if "mavstack" in runs else None
    lines = ["| tool | median (s) | min–max (s) | runs | beside mavstack |",
             "| --- | --- | --- | --- | --- |"]
    for tool, ts in runs.items():
        med = statistics.median(ts)
        ratio = "—" if tool == "mavstack" or not ours else "%.1f× longer" % (med / ours)
        lines.append("| %s | %.3f | %.3f–%.3f | %d | %s |" % (tool, med, min(ts), max(ts),
                                                              len(ts), ratio))
    table = "\n".join(lines)
    print(table)
    if a.md:
        with open(a.md, "w") as f:
            f.write(table + "\n")


if __name__ == "__main__":
    main()
