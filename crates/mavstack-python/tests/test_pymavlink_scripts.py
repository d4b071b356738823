"""Scripts written for pymavlink only (tests/pymavlink_scripts/), each run first with pymavlink
against the simulated vehicle (`mavstack vehicle`), then unchanged with mavstack's mavutil in
pymavlink's place (run_with_mavstack.py): the same lines printed.

The vehicle is the `mavstack` binary of the workspace (target/debug, else target/release;
$MAVSTACK_BIN overrides): missing, the tests fail."""

import os
import socket
import subprocess
import sys
import threading
import time

import pytest

from conftest import Lossy, Vehicle, free_port, wait_tcp_listening

SCRIPTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "pymavlink_scripts")
SHIM = os.path.join(SCRIPTS, "run_with_mavstack.py")


def run_script(script, args, with_mavstack):
    """The script run with pymavlink, or with mavstack's mavutil in its place; its process."""
    cmd = [sys.executable]
    if with_mavstack:
        cmd.append(SHIM)
    cmd += [os.path.join(SCRIPTS, script), *args]
    env = dict(os.environ, MAVLINK20="1", MAVLINK_DIALECT="ardupilotmega")
    return subprocess.run(cmd, capture_output=True, text=True, timeout=90, env=env)


def run(script, args, with_mavstack):
    """The script's output; it must succeed."""
    p = run_script(script, args, with_mavstack)
    who = "mavstack" if with_mavstack else "pymavlink"
    assert p.returncode == 0, "%s with %s failed (%d):\n%s%s" % (script, who, p.returncode, p.stdout, p.stderr)
    return p.stdout


def udp_session(script, vehicle_args=(), with_mavstack=False):
    """The vehicle sends to the script's `udpin` port (as gcs_pymavlink.py runs it)."""
    port = free_port()
    with Vehicle("udpout:127.0.0.1:%d" % port, *vehicle_args):
        return run(script, ["udpin:127.0.0.1:%d" % port], with_mavstack)


def lossy_session(script, vehicle_args=(), with_mavstack=False, loss=0.2):
    """The same through 20 % loss each way (tests-interop/lossy_relay.py, seeded)."""
    port = free_port()
    with Lossy(port, loss=loss, seed=3) as relay_port, Vehicle("udpout:127.0.0.1:%d" % relay_port, *vehicle_args):
        return run(script, ["udpin:127.0.0.1:%d" % port], with_mavstack)


def both(script, session=udp_session, **kw):
    theirs = session(script, with_mavstack=False, **kw)
    ours = session(script, with_mavstack=True, **kw)
    assert theirs.strip(), "pymavlink printed nothing"
    assert ours == theirs, "%s:\npymavlink:\n%s\nmavstack:\n%s" % (script, theirs, ours)
    return ours


@pytest.mark.parametrize("script", ["heartbeat.py", "attitude.py", "mission.py", "params.py"])
def test_px4_flavour(script):
    """The scripts that are not ArduPilot's alone, against the vehicle as PX4."""
    out = both(script, vehicle_args=("--autopilot", "px4"))
    assert "None" not in out and "False" not in out.replace("armed False", "")


def test_interval_on_the_px4_flavour_stops_as_on_px4():
    """PX4 (1.16 SITL) answers REQUEST_MESSAGE(MESSAGE_INTERVAL) with DENIED, and so does the
    simulator as PX4: interval.py sets the rate, then stops without MESSAGE_INTERVAL, with
    pymavlink and with mavstack's mavutil alike."""
    outs = []
    for with_mavstack in (False, True):
        port = free_port()
        with Vehicle("udpout:127.0.0.1:%d" % port, "--autopilot", "px4"):
            p = run_script("interval.py", ["udpin:127.0.0.1:%d" % port], with_mavstack)
        outs.append((p.returncode, p.stdout, p.stderr.strip().splitlines()[-1:]))
    assert outs[0] == outs[1], outs
    assert outs[0][0] == 1 and outs[0][1] == "ack 511 result 0\n" and outs[0][2] == ["no MESSAGE_INTERVAL"], outs


def test_heartbeat():
    out = both("heartbeat.py")
    assert "heartbeat from 1/1" in out and "target 1/0" in out


def test_heartbeat_over_tcp():
    def tcp_session(script, with_mavstack):
        port = free_port(socket.SOCK_STREAM)
        with Vehicle("tcpin:127.0.0.1:%d" % port) as vehicle:
            # pymavlink gives up on a server that is not up yet.
            wait_tcp_listening(port, vehicle.proc)
            return run(script, ["tcp:127.0.0.1:%d" % port], with_mavstack)
    out = both("heartbeat.py", session=tcp_session)
    assert "heartbeat from 1/1" in out


def test_attitude_stream():
    out = both("attitude.py")
    assert "ATTITUDE x20" in out and "finite True" in out


@pytest.mark.parametrize("script,vehicle_args", [
    ("heartbeat.py", ()), ("attitude.py", ()), ("params.py", ()), ("mission.py", ()),
    ("arm_mode.py", ()), ("interval.py", ()), ("signing.py", ("--secure",)),
])
def test_through_20_percent_loss(script, vehicle_args):
    """Each script (they ask again for what is lost) through 20 % loss each way."""
    out = both(script, session=lossy_session, vehicle_args=vehicle_args)
    assert "None" not in out and "False" not in out.replace("armed False", "")


def test_params_fetch_all_and_set():
    out = both("params.py")
    assert "set RTL_ALT -> 3000.0" in out and "read back RTL_ALT = 3000.0" in out


def test_mission_upload_and_read_back():
    out = both("mission.py")
    assert "upload ack 0" in out and "count 6" in out and "item 5 cmd 20" in out


def test_arm_disarm_and_modes():
    out = both("arm_mode.py")
    assert "mode GUIDED" in out and "armed True" in out and "mode LOITER" in out


def test_message_interval():
    out = both("interval.py")
    assert "ack 511 result 0" in out and "between 5 and 13 Hz True" in out


def test_signing_setup():
    out = both("signing.py", vehicle_args=("--secure",))
    assert "heartbeat signed True" in out and "signed True" in out


def forward_session(script, with_mavstack, loss=0.0):
    """vehicle -> forwarder (argv[1]) -> a pymavlink ground station (argv[2]), and back; with
    `loss`, the vehicle's link goes through lossy_relay.py."""
    from pymavlink import mavutil as pm
    vport, gport = free_port(), free_port()
    gcs = pm.mavlink_connection("udpin:127.0.0.1:%d" % gport, source_system=250)
    stop = threading.Event()

    def ask():
        while not stop.is_set():
            gcs.mav.param_request_read_send(1, 1, b"RTL_ALT", -1)
            while gcs.recv_msg() is not None:
                pass
            time.sleep(0.2)
    # The ground station speaks first: the forwarder's udpout learns nothing else.
    t = threading.Thread(target=ask, daemon=True)
    try:
        with Lossy(vport, loss=loss, seed=5) as relay_port, Vehicle("udpout:127.0.0.1:%d" % relay_port):
            t.start()
            return run(script, ["udpin:127.0.0.1:%d" % vport, "udpout:127.0.0.1:%d" % gport],
                       with_mavstack)
    finally:
        stop.set()
        if t.is_alive():
            t.join()
        gcs.close()


@pytest.mark.parametrize("loss", [0.0, 0.2])
def test_two_link_forwarder(loss):
    """A forwarder between the vehicle and a pymavlink ground station: its HEARTBEATs one
    way, a parameter request the other, the answer back; clean and through 20 % loss."""
    out = both("forwarder.py", session=lambda script, with_mavstack: forward_session(script, with_mavstack, loss))
    assert "answer forwarded True" in out


def test_mav_signatures_match_pymavlink():
    """Every `<message>_send` and `_encode` of ardupilotmega: pymavlink's parameter names,
    order and defaults."""
    import inspect
    from pymavlink.dialects.v20 import ardupilotmega as apm
    from mavstack import mavutil
    port = free_port()
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    try:
        ours = conn.mav
        theirs = apm.MAVLink(None)
        names = [n for n in dir(theirs) if n.endswith(("_send", "_encode")) and n != "send"]
        assert len(names) > 500
        for n in names:
            sig_t = inspect.signature(getattr(theirs, n))
            sig_o = inspect.signature(getattr(ours, n))
            t = [(p.name, p.default) for p in sig_t.parameters.values()]
            o = [(p.name, p.default) for p in sig_o.parameters.values()]
            assert o == t, n
        assert set(names) <= set(dir(ours))
    finally:
        conn.close()

