"""mavstack's web API side by side with mavlink2rest 1.0.2 on the same simulated vehicle.

    python tests-interop/mavlink2rest_compare.py --mavstack target/debug/mavstack \
        --mavlink2rest /path/to/mavlink2rest [--fixtures crates/mavstack/tests/fixtures/mavlink2rest]

mavlink2rest is built from its source outside this repository (see
docs/contracts/web-api.md, "Checked against mavlink2rest"); this script only runs it. The
layout: `mavstack vehicle` sends to `mavstack router`, which serves the API (`--http`) and
sends every frame on to mavlink2rest (a UDP client of the router's), and logs every frame it
accepts (`--log`).
Both APIs then see the same frames, header and sequence included. Compared:

- every frame both WebSocket streams carry (no filter): the message objects, equal as JSON
  values, for every message type the vehicle sends; the vehicle is asked for more types
  (AUTOPILOT_VERSION, PARAM_VALUE, MISSION_COUNT, arming and its STATUSTEXT, COMMAND_ACK) by
  COMMAND_LONGs and requests POSTed to each API;
- the templates (`/helper/mavlink?name=`) of every ardupilotmega message pymavlink knows;
- the WebSocket filter (`?filter=^(ATTITUDE|VFR_HUD)$`): the names each stream carries;
- a POSTed COMMAND_LONG: the vehicle's COMMAND_ACK shows in each API's `/mavlink`;
- a bad body and an unknown message: the status code and that nothing was sent.

With `--fixtures DIR` it writes mavlink2rest's answers for CI (which compares against them
without mavlink2rest): `messages-AUTOPILOT.json` (per message type, the frame as the router
logged it and mavlink2rest's object of it), `templates.jsonl`, `session-AUTOPILOT.json`. Exit 1 on any
difference; prints a summary.
"""

import argparse
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from xml.etree import ElementTree

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ws_min import WebSocket  # noqa: E402


# Where our definitions (definitions/) and rust-mavlink 0.16.2's, which mavlink2rest 1.0.2 is
# built with, say different things: fields one has and the other has not are reported, not
# failed; these fields have another type in one of them (an enum or bitmask attribute added,
# entries renamed). With rust-mavlink's own XML the mapping writes all of them as 1.0.2 does
# (crates/mavstack/tests/web_json.rs, templates_equal_mavlink2rest_on_its_own_definitions).
DEFINITION_DIFFERENCES = {
    ("REQUEST_DATA_STREAM", "req_stream_id"), ("DATA_STREAM", "stream_id"),
    ("LANDING_TARGET", "position_valid"), ("CAMERA_IMAGE_CAPTURED", "capture_result"),
    ("CAMERA_TRACKING_IMAGE_STATUS", "tracking_status"),
    ("CAMERA_TRACKING_GEO_STATUS", "tracking_status"), ("AIS_VESSEL", "navigational_status"),
}


def differences(ours, theirs):
    """(fields whose values differ, fields only one side has) of two message objects."""
    if not isinstance(ours, dict) or not isinstance(theirs, dict):
        return ([] if ours == theirs else ["(whole)"]), []
    name = theirs.get("type")
    values = [k for k in set(ours) & set(theirs)
              if ours[k] != theirs[k] and (name, k) not in DEFINITION_DIFFERENCES]
    return sorted(values), sorted(set(ours) ^ set(theirs))


def free_port(kind=socket.SOCK_DGRAM):
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def http(method, url, body=None):
    """(status, text) of one request."""
    data = body.encode() if isinstance(body, str) else body
    req = urllib.request.Request(url, data=data, method=method)
    if data is not None:
        req.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode()


def wait_http(url, deadline):
    while time.time() < deadline:
        try:
            urllib.request.urlopen(url, timeout=1).read()
            return
        except OSError:
            time.sleep(0.2)
    raise SystemExit(f"no answer from {url}")


class Stream(threading.Thread):
    """Reads one WebSocket into `frames`: (sysid, compid, seq, name) → (message, text)."""

    def __init__(self, port, path):
        super().__init__(daemon=True)
        self.ws = WebSocket("127.0.0.1", port, path)
        self.frames = {}
        self.names = set()
        self.stop = False

    def run(self):
        try:
            while not self.stop:
                text = self.ws.recv_text()
                obj = json.loads(text)
                h, m = obj["header"], obj["message"]
                key = (h["system_id"], h["component_id"], h["sequence"], m["type"])
                self.frames.setdefault(key, (m, text))
                self.names.add(m["type"])
        except (ConnectionError, OSError, ValueError):
            pass

    def close(self):
        self.stop = True
        self.ws.close()


def command_long(command, params, seq, compid=190):
    p = (list(params) + [0.0] * 7)[:7]
    return json.dumps({
        "header": {"system_id": 255, "component_id": compid, "sequence": seq},
        "message": {
            "type": "COMMAND_LONG", "target_system": 1, "target_component": 1,
            "command": {"type": command}, "confirmation": 0,
            **{f"param{i + 1}": v for i, v in enumerate(p)},
        },
    })


def requests(seq):
    """What is posted to each API to make the vehicle send more message types."""
    return [
        command_long("MAV_CMD_REQUEST_MESSAGE", [148], seq),  # AUTOPILOT_VERSION
        json.dumps({"header": {"system_id": 255, "component_id": 190, "sequence": seq + 1},
                    "message": {"type": "PARAM_REQUEST_READ", "target_system": 1,
                                "target_component": 1, "param_id": "",
                                "param_index": 0}}),
        json.dumps({"header": {"system_id": 255, "component_id": 190, "sequence": seq + 2},
                    "message": {"type": "MISSION_REQUEST_LIST", "target_system": 1,
                                "target_component": 1,
                                "mission_type": {"type": "MAV_MISSION_TYPE_MISSION"}}}),
        command_long("MAV_CMD_COMPONENT_ARM_DISARM", [1], seq + 3),
        command_long("MAV_CMD_COMPONENT_ARM_DISARM", [0], seq + 4),
        command_long("MAV_CMD_REQUEST_MESSAGE", [242], seq + 5),  # HOME_POSITION
        command_long("MAV_CMD_REQUEST_MESSAGE", [435], seq + 6),  # AVAILABLE_MODES
        command_long("MAV_CMD_REQUEST_MESSAGE", [436], seq + 7),  # CURRENT_MODE
        command_long("MAV_CMD_REQUEST_MESSAGE", [300], seq + 8),  # PROTOCOL_VERSION
        command_long("MAV_CMD_REQUEST_MESSAGE", [2], seq + 9),  # SYSTEM_TIME
        command_long("MAV_CMD_GET_MESSAGE_INTERVAL", [33], seq + 10),  # MESSAGE_INTERVAL
        json.dumps({"header": {"system_id": 255, "component_id": 190, "sequence": 0},
                    "message": {"type": "LOG_REQUEST_LIST", "target_system": 1,
                                "target_component": 1, "start": 0, "end": 65535}}),
        json.dumps({"header": {"system_id": 255, "component_id": 190, "sequence": 0},
                    "message": {"type": "TIMESYNC", "tc1": 0, "ts1": 12345}}),
    ]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--mavlink2rest", required=True)
    ap.add_argument("--fixtures")
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--autopilot", default="ardupilot", help="the vehicle's: ardupilot or px4")
    args = ap.parse_args()
    from pymavlink.dialects.v20 import ardupilotmega as apm

    tmp = tempfile.mkdtemp(prefix="m2r-")
    p_in, p_out = free_port(), free_port()
    h_ours, h_theirs = free_port(socket.SOCK_STREAM), free_port(socket.SOCK_STREAM)
    procs = []
    failures = []

    def check(ok, what):
        if not ok:
            failures.append(what)
            print("FAIL", what)

    try:
        procs.append(subprocess.Popen(
            # rust-mavlink 0.16's udpin never learns where to send: mavlink2rest is the client.
            [args.mavlink2rest, "-c", f"udpout:127.0.0.1:{p_out}", "-s", f"127.0.0.1:{h_theirs}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        procs.append(subprocess.Popen(
            [args.mavstack, "router", f"udpin:127.0.0.1:{p_in}", f"udpin:127.0.0.1:{p_out}",
             "--http", f"127.0.0.1:{h_ours}", "--log", tmp],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        procs.append(subprocess.Popen(
            [args.mavstack, "vehicle", f"udpout:127.0.0.1:{p_in}", "--autopilot", args.autopilot],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        ours = f"http://127.0.0.1:{h_ours}"
        theirs = f"http://127.0.0.1:{h_theirs}"
        deadline = time.time() + 30
        wait_http(ours + "/info", deadline)
        wait_http(theirs + "/info", deadline)
        # Both have heard the vehicle.
        while time.time() < deadline:
            a = http("GET", ours + "/mavlink/vehicles/1/components/1/messages/HEARTBEAT")
            b = http("GET", theirs + "/mavlink/vehicles/1/components/1/messages/HEARTBEAT")
            if a[0] == 200 and b[0] == 200 and b[1] != "None":
                break
            time.sleep(0.3)

        # Every frame of both streams, while each API is asked for more message types.
        s_ours = Stream(h_ours, "/ws/mavlink")
        s_theirs = Stream(h_theirs, "/ws/mavlink")
        s_ours.start()
        s_theirs.start()
        posts = []
        for i, body in enumerate(requests(10)):
            posts.append(("mavlink2rest", json.loads(body)["message"]["type"], http("POST", theirs + "/mavlink", body)[0]))
            time.sleep(0.4)
        for i, body in enumerate(requests(20)):
            posts.append(("mavstack", json.loads(body)["message"]["type"], http("POST", ours + "/mavlink", body)[0]))
            time.sleep(0.4)
        time.sleep(args.seconds)
        s_ours.close()
        s_theirs.close()
        check(all(code == 200 for _, _, code in posts), f"POSTs answered {posts}")
        common = set(s_ours.frames) & set(s_theirs.frames)
        diffs = []
        definition_only = {}
        for key in sorted(common):
            values, fields = differences(s_ours.frames[key][0], s_theirs.frames[key][0])
            if values:
                diffs.append((key, s_ours.frames[key][0], s_theirs.frames[key][0]))
            if fields:
                definition_only[key[3]] = fields
        names = sorted({k[3] for k in common})
        print(f"frames compared: {len(common)} ({len(names)} message types: {', '.join(names)})")
        print(f"only in mavlink2rest's stream: {len(set(s_theirs.frames) - common)}, "
              f"only in ours: {len(set(s_ours.frames) - common)}")
        for key, a, b in diffs[:10]:
            print("DIFF", key, "\n  ours:  ", json.dumps(a, sort_keys=True), "\n  theirs:", json.dumps(b, sort_keys=True))
        print("fields only one definition has:", definition_only)
        check(not diffs, f"{len(diffs)} frames differ")
        check(s_theirs.names - s_ours.names <= set(), f"types only mavlink2rest saw: {s_theirs.names - s_ours.names}")

        # A POSTed COMMAND_LONG is answered: the COMMAND_ACK is in each API's store.
        for who, base in (("mavstack", ours), ("mavlink2rest", theirs)):
            code, text = http("GET", base + "/mavlink/vehicles/1/components/1/messages/COMMAND_ACK")
            check(code == 200 and text != "None", f"{who}: no COMMAND_ACK after the POSTs")
        code_o, text_o = http("GET", ours + "/mavlink/vehicles/1/components/1/messages/AUTOPILOT_VERSION")
        code_t, text_t = http("GET", theirs + "/mavlink/vehicles/1/components/1/messages/AUTOPILOT_VERSION")
        check(code_o == 200 and code_t == 200
              and differences(json.loads(text_o)["message"], json.loads(text_t)["message"])[0] == [],
              "AUTOPILOT_VERSION differs")

        # The filter.
        f_ours = Stream(h_ours, "/ws/mavlink?filter=%5E(ATTITUDE%7CVFR_HUD)%24")
        f_theirs = Stream(h_theirs, "/ws/mavlink?filter=%5E(ATTITUDE%7CVFR_HUD)%24")
        f_ours.start()
        f_theirs.start()
        time.sleep(3)
        f_ours.close()
        f_theirs.close()
        print("filter ^(ATTITUDE|VFR_HUD)$:", sorted(f_ours.names), "mavlink2rest:", sorted(f_theirs.names))
        check(f_ours.names == f_theirs.names == {"ATTITUDE", "VFR_HUD"}, "filtered streams differ")

        # Templates of every message.
        templates = []
        template_diffs = []
        for msg_id in sorted(apm.mavlink_map):
            name = apm.mavlink_map[msg_id].msgname
            a = http("GET", ours + f"/helper/mavlink?name={name}")
            b = http("GET", theirs + f"/helper/mavlink?name={name}")
            ta = json.loads(a[1]) if a[0] == 200 else a[1]
            tb = json.loads(b[1]) if b[0] == 200 else b[1]
            templates.append({"name": name, "status": b[0], "body": tb})
            if (a[0], b[0]) == (200, 404):
                definition_only[name] = "a message only our definitions have"
            elif a[0] != b[0]:
                template_diffs.append((name, a[0], b[0]))
            elif a[0] == 200:
                values, fields = differences(ta["message"], tb["message"])
                if values or ta["header"] != tb["header"]:
                    template_diffs.append((name, values))
                if fields:
                    definition_only[name] = fields
        print(f"templates compared: {len(templates)}, differing: {len(template_diffs)}")
        for d in template_diffs[:10]:
            print("TEMPLATE DIFF", d)
        check(not template_diffs, f"{len(template_diffs)} templates differ")

        # Refusals: nothing is sent.
        before = json.loads(http("GET", ours + "/api/status")[1])["web"]["sent"]
        bad = {}
        for label, body in (("bad JSON", "{not json"),
                            ("unknown message", json.dumps({"header": {"system_id": 255, "component_id": 0, "sequence": 0},
                                                            "message": {"type": "NO_SUCH_MESSAGE"}}))):
            bad[label] = {"mavstack": http("POST", ours + "/mavlink", body), "mavlink2rest": http("POST", theirs + "/mavlink", body)}
            print(f"{label}: mavstack {bad[label]['mavstack']}, mavlink2rest {bad[label]['mavlink2rest']}")
            check(400 <= bad[label]["mavstack"][0] < 500, f"{label}: not a 4xx")
        after = json.loads(http("GET", ours + "/api/status")[1])["web"]["sent"]
        check(after == before, "a refused POST was sent")
        info = json.loads(http("GET", theirs + "/info")[1])
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()

    if args.fixtures:
        # The frames as the router logged them (a tlog: 8-byte time, then the frame), by
        # (sysid, compid, seq, name).
        names = {m.msgname: i for i, m in apm.mavlink_map.items()}
        # Ids pymavlink's module may not have (AVAILABLE_MODES, ...), from our definitions.
        root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "definitions")
        for path, _, files in os.walk(root):
            for xml in files:
                if xml.endswith(".xml"):
                    for m in ElementTree.parse(os.path.join(path, xml)).iter("message"):
                        names.setdefault(m.get("name"), int(m.get("id")))
        by_id = {}
        for name in os.listdir(tmp):
            data = open(os.path.join(tmp, name), "rb").read()
            at = 0
            while at + 8 + 8 <= len(data):
                frame_at = at + 8
                magic, n = data[frame_at], data[frame_at + 1]
                if magic == 0xFD:
                    size = 12 + n + (13 if data[frame_at + 2] & 1 else 0)
                    seq, sysid, compid = data[frame_at + 4:frame_at + 7]
                    msg_id = int.from_bytes(data[frame_at + 7:frame_at + 10], "little")
                elif magic == 0xFE:
                    size = 8 + n
                    seq, sysid, compid, msg_id = data[frame_at + 2:frame_at + 6]
                else:
                    break
                by_id.setdefault((sysid, compid, seq, msg_id), data[frame_at:frame_at + size])
                at = frame_at + size
        logged = {}
        for key in s_theirs.frames:
            msg_id = names.get(key[3])
            if msg_id is not None and (key[0], key[1], key[2], msg_id) in by_id:
                logged[key] = by_id[(key[0], key[1], key[2], msg_id)]
        out = []
        per_type = {}
        for key in sorted(s_theirs.frames):
            name = key[3]
            if key in logged and per_type.get(name, 0) < 2:
                per_type[name] = per_type.get(name, 0) + 1
                message = s_theirs.frames[key][0]
                header = {"component_id": key[1], "sequence": key[2], "system_id": key[0]}
                out.append({"frame": bytes(logged[key]).hex(), "mavlink2rest": {"header": header, "message": message}})
        os.makedirs(args.fixtures, exist_ok=True)
        with open(os.path.join(args.fixtures, f"messages-{args.autopilot}.json"), "w") as f:
            json.dump(out, f, indent=1, sort_keys=True)
            f.write("\n")
        with open(os.path.join(args.fixtures, "templates.jsonl"), "w") as f:
            for t in templates:
                f.write(json.dumps(t, sort_keys=True) + "\n")
        session = {"mavlink2rest_info": info["service"]["version"] + " " + info["service"]["sha"],
                   "filter": {"regex": "^(ATTITUDE|VFR_HUD)$", "mavlink2rest": sorted(f_theirs.names)},
                   "refused": {k: {"status": v["mavlink2rest"][0], "body": v["mavlink2rest"][1][:200]}
                               for k, v in bad.items()},
                   "message_types": sorted(per_type)}
        with open(os.path.join(args.fixtures, f"session-{args.autopilot}.json"), "w") as f:
            json.dump(session, f, indent=1, sort_keys=True)
            f.write("\n")
        print(f"fixtures: {len(out)} frames of {len(per_type)} types, {len(templates)} templates in {args.fixtures}")
    shutil.rmtree(tmp, ignore_errors=True)
    print(f"{len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
