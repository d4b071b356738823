#!/usr/bin/env python3
"""MAVProxy 1.8.75 (the real ground station, from PyPI) against `mavstack vehicle` on loopback UDP.

    gcs_mavproxy.py [--mavstack BIN] [--keep DIR] [--via-router]
    gcs_mavproxy.py --bench N_PARAMS N_ITEMS [--loss 0.2] [--seed 1] [--mavstack BIN]

The vehicle (`BIN vehicle udpout:127.0.0.1:PORT --secure --params FILE`, BIN from --mavstack or
$MAVSTACK_BIN) sends to MAVProxy listening on `--master=udpin:127.0.0.1:PORT`. MAVProxy runs
headless in a pseudo-terminal (pexpect) with `set param_ftp 0` (the parameter protocol, not
MAVFTP) and the modules signing, wp, param, arm, mode, cmdlong; its own console lines are what
is checked, plus its telemetry log (every frame it received, signature bytes included):

 1. connect: "Detected vehicle 1:1";
 2. param fetch: "Received N parameters" where N is the vehicle's param_count, `param status`
    "Have N/N params", `param save` writes N lines holding every name/value of the --params file;
 3. param set + read back: a REAL32 and an INT32 parameter set, then fetched one by one
    (PARAM_REQUEST_READ) and printed with the new value; `param set` of the same names shows
    them in a second full fetch too;
 4. wp list and wp save on the empty vehicle: one item, home (ArduPilot keeps home as item 0);
 5. wp load of a generated QGC WPL 110 file (MISSION_COUNT, MISSION_REQUEST(_INT), MISSION_ITEM_INT,
    MISSION_ACK ACCEPTED), then wp save (a second download) compared item by item;
 6. arm throttle: COMMAND_ACK ACCEPTED, "ARMED", and an armed HEARTBEAT in the log; disarm;
 7. signing setup KEY (SETUP_SIGNING, accepted by a `--secure` vehicle), then `set allow_unsigned 0`
    and a full param fetch again (only signed frames reach MAVProxy now), and the log shows the
    vehicle's frames signed from then on with MAVProxy's key (checked with pymavlink's signing).

--via-router: the same session with `mavstack router` in the middle: the vehicle sends to the
router's `udpin:...?name=vehicle&trusted=true` link, the router's `udpout:...?name=gcs` link
sends to MAVProxy's `--master=udpin:`; checks 1-6 as above. SETUP_SIGNING cannot work through
a router link without a key (the router removes signatures there, by design), so 7 becomes: a
second MAVProxy on the router's signed link `udpout:...?name=gcs_signed&key=K` (K = the
passphrase's SHA-256, as MAVProxy derives it): `signing key` (local), `set allow_unsigned 0`, a
full fetch, and every vehicle frame in its log signed with K (by the router, from the trusted
vehicle link). Then a MAVLink 1 hop: a `--mavlink1-only` vehicle on a `version=1` router link,
MAVProxy on a plain one: fetch, set + read back, wp load/save compared, arm/disarm, through
the router's conversion (its stats show the versions and conversions). The router is stopped
with SIGTERM and must exit 0; its stats (per link frames, conversions, drops) are in the JSON.

--via-broker: the same session (checks 1-6) across an MQTT broker (mosquitto, started on a free
port): the vehicle sends to a vehicle-side `mavstack router` (`udpin:...?name=vehicle` and
`mqtt://...?fleet=interop&vid=truck-1`), a ground-side `mavstack router`
(`mqtt://...?fleet=interop&vid=*` and `udpout:...?name=gcs`) serves MAVProxy; both routers
must exit 0 on SIGTERM and their stats show frames both ways on the vehicle and gcs links.

Prints one JSON line with timings on success, exits 1 with the reason (and MAVProxy's and the
vehicle's last output) on any failure.

--bench: a vehicle with N_PARAMS extra parameters (a generated --params file) and MAVProxy,
directly and through tests-interop/lossy_relay.py dropping --loss of the datagrams each way
(seeded): time to fetch every parameter, upload N_ITEMS mission items (retried when MAVProxy
gives up: it never resends MISSION_COUNT) and download them again; JSON with both runs.
"""

import argparse
import hashlib
import json
import os
import re
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import mqtt_broker  # noqa: E402

from gcs_common import (  # noqa: E402
    Failure,
    Router,
    Timer,
    check_router_carried,
    link_dropped,
    link_stats,
    link_total,
    Vehicle,
    compare_missions,
    fail,
    free_udp_port,
    mavstack_bin,
    read_qgc_wpl,
    run_main,
    survey_mission,
    via_router,
    write_params_file,
    write_qgc_wpl,
)

try:
    import pexpect
except ImportError as e:  # never skip: a missing client is a failure
    print(f"gcs_mavproxy: FAILED: pexpect is not installed ({e}); run scripts/setup-peers.sh",
          file=sys.stderr)
    sys.exit(1)

MODULES = "signing,wp,param,arm,mode,cmdlong"
PASSPHRASE = "mavstack-interop"
FLEET = "interop"  # --via-broker: the fleet; the vehicle is truck-1
# defaults of the ArduPilot flavour that the fetch must show
ARDUPILOT_PARAMS = {"MAV_SYSID": 1, "ARMING_CHECK": 1, "WPNAV_SPEED": 500.0, "RTL_ALT": 1500}
# The shortest wait for a line from MAVProxy, whatever a call asks for. Every wait is for
# something that comes within a second on an idle machine; a busy one (CI building beside the
# test, on 2 cores) can hold MAVProxy, the vehicle, the routers or the broker off the CPU for
# seconds. A deadline only bounds how long a broken run takes to fail, so none is short.
PATIENCE = 60


def mavproxy_exe():
    exe = os.path.join(os.path.dirname(sys.executable), "mavproxy.py")
    if not os.path.exists(exe):
        fail(f"MAVProxy is not installed next to {sys.executable} (no {exe}); "
             "run scripts/setup-peers.sh")
    return exe


class MavProxy:
    """MAVProxy in a pty: send console commands, wait for console lines."""

    def __init__(self, master, workdir, vehicle, extra=(), router=None):
        self.workdir = workdir
        self.vehicle = vehicle
        self.router = router
        self.out_path = os.path.join(workdir, "mavproxy.out")
        self.out = open(self.out_path, "w")
        self.state = os.path.join(workdir, "state")
        os.makedirs(self.state, exist_ok=True)
        env = dict(os.environ, HOME=workdir, TERM="dumb", PYTHONUNBUFFERED="1")
        args = [
            f"--master={master}",
            f"--state-basedir={self.state}",
            "--aircraft=gcs",
            f"--default-modules={MODULES}",
            "--cmd=set param_ftp 0",
            # the telemetry log is checked after MAVProxy is killed: unflushed, its tail was lost
            "--cmd=set flushlogs 1",
            *extra,
        ]
        self.p = pexpect.spawn(sys.executable, [mavproxy_exe(), *args], cwd=workdir, env=env,
                               encoding="utf-8", codec_errors="replace", timeout=30,
                               maxread=65536, searchwindowsize=None)
        self.p.logfile_read = self.out

    def tail(self, n=3000):
        self.out.flush()
        with open(self.out_path, errors="replace") as f:
            return f.read()[-n:]

    def drain(self):
        """Forget output so far, so that a new command's answer cannot match stale lines."""
        while True:
            try:
                self.p.read_nonblocking(65536, timeout=0.05)
            except pexpect.TIMEOUT:
                return
            except pexpect.EOF:
                fail(f"MAVProxy exited:\n{self.tail()}")

    def cmd(self, line):
        self.drain()
        self.p.sendline(line)

    def expect(self, patterns, timeout, what):
        """Waits for the first of the regex patterns, `timeout` seconds but never less than
        PATIENCE; returns (index, match)."""
        if isinstance(patterns, str):
            patterns = [patterns]
        timeout = max(timeout, PATIENCE)
        try:
            i = self.p.expect(patterns, timeout=timeout)
        except pexpect.TIMEOUT:
            self.vehicle.check_alive()
            if self.router is not None:
                self.router.check_alive()
            fail(f"{what}: MAVProxy did not print /{'/ or /'.join(patterns)}/ within {timeout} s\n"
                 f"--- MAVProxy output (tail) ---\n{self.tail()}\n"
                 f"--- vehicle log (tail) ---\n{self.vehicle.log(1500)}"
                 + (f"\n{self.router.describe()}" if self.router is not None else ""))
        except pexpect.EOF:
            fail(f"{what}: MAVProxy exited\n{self.tail()}")
        return i, self.p.match

    def tlog(self):
        for dirpath, _, files in os.walk(self.state):
            for f in files:
                if f.endswith(".tlog") and not f.endswith(".raw"):
                    return os.path.join(dirpath, f)
        fail(f"MAVProxy wrote no telemetry log under {self.state}")

    def close(self):
        if self.p.isalive():
            self.p.terminate(force=True)
        self.out.close()


def fetch_all(mp, timeout, what):
    mp.cmd("param fetch")
    t = time.monotonic()
    _, m = mp.expect(r"Received (\d+) parameters\r?\n", timeout, what)
    return int(m.group(1)), round(time.monotonic() - t, 3)


def param_read_back(mp, name, want, what):
    mp.cmd(f"param fetch {name}")
    # Not anchored at a line's start: MAVProxy's input thread writes its prompt ("MANUAL> ")
    # without a newline whenever it is ready for the next line, and a value that arrives after
    # it is printed on the prompt's line.
    pat = rf"(?<![A-Za-z0-9_]){name} = (-?[0-9.e+-]+)\r?\n"
    _, m = mp.expect(pat, 15, what)
    got = float(m.group(1))
    if abs(got - want) > 1e-6 * max(1.0, abs(want)):
        fail(f"{what}: {name} read back as {got}, expected {want}")
    return got


def read_param_file(path):
    out = {}
    with open(path) as f:
        for line in f:
            a = line.split()
            if len(a) >= 2 and not a[0].startswith("#"):
                out[a[0]] = float(a[1])
    return out


def upload(mp, path, n, timeout, attempts=1, last_request=None):
    """`wp load`; returns (seconds, attempts used, how it ended). With attempts == 1 (a clean
    link) MAVProxy must print the vehicle's MISSION_ACK ACCEPTED. Before it, MISSION_ACKs
    INVALID_SEQUENCE may come, as from ArduPilot: MAVProxy answers every MISSION_REQUEST, so
    when it answered one later than the vehicle's re-request (ArduPilot's and the simulator's
    ArduPilot flavour's come a second after the request), the vehicle gets the item twice and
    refuses the copy with INVALID_SEQUENCE, keeping the upload open; they are counted in how it
    ended. Any other result ends the upload and fails. On a lossy link MAVProxy 1.8.75 cannot
    finish on its own every time: it never resends MISSION_COUNT, and once it has sent the last
    item it ignores the vehicle's re-requests for it (loading_waypoints is cleared), so a lost
    last item, or a lost final MISSION_ACK, ends the transfer on one side only. There the
    upload counts as done when MAVProxy prints the ACK or the vehicle's log says it stored the
    N items, and is started again when the vehicle abandoned it (its log, or its MISSION_ACK
    OPERATION_CANCELLED), when no MISSION_REQUEST from the vehicle got through for 5 s
    (`last_request()`, the relay's tap: a lost MISSION_COUNT), or after `timeout`."""
    t = time.monotonic()
    ack = r"Got MISSION_ACK: (?:TYPE_)?MISSION: (\w+)"
    stored = f"plan stored: {n} items"
    for attempt in range(1, attempts + 1):
        log = mp.vehicle.log(10**9)
        abandoned, stores = log.count("upload abandoned"), log.count(stored)
        mp.cmd(f"wp load {path}")
        mp.expect(rf"Loaded {n} waypoints from", 10, "wp load: reading the file")
        if attempts == 1:
            copies = 0
            while True:
                _, m = mp.expect(ack, timeout, f"wp load: MISSION_ACK for {n} items")
                if m.group(1) != "INVALID_SEQUENCE":
                    break
                copies += 1
            if m.group(1) != "ACCEPTED":
                fail(f"wp load: the vehicle answered MISSION_ACK {m.group(1)} to {n} items")
            ended = f"ack after {copies} copies refused (INVALID_SEQUENCE)" if copies else "ack"
            return round(time.monotonic() - t, 3), attempt, ended
        t_try = time.monotonic()
        while time.monotonic() - t_try < timeout:
            try:
                mp.p.expect(ack, timeout=0.5)
                if mp.p.match.group(1) == "INVALID_SEQUENCE":
                    continue
                if mp.p.match.group(1) == "OPERATION_CANCELLED":
                    break  # the vehicle gave the upload up (8 s without an item, as ArduPilot)
                if mp.p.match.group(1) != "ACCEPTED":
                    fail(f"wp load: the vehicle answered MISSION_ACK {mp.p.match.group(1)}")
                return round(time.monotonic() - t, 3), attempt, "ack"
            except pexpect.TIMEOUT:
                log = mp.vehicle.log(10**9)
                if log.count(stored) > stores:
                    return round(time.monotonic() - t, 3), attempt, "vehicle stored (ACK lost)"
                if log.count("upload abandoned") > abandoned:
                    break
                quiet_since = max(t_try, last_request() if last_request else t_try)
                # the vehicle asks again every second (as ArduPilot): 5 s without a request
                # getting through is a lost MISSION_COUNT, not five lost requests in a row
                if last_request and time.monotonic() - quiet_since > 5.0:
                    break
    fail(f"wp load: {n} items not stored after {attempts} attempts\n"
         f"--- MAVProxy (tail) ---\n{mp.tail()}\n--- vehicle (tail) ---\n{mp.vehicle.log(1500)}")


def download(mp, path, n, timeout, attempts=1):
    """`wp save PATH` (MISSION_REQUEST_LIST, then MAVProxy requests the items and re-requests
    missing ones itself); returns (seconds, attempts). MAVProxy never resends
    MISSION_REQUEST_LIST, so with attempts > 1 it is sent again when no MISSION_COUNT came."""
    t = time.monotonic()
    for attempt in range(1, attempts + 1):
        if os.path.exists(path):
            os.remove(path)
        mp.cmd(f"wp save {path}")
        if attempt < attempts:
            try:
                mp.p.expect(r"Requesting (\d+) waypoints", timeout=3)
            except pexpect.TIMEOUT:
                continue
        else:
            mp.expect(r"Requesting (\d+) waypoints", 3, "wp save: MISSION_COUNT")
        if int(mp.p.match.group(1)) != n:
            fail(f"wp save: the vehicle announced {mp.p.match.group(1)} items, expected {n}")
        _, m = mp.expect(rf"Saved (\d+) waypoints to {re.escape(path)}", timeout,
                         f"wp save: download of {n} items")
        if int(m.group(1)) != n:
            fail(f"wp save: downloaded {m.group(1)} items, expected {n}")
        return round(time.monotonic() - t, 3), attempt
    fail(f"wp save: no MISSION_COUNT after {attempts} MISSION_REQUEST_LISTs\n{mp.tail()}")


def tlog_frames(path):
    """(timestamp_us, raw frame bytes) of every frame in a MAVProxy tlog, with pymavlink's parse."""
    from pymavlink import mavutil

    mlog = mavutil.mavlink_connection(path, dialect="common", robust_parsing=True)
    while True:
        m = mlog.recv_msg()
        if m is None:
            return
        yield m


def check_signed_tail(tlog, setup_wall, key):
    """Every vehicle frame logged after setup_wall (plus a margin) is MAVLink 2 with a valid
    signature under key; returns (signed, unsigned-before) counts."""
    signed, after_unsigned, before = 0, [], 0
    for m in tlog_frames(tlog):
        if m.get_srcSystem() != 1 or m.get_type() == "BAD_DATA":
            continue
        buf = bytes(m.get_msgbuf())
        ts = getattr(m, "_timestamp", 0)
        is_signed = len(buf) > 12 and buf[0] == 0xFD and (buf[2] & 1)
        if ts < setup_wall:
            before += 1
            continue
        if ts < setup_wall + 1.0:
            continue  # frames in flight when the key arrived
        if not is_signed:
            after_unsigned.append(m.get_type())
            continue
        # signature = first 6 bytes of sha256(key + frame-without-signature-bytes... + link+ts)
        sig = buf[-13:]
        digest = hashlib.sha256(key + buf[:-6]).digest()[:6]
        if digest != sig[7:]:
            fail(f"signing: a {m.get_type()} from the vehicle has a signature that does not "
                 f"verify with MAVProxy's key (link {sig[0]}, timestamp "
                 f"{int.from_bytes(sig[1:7], 'little')})")
        signed += 1
    if after_unsigned:
        fail(f"signing: {len(after_unsigned)} unsigned frames from the vehicle after SETUP_SIGNING "
             f"(first: {after_unsigned[:5]})")
    if signed == 0:
        fail("signing: no signed frame from the vehicle in MAVProxy's log after SETUP_SIGNING")
    return signed, before


def heartbeat_armed(tlog):
    for m in tlog_frames(tlog):
        if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1 and m.base_mode & 128:
            return True
    return False


def full(binary, keep, via=None):
    timer = Timer()
    work = keep or tempfile.mkdtemp(prefix="gcs-mavproxy-")
    os.makedirs(work, exist_ok=True)
    router = None
    broker = ground = None
    if via == "broker":
        try:
            broker = mqtt_broker.Broker()
        except RuntimeError as e:
            fail(str(e))
        port, gport = free_udp_port(), free_udp_port()
        router = Router(binary, [f"udpin:127.0.0.1:{port}?name=vehicle", broker.url(FLEET, "truck-1")],
                        work, name="vehicle-router",
                        ready_timeout=PATIENCE)
        ground = Router(binary, [broker.url(FLEET, "*"), f"udpout:127.0.0.1:{gport}?name=gcs"], work,
                        name="ground-router",
                        ready_timeout=PATIENCE)
        master = f"udpin:127.0.0.1:{gport}"
    elif via == "router":
        key_hex = hashlib.sha256(PASSPHRASE.encode()).hexdigest()
        router, port, gcs_ports = via_router(
            binary, work, [("gcs", ""), ("gcs_signed", f"key={key_hex}")], "trusted=true")
        master = f"udpin:127.0.0.1:{gcs_ports['gcs']}"
    else:
        port = free_udp_port()
        master = f"udpin:127.0.0.1:{port}"
    try:
        vehicle = Vehicle(binary, f"udpout:127.0.0.1:{port}", ["--secure"], work)
    except Failure:
        if router is not None:
            router.kill()
        raise
    mp = None
    summary = {}
    try:
        t = time.monotonic()
        mp = MavProxy(master, work, vehicle, router=router)
        mp.expect(r"Detected vehicle 1:1", 20, "connect")
        summary["connect_s"] = timer.mark("connect", t)

        # 2. parameters
        n, secs = fetch_all(mp, 30, "param fetch")
        summary.update(params=n, param_fetch_s=secs)
        mp.cmd("param status")
        _, m = mp.expect(r"Have (\d+)/(\d+) params", 10, "param status")
        if not (int(m.group(1)) == int(m.group(2)) == n):
            fail(f"param status: {m.group(0)!r} after 'Received {n} parameters'")
        saved = os.path.join(work, "fetched.parm")
        mp.cmd(f"param save {saved}")
        # MAVProxy also saves to its own log folder after a fetch ("Saved N parameters to
        # .../mav.parm"): only the line naming our file says ours is written.
        _, m = mp.expect(rf"Saved (\d+) parameters to {re.escape(saved)}", 10, "param save")
        if int(m.group(1)) != n:
            fail(f"param save wrote {m.group(1)} parameters, the vehicle reports {n}")
        values = read_param_file(saved)
        for name, want in ARDUPILOT_PARAMS.items():
            if name not in values:
                fail(f"param fetch: the ArduPilot-style vehicle has no {name}")
            if abs(values[name] - want) > 1e-6 * max(1, abs(want)):
                fail(f"param fetch: {name} = {values[name]}, expected the default {want}")

        # 3. set + read back
        t = time.monotonic()
        for name, new in (("WPNAV_SPEED", 750.5), ("RTL_ALT", 2500), ("ANGLE_MAX", 4500)):
            if name not in values:
                fail(f"param set: {name} is not a vehicle parameter")
            mp.cmd(f"param set {name} {new}")
            time.sleep(0.3)
            param_read_back(mp, name, new, f"param set {name} {new}")
        summary["param_set_readback_s"] = timer.mark("param_set", t)

        # 4. wp list + wp save on the empty vehicle: ArduPilot keeps home as item 0, so
        #    there is one item to list and to save, at the vehicle's home
        t = time.monotonic()
        mp.cmd("wp list")
        _, m = mp.expect(r"Requesting (\d+) waypoints", 15, "wp list")
        before = int(m.group(1))
        if before != 1:
            fail(f"wp list on an empty ArduPilot-style vehicle: {before} items, expected 1 "
                 "(home as item 0)")
        mp.expect(r"Saved 1 waypoints to", 20, "wp list: the home item")
        summary.update(wp_list_before=before, wp_list_s=timer.mark("wp_list", t))
        empty = os.path.join(work, "empty.txt")
        download(mp, empty, 1, 20)
        rows = read_qgc_wpl(empty)
        if len(rows) != 1 or rows[0]["seq"] != 0 or rows[0]["command"] != 16:
            fail(f"wp save on an empty vehicle: {rows}, expected item 0 = home (NAV_WAYPOINT)")
        home = (-35.363261, 149.16523)
        if abs(rows[0]["x"] - home[0]) > 1e-6 or abs(rows[0]["y"] - home[1]) > 1e-6:
            fail(f"wp save on an empty vehicle: item 0 at {rows[0]['x']}, {rows[0]['y']}, "
                 f"expected home {home}")

        # 5. wp load + compare
        items = survey_mission(12)
        mission = os.path.join(work, "mission.txt")
        write_qgc_wpl(mission, items)
        secs, _, ended = upload(mp, mission, len(items), 20)
        back = os.path.join(work, "downloaded.txt")
        dsecs, _ = download(mp, back, len(items), 20)
        compare_missions(read_qgc_wpl(mission), read_qgc_wpl(back), "wp load/save")
        summary.update(wp_items=len(items), wp_upload_s=secs, wp_upload_end=ended,
                       wp_download_s=dsecs)

        # 6. arm
        t = time.monotonic()
        mp.cmd("arm throttle")
        mp.expect(r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", 10, "arm throttle: ACK")
        mp.expect(r"\bARMED", 10, "arm throttle: armed HEARTBEAT")
        summary["arm_s"] = timer.mark("arm", t)
        mp.cmd("disarm")
        mp.expect(r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", 10, "disarm: ACK")
        mp.expect(r"DISARMED", 10, "disarm: disarmed HEARTBEAT")

        # 7. signing
        if ground is not None:
            mp.close()
            if not heartbeat_armed(mp.tlog()):
                fail("arm: no HEARTBEAT with MAV_MODE_FLAG_SAFETY_ARMED in MAVProxy's log")
            mp = None
            stats = ground.stop()
            summary["ground_router"] = router_summary(stats, ["gcs"])
            check_router_carried(stats, ["gcs"], "the ground router")
            stats = router.stop()
            summary["vehicle_router"] = router_summary(stats, ["vehicle"])
            check_router_carried(stats, ["vehicle"], "the vehicle's router")
            return summary
        if router is not None:
            mp.close()
            if not heartbeat_armed(mp.tlog()):
                fail("arm: no HEARTBEAT with MAV_MODE_FLAG_SAFETY_ARMED in MAVProxy's log")
            mp = None
            summary.update(signed_via_router(vehicle, router, gcs_ports["gcs_signed"], work, n))
            stats = router.stop()
            summary["router"] = router_summary(stats, ["vehicle", "gcs", "gcs_signed"])
            check_router_carried(stats, ["vehicle", "gcs", "gcs_signed"], "through the router")
            vehicle.stop()
            summary["mavlink1_hop"] = mavlink1_hop(binary, os.path.join(work, "mavlink1-hop"))
            return summary
        t = time.monotonic()
        setup_wall = time.time()
        mp.cmd(f"signing setup {PASSPHRASE}")
        mp.expect(r"Setup signing key", 10, "signing setup")
        time.sleep(1.5)
        mp.cmd("set allow_unsigned 0")
        n2, secs = fetch_all(mp, 30, "param fetch over the signed link (allow_unsigned 0)")
        if n2 != n:
            fail(f"signed param fetch: {n2} parameters, {n} before")
        summary.update(signed_param_fetch_s=secs, signing_s=timer.mark("signing", t))
        mp.cmd("param show WPNAV_SPEED")
        mp.expect(r"WPNAV_SPEED\s+750\.5", 10, "signed: the value set before")
        time.sleep(1.0)
        vehicle.check_alive()
        mp.close()
        tlog = mp.tlog()
        key = hashlib.sha256(PASSPHRASE.encode()).digest()
        signed, before_frames = check_signed_tail(tlog, setup_wall, key)
        if not heartbeat_armed(tlog):
            fail("arm: no HEARTBEAT with MAV_MODE_FLAG_SAFETY_ARMED in MAVProxy's log")
        summary.update(frames_before_signing=before_frames, signed_frames=signed)
    finally:
        if mp is not None:
            mp.close()
        vehicle.stop()
        for r in (router, ground):
            if r is not None:
                r.kill()
        if broker is not None:
            broker.stop()
    return summary


def router_summary(stats, names):
    """Per router link: frames in/out, conversions, drops (from the router's last stats)."""
    return {name: {"version": sorted({str(e.get("version")) for e in link_stats(stats, name)}),
                   "rx": link_total(stats, name, "rx_frames"),
                   "tx": link_total(stats, name, "tx_frames"),
                   "converted": link_total(stats, name, "converted"),
                   "dropped": link_dropped(stats, name)}
            for name in names}


def signed_via_router(vehicle, router, port, work, n):
    """Check 7 through the router: a second MAVProxy on the router's link keyed with
    sha256(PASSPHRASE) sets the same key locally and refuses unsigned frames; a full fetch
    must complete, and every vehicle frame it logged is signed with the key (the router signs
    the trusted vehicle link's unsigned frames onto its signed link)."""
    res = {}
    work2 = os.path.join(work, "signed")
    os.makedirs(work2, exist_ok=True)
    start_wall = time.time()
    t = time.monotonic()
    mp = MavProxy(f"udpin:127.0.0.1:{port}", work2, vehicle, router=router)
    try:
        mp.expect(r"Detected vehicle 1:1", 20, "signed router link: connect")
        # before its key is set, MAVProxy's frames (its HEARTBEATs) are unsigned: the router's
        # signed link must drop them
        deadline = time.monotonic() + 6
        while not link_dropped(router.last_stats(), "gcs_signed").get("unsigned"):
            if time.monotonic() > deadline:
                fail("signed router link: MAVProxy's unsigned frames (before `signing key`) "
                     f"not counted as dropped `unsigned` within 6 s\n{router.describe()}")
            time.sleep(0.1)
        res["unsigned_dropped_before_key_s"] = round(time.monotonic() - t, 3)
        mp.cmd(f"signing key {PASSPHRASE}")
        mp.expect(r"Setup signing key", 10, "signing key")
        mp.cmd("set allow_unsigned 0")
        n2, secs = fetch_all(mp, 30, "param fetch over the router's signed link (allow_unsigned 0)")
        if n2 != n:
            fail(f"signed param fetch through the router: {n2} parameters, {n} before")
        res.update(signed_param_fetch_s=secs)
        mp.cmd("param show WPNAV_SPEED")
        mp.expect(r"WPNAV_SPEED\s+750\.5", 10, "signed: the value set before")
        res["signing_s"] = round(time.monotonic() - t, 3)
        time.sleep(1.0)
        vehicle.check_alive()
        router.check_alive()
    finally:
        mp.close()
    key = hashlib.sha256(PASSPHRASE.encode()).digest()
    # every vehicle frame this MAVProxy logged, from its start on, is signed with the key
    signed, _ = check_signed_tail(mp.tlog(), start_wall - 2.0, key)
    res.update(signed_frames=signed)
    return res


def mavlink1_hop(binary, work):
    """A `--mavlink1-only` vehicle on the router's `version=1` link, MAVProxy (MAVLink 2) on a
    plain one: parameters, a mission and arm/disarm through the router's conversion."""
    os.makedirs(work, exist_ok=True)
    res = {}
    router, port, gcs_ports = via_router(binary, work, [("gcs", "")], "version=1",
                                         name="router-v1")
    mp = None
    try:
        vehicle = Vehicle(binary, f"udpout:127.0.0.1:{port}", ["--mavlink1-only"], work)
    except Failure:
        router.kill()
        raise
    try:
        t = time.monotonic()
        mp = MavProxy(f"udpin:127.0.0.1:{gcs_ports['gcs']}", work, vehicle, router=router)
        mp.expect(r"Detected vehicle 1:1", 20, "MAVLink 1 hop: connect")
        res["connect_s"] = round(time.monotonic() - t, 3)
        n, secs = fetch_all(mp, 30, "MAVLink 1 hop: param fetch")
        res.update(params=n, param_fetch_s=secs)
        saved = os.path.join(work, "fetched.parm")
        mp.cmd(f"param save {saved}")
        # (MAVProxy also saves a fetch to its own mav.parm and says so: match our path only)
        _, m = mp.expect(rf"Saved (\d+) parameters to {re.escape(saved)}", 10,
                         "MAVLink 1 hop: param save")
        if int(m.group(1)) != n:
            fail(f"MAVLink 1 hop: param save wrote {m.group(1)} parameters, the vehicle reports {n}")
        values = read_param_file(saved)
        for name, want in ARDUPILOT_PARAMS.items():
            if name not in values or abs(values[name] - want) > 1e-6 * max(1, abs(want)):
                fail(f"MAVLink 1 hop: param fetch: {name} = {values.get(name)}, expected {want}")
        for name, new in (("WPNAV_SPEED", 612.25), ("RTL_ALT", 1800)):
            mp.cmd(f"param set {name} {new}")
            time.sleep(0.3)
            param_read_back(mp, name, new, f"MAVLink 1 hop: param set {name} {new}")
        items = survey_mission(12)
        mission = os.path.join(work, "mission.txt")
        write_qgc_wpl(mission, items)
        secs, _, _ = upload(mp, mission, len(items), 20)
        back = os.path.join(work, "downloaded.txt")
        dsecs, _ = download(mp, back, len(items), 20)
        compare_missions(read_qgc_wpl(mission), read_qgc_wpl(back), "MAVLink 1 hop: wp load/save")
        res.update(wp_items=len(items), wp_upload_s=secs, wp_download_s=dsecs)
        mp.cmd("arm throttle")
        mp.expect(r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", 10, "MAVLink 1 hop: arm ACK")
        mp.expect(r"\bARMED", 10, "MAVLink 1 hop: armed HEARTBEAT")
        mp.cmd("disarm")
        mp.expect(r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", 10, "MAVLink 1 hop: disarm ACK")
        mp.expect(r"DISARMED", 10, "MAVLink 1 hop: disarmed HEARTBEAT")
        vehicle.check_alive()
        mp.close()
        v1 = v2 = 0
        for m in tlog_frames(mp.tlog()):
            if m.get_srcSystem() == 1 and m.get_type() != "BAD_DATA":
                if bytes(m.get_msgbuf())[0] == 0xFD:
                    v2 += 1
                else:
                    v1 += 1
        stats = router.stop()
        res["router"] = router_summary(stats, ["vehicle", "gcs"])
        check_router_carried(stats, ["vehicle", "gcs"], "MAVLink 1 hop")
        if res["router"]["vehicle"]["version"] != ["1"]:
            fail(f"MAVLink 1 hop: the vehicle's router link has version {res['router']['vehicle']['version']}, "
                 f"expected [\"1\"]: {json.dumps(stats)}")
        # MAVProxy speaks MAVLink 2: from its first frame on, the vehicle's MAVLink 1 frames
        # reach it converted to MAVLink 2
        if res["router"]["gcs"]["converted"] == 0 or v2 == 0:
            fail(f"MAVLink 1 hop: no conversion to MAVLink 2 towards MAVProxy ({v2} MAVLink 2 and "
                 f"{v1} MAVLink 1 vehicle frames in its log): {json.dumps(stats)}")
        res.update(vehicle_frames_v2_at_gcs=v2, vehicle_frames_v1_at_gcs=v1)
    finally:
        if mp is not None:
            mp.close()
        vehicle.stop()
        router.kill()
    return res


def bench_run(binary, n_params, n_items, loss, seed, work):
    from lossy_relay import LossyRelay

    params = {f"BENCH_P{i:05d}": (i if i % 2 else i + 0.5) for i in range(n_params)}
    params_file = os.path.join(work, "bench.parm")
    write_params_file(params_file, params)
    gcs_port = free_udp_port()
    relay = None
    heard = {"request": 0.0}

    def tap(way, data, dropped):
        # a MISSION_REQUEST(_INT) (ids 40, 51) from the vehicle that reaches MAVProxy
        if way == "up" and not dropped and len(data) > 10 and data[0] == 0xFD:
            if int.from_bytes(data[7:10], "little") in (40, 51):
                heard["request"] = time.monotonic()

    if loss > 0:
        relay = LossyRelay(("127.0.0.1", 0), ("127.0.0.1", gcs_port), loss=loss, seed=seed,
                           tap=tap).start()
        vport = relay.listen_port
    else:
        vport = gcs_port
    vehicle = Vehicle(binary, f"udpout:127.0.0.1:{vport}", ["--params", params_file], work)
    mp = None
    res = {"loss": loss, "seed": seed}
    try:
        mp = MavProxy(f"udpin:127.0.0.1:{gcs_port}", work, vehicle)
        mp.expect(r"Detected vehicle 1:1", 30, "connect")
        budget = 60 + n_params * (0.2 if loss else 0.02)
        n, secs = fetch_all(mp, budget, f"param fetch of {n_params}+ parameters")
        if n < n_params:
            fail(f"bench: the vehicle reports {n} parameters, the --params file has {n_params}")
        res.update(params=n, param_fetch_s=secs)
        saved = os.path.join(work, "fetched.parm")
        mp.cmd(f"param save {saved}")
        mp.expect(rf"Saved (\d+) parameters to {re.escape(saved)}", 30, "param save")
        values = read_param_file(saved)
        wrong = [(k, v, values.get(k)) for k, v in params.items()
                 if k not in values or abs(values[k] - v) > 1e-3]
        if wrong:
            fail(f"bench: {len(wrong)} parameters differ from the --params file, first "
                 f"(name, file, fetched): {wrong[:5]}")
        items = survey_mission(n_items)
        mission = os.path.join(work, "bench-mission.txt")
        write_qgc_wpl(mission, items)
        # under loss about a third of the items wait for the vehicle's re-request, 1 s each
        budget = 30 + n_items * (1.0 if loss else 0.02)
        secs, attempts, ended = upload(mp, mission, len(items), budget,
                                       attempts=30 if loss else 1,
                                       last_request=(lambda: heard["request"]) if loss else None)
        back = os.path.join(work, "bench-downloaded.txt")
        dsecs, dattempts = download(mp, back, len(items), 60 + n_items * (1.5 if loss else 0.02),
                                   attempts=10 if loss else 1)
        compare_missions(read_qgc_wpl(mission), read_qgc_wpl(back), "bench mission")
        res.update(items=len(items), wp_upload_s=secs, wp_upload_attempts=attempts,
                   wp_upload_end=ended,
                   wp_download_s=dsecs, wp_download_attempts=dattempts)
        vehicle.check_alive()
    finally:
        if mp is not None:
            mp.close()
        vehicle.stop()
        if relay is not None:
            relay.stop()
            res["relay"] = relay.stats
    return res


def bench(binary, n_params, n_items, losses, seed, keep):
    runs = []
    if keep:
        os.makedirs(keep, exist_ok=True)
    for loss in losses:
        work = tempfile.mkdtemp(prefix=f"gcs-mavproxy-bench-{loss}-", dir=keep)
        runs.append(bench_run(binary, n_params, n_items, loss, seed, work))
    return {"bench": runs}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mavstack", help="the mavstack binary (default $MAVSTACK_BIN)")
    ap.add_argument("--keep", help="work directory to keep (default: a fresh temporary one)")
    ap.add_argument("--bench", nargs=2, type=int, metavar=("N_PARAMS", "N_ITEMS"))
    ap.add_argument("--loss", type=float, action="append",
                    help="bench: loss rates to run (default 0 and 0.2)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--via-router", action="store_true",
                    help="the session through `mavstack router` (and a MAVLink 1 hop)")
    ap.add_argument("--via-broker", action="store_true",
                    help="the session through an MQTT broker: the vehicle's router bridges onto "
                         "mosquitto, a ground router subscribed to the fleet serves MAVProxy")
    args = ap.parse_args()
    if args.bench and (args.via_router or args.via_broker):
        ap.error("--via-router and --via-broker run the session, not --bench")

    def body():
        binary = mavstack_bin(args.mavstack)
        if args.bench:
            return bench(binary, *args.bench, args.loss or [0.0, 0.2], args.seed, args.keep)
        via = "router" if args.via_router else "broker" if args.via_broker else None
        return full(binary, args.keep, via)

    run_main("gcs_mavproxy", body)


if __name__ == "__main__":
    try:
        main()
    except Failure as e:
        print(f"gcs_mavproxy: FAILED: {e}", file=sys.stderr)
        sys.exit(1)
