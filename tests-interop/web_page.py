#!/usr/bin/env python3
"""The status page of `mavstack vehicle --http --http-token` in Debian's headless chromium.

Usage: web_page.py --mavstack BIN [--artifacts DIR] [--linger S]

The vehicle is flown through the web API alone (POST /mavlink with the token: GUIDED, arm,
take off to 10 m, reposition 60 m away), the way a web client would. Chromium (through
chromedriver's WebDriver API, log_tools.Driver) opens `/?token=...` and the vehicle's card
must show what an operator glances at, each against what the API itself says at that
moment: the mode by name (GUIDED), armed, battery volts and percent, GPS fix and satellites,
height above home (rising), ground speed, heading, the STATUSTEXT lines of the flight
("Arming motors", "Takeoff to 10.0 m") with their severity, and the track as an SVG polyline
with at least 5 points; no resource is fetched from another origin. A screenshot is kept
as DIR/vehicle-page.png. Exit 0 with "web_page: ... ok", or 1 with FAIL lines.
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from log_tools import Driver  # noqa: E402
from scenario import check, fail, failures  # noqa: E402

TOKEN = "page-token-123"

READ_CARD = """
const card = document.querySelector('.vehicle[data-sysid="1"]');
if (!card) return null;
const get = cls => { const e = card.querySelector('dd.' + cls); return e ? e.textContent : null; };
const line = card.querySelector('svg.track polyline');
return {
  title: card.querySelector('h3').textContent,
  mode: get('mode'), armed: get('arming'), battery: get('battery'), gps: get('gps'),
  height: get('height'), speed: get('speed'), heading: get('heading'), link: get('loss'),
  texts: [...card.querySelectorAll('.texts li')].map(li => li.textContent),
  track: line ? line.getAttribute('points').trim().split(/\\s+/).length : 0,
  foreign: performance.getEntriesByType('resource').map(r => r.name)
    .filter(n => !n.startsWith(location.origin)),
};
"""


def call(base, path, body=None, token=TOKEN):
    req = urllib.request.Request(base + path, data=body and body.encode(), method="POST" if body else "GET")
    if token:
        req.add_header("Authorization", "Bearer " + token)
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


def command(name, *params):
    p = (list(params) + [0.0] * 7)[:7]
    return json.dumps({"header": {"system_id": 255, "component_id": 190, "sequence": 0},
                       "message": {"type": "COMMAND_LONG", "target_system": 1, "target_component": 1,
                                   "command": {"type": name}, "confirmation": 0,
                                   **{"param%d" % (i + 1): v for i, v in enumerate(p)}}})


def number(text):
    return float(text.split()[0])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--artifacts")
    ap.add_argument("--linger", type=float, default=0.0, help="fly this much longer before the screenshot")
    a = ap.parse_args()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        udp = s.getsockname()[1]
    base = "http://127.0.0.1:%d" % port
    vehicle = subprocess.Popen([a.mavstack, "vehicle", "udpout:127.0.0.1:%d" % udp, "--http",
                                "127.0.0.1:%d" % port, "--http-token", TOKEN],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    driver = None
    card = None
    with tempfile.TemporaryDirectory() as tmp:
        try:
            deadline = time.monotonic() + 20
            while True:
                try:
                    if call(base, "/mavlink/vehicles/1/components/1/messages/GLOBAL_POSITION_INT")[0] == 200:
                        break
                except OSError:
                    pass  # not listening yet
                if time.monotonic() > deadline:
                    raise RuntimeError("the vehicle's API did not answer")
                time.sleep(0.2)
            check(call(base, "/", token=None)[0] == 401, "the page was served without the token")
            for body in (command("MAV_CMD_DO_SET_MODE", 1, 4), command("MAV_CMD_COMPONENT_ARM_DISARM", 1),
                         command("MAV_CMD_NAV_TAKEOFF", 0, 0, 0, 0, 0, 0, 10)):
                code, text = call(base, "/mavlink", body)
                check(code == 200, "POST %s: %s %s" % (body, code, text))
                time.sleep(0.5)
            time.sleep(4)
            # DO_REPOSITION's altitude is above mean sea level: home's plus 15 m.
            home = json.loads(call(base, "/mavlink/vehicles/1/components/1/messages/HOME_POSITION")[1])["message"]
            target = (home["latitude"] / 1e7 + 0.0004, home["longitude"] / 1e7 + 0.0005, home["altitude"] / 1000 + 15)
            code, text = call(base, "/mavlink", command("MAV_CMD_DO_REPOSITION", -1, 0, 0, 0, *target))
            check(code == 200, "reposition: %s %s" % (code, text))
            driver = Driver(tmp)
            driver.go(base + "/?token=" + TOKEN)
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                card = driver.script(READ_CARD)
                if card and card["mode"] == "GUIDED" and card["track"] >= 5 and card["gps"] != "–" \
                        and number(card["height"]) > 3:
                    break
                time.sleep(0.5)
            time.sleep(a.linger)
            if a.artifacts:
                # A fresh checkout has no artifacts directory until a test makes it.
                os.makedirs(a.artifacts, exist_ok=True)
                driver.screenshot(os.path.join(a.artifacts, "vehicle-page.png"))
            if not card:
                raise RuntimeError("the page shows no vehicle 1/1")
            api = lambda name: json.loads(call(base, "/mavlink/vehicles/1/components/1/messages/%s" % name)[1])["message"]  # noqa: E731
            sys_status, gps = api("SYS_STATUS"), api("GPS_RAW_INT")
            check("quadrotor" in card["title"] and "ArduPilot" in card["title"], "title %r" % card["title"])
            check(card["mode"] == "GUIDED", "mode %r" % card["mode"])
            check(card["armed"] == "ARMED", "armed %r" % card["armed"])
            check(abs(number(card["battery"]) - sys_status["voltage_battery"] / 1000) < 0.5 and "%" in card["battery"],
                  "battery %r, SYS_STATUS %s mV" % (card["battery"], sys_status["voltage_battery"]))
            check(card["gps"].startswith("3D fix") and str(gps["satellites_visible"]) in card["gps"],
                  "GPS %r, GPS_RAW_INT %s" % (card["gps"], gps["fix_type"]))
            check(number(card["height"]) > 3, "height above home %r" % card["height"])
            check(card["speed"].endswith("m/s") and card["heading"].endswith("°"), "speed %r heading %r" % (card["speed"], card["heading"]))
            texts = " | ".join(card["texts"])
            check("Arming motors" in texts and "Takeoff to 10.0 m" in texts and "info" in texts, "STATUSTEXT lines %r" % texts)
            check(card["track"] >= 5, "track of %d points" % card["track"])
            check(card["foreign"] == [], "resources from elsewhere: %s" % card["foreign"])
        except (OSError, RuntimeError, ValueError, KeyError, TypeError) as e:
            fail("web page: %s: %s" % (type(e).__name__, e))
        finally:
            if driver:
                driver.close()
            vehicle.terminate()
            vehicle.wait(10)
    if failures:
        print("web_page: %d failures" % len(failures))
        sys.exit(1)
    print("web_page: mode %s, %s, battery %s, GPS %s, height %s, %d track points, %d STATUSTEXT lines ok"
          % (card["mode"], card["armed"], card["battery"], card["gps"], card["height"], card["track"], len(card["texts"])))


if __name__ == "__main__":
    main()
