"""mavstack.mavutil's live links without the vehicle: serial ports (a pseudo-terminal, with
pymavlink at the other end), the GIL released while a receive waits, Ctrl-C during a wait,
errors that name the connection string, sending and encoding against pymavlink's decoder."""

import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
import tty

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as apm  # noqa: E402

from conftest import free_port  # noqa: E402
from mavstack import mavutil  # noqa: E402


def test_serial_device_with_baud_both_ways():
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    conn = mavutil.mavlink_connection(os.ttyname(slave), baud=115200)
    try:
        peer = apm.MAVLink(None, srcSystem=1, srcComponent=1)
        os.write(master, peer.heartbeat_encode(2, 3, 81, 4, 4).pack(peer))
        hb = conn.wait_heartbeat(timeout=5)
        assert hb is not None and hb.custom_mode == 4 and conn.target_system == 1
        conn.mav.param_request_read_send(1, 1, b"RTL_ALT", -1)
        deadline, got = time.time() + 5, []
        while not got and time.time() < deadline:
            time.sleep(0.05)
            got = [m for m in peer.parse_buffer(os.read(master, 4096)) or []]
        assert [m.get_type() for m in got] == ["PARAM_REQUEST_READ"]
        assert (got[0].param_id, got[0].param_index, got[0].get_srcSystem()) == ("RTL_ALT", -1, 255)
    finally:
        conn.close()
        os.close(master)
        os.close(slave)


def test_missing_serial_device_is_an_error_naming_it():
    with pytest.raises(OSError, match="/dev/ttyNOPE"):
        mavutil.mavlink_connection("/dev/ttyNOPE", baud=57600)


def test_bad_connection_strings_are_named():
    with pytest.raises(ValueError, match="udpin:nohost"):
        mavutil.mavlink_connection("udpin:nohost")
    with pytest.raises(ValueError, match="tcp:127.0.0.1:99999"):
        mavutil.mavlink_connection("tcp:127.0.0.1:99999")


def test_a_blocking_receive_releases_the_gil():
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % free_port())
    ticks = [0]
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks[0] += 1
    t = threading.Thread(target=count)
    t.start()
    try:
        before = ticks[0]
        start = time.time()
        assert conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5) is None
        assert 0.45 <= time.time() - start < 2.0
        assert ticks[0] - before > 1000
    finally:
        stop.set()
        t.join()
        conn.close()


def _wait_heartbeat_then_ctrl_c(port, while_waiting=lambda: None):
    """Starts a child that waits for a HEARTBEAT without timeout on `port`, runs
    `while_waiting` once it waits, then sends it SIGINT: the child must say it was
    interrupted (a KeyboardInterrupt out of the wait)."""
    code = textwrap.dedent("""
        import signal
        # A harness that runs the tests in the background may have SIGINT ignored, and
        # Python keeps an inherited SIG_IGN: Ctrl-C as a terminal gives it.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        from mavstack import mavutil
        conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d")
        print("waiting", flush=True)
        try:
            conn.wait_heartbeat()
        except KeyboardInterrupt:
            print("interrupted", flush=True)
    """ % port)
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "waiting"
        while_waiting()
        time.sleep(0.3)
        p.send_signal(signal.SIGINT)
        got, _ = p.communicate(timeout=10)
        assert got.strip() == "interrupted"
    finally:
        if p.poll() is None:
            p.kill()


def test_ctrl_c_interrupts_a_wait_without_timeout():
    _wait_heartbeat_then_ctrl_c(free_port())


def test_ctrl_c_interrupts_a_wait_while_other_messages_stream_in():
    """A stream of messages the call does not want (here ATTITUDE, one a millisecond, while it
    waits for a HEARTBEAT) never leaves it idle long enough to time out a wait: Ctrl-C must
    still get through."""
    port = free_port()
    enc = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    frame = enc.attitude_encode(1, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03).pack(enc)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stop = threading.Event()

    def stream():
        while not stop.is_set():
            out.sendto(frame, ("127.0.0.1", port))
            time.sleep(0.001)
    t = threading.Thread(target=stream)
    try:
        _wait_heartbeat_then_ctrl_c(port, t.start)
    finally:
        stop.set()
        if t.is_alive():
            t.join()
        out.close()


def test_sent_and_encoded_messages_decode_in_pymavlink():
    port = free_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", port))
    rx.settimeout(5)
    conn = mavutil.mavlink_connection("udpout:127.0.0.1:%d" % port, source_system=42, source_component=7)
    try:
        peer = apm.MAVLink(None)
        conn.mav.statustext_send(4, b"hello")
        conn.mav.mission_item_int_send(1, 1, 3, 6, 16, 0, 1, 0.5, 0, 0, float("nan"), -353632610, 1491652300, 30.0)
        msg = conn.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        assert msg.get_type() == "COMMAND_LONG" and msg.command == 400 and msg.param1 == 1.0
        conn.mav.send(msg)
        got = []
        while len(got) < 3:
            got += peer.parse_buffer(rx.recv(1024)) or []
        assert [m.get_type() for m in got] == ["STATUSTEXT", "MISSION_ITEM_INT", "COMMAND_LONG"]
        assert all((m.get_srcSystem(), m.get_srcComponent()) == (42, 7) for m in got)
        assert got[0].text == "hello" and got[0].severity == 4
        it = got[1]
        assert (it.seq, it.frame, it.command, it.x, it.y, it.z, it.mission_type) == (3, 6, 16, -353632610, 1491652300, 30.0, 0)
        assert got[2].command == 400 and got[2].param1 == 1.0
        with pytest.raises(ValueError, match="seq"):
            conn.mav.mission_item_int_send(1, 1, 70000, 6, 16, 0, 1, 0, 0, 0, 0, 0, 0, 0)
        with pytest.raises(TypeError):
            conn.mav.heartbeat_send(1, 2)
        assert conn.mav.srcSystem == 42 and conn.mav.srcComponent == 7
    finally:
        conn.close()
        rx.close()


def test_files_still_open_as_logs(tmp_path):
    path = tmp_path / "x.tlog"
    path.write_bytes(b"")
    log = mavutil.mavlink_connection(str(path))
    assert isinstance(log, mavutil.mavlogfile) and log.recv_msg() is None
    with pytest.raises(OSError):
        mavutil.mavlink_connection(str(tmp_path / "missing.tlog"))


def test_tcpin_serves_a_pymavlink_client():
    from pymavlink import mavutil as pm
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    conn = mavutil.mavlink_connection("tcpin:127.0.0.1:%d" % port)
    client = pm.mavlink_connection("tcp:127.0.0.1:%d" % port, source_system=1, source_component=1)
    try:
        client.mav.heartbeat_send(2, 3, 81, 5, 4)
        hb = conn.wait_heartbeat(timeout=5)
        assert hb is not None and hb.custom_mode == 5 and conn.flightmode == "LOITER"
        conn.mav.param_request_read_send(1, 1, b"RTL_ALT", -1)
        m = client.recv_match(type="PARAM_REQUEST_READ", blocking=True, timeout=5)
        assert m is not None and m.param_id == "RTL_ALT" and m.get_srcSystem() == 255
    finally:
        client.close()
        conn.close()


def test_udpbcast_sends_to_the_broadcast_address():
    from pymavlink import mavutil as pm
    port = free_port()
    listener = pm.mavlink_connection("udpin:0.0.0.0:%d" % port)
    conn = mavutil.mavlink_connection("udpbcast:127.255.255.255:%d" % port, source_system=7, source_component=1)
    try:
        deadline, m = time.time() + 5, None
        while m is None and time.time() < deadline:
            conn.mav.heartbeat_send(6, 8, 0, 0, 4)
            m = listener.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        assert m is not None and m.get_srcSystem() == 7
    finally:
        listener.close()
        conn.close()


def test_pymavlink_constants():
    from pymavlink.dialects.v20 import ardupilotmega as apm_mod
    ours = mavutil.mavlink
    names = [n for n in dir(apm_mod) if n.startswith(("MAV_", "MAVLINK_MSG_ID_", "MAVLINK_TYPE_", "COPTER_MODE_"))
             and isinstance(getattr(apm_mod, n), int) and not n.endswith("_ENUM_END")]
    assert len(names) > 1000
    missing = [n for n in names if not hasattr(ours, n)]
    differ = [n for n in names if hasattr(ours, n) and getattr(ours, n) != getattr(apm_mod, n)]
    assert not differ, differ[:10]
    assert len(missing) < len(names) // 50, missing[:20]


def test_udp_with_input_false_sends():
    port = free_port()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", port))
    rx.settimeout(5)
    conn = mavutil.mavlink_connection("udp:127.0.0.1:%d" % port, input=False)
    try:
        assert conn.address.startswith("udpout:")
        conn.mav.heartbeat_send(6, 8, 0, 0, 4)
        got = apm.MAVLink(None).parse_buffer(rx.recv(1024))
        assert [m.get_type() for m in got] == ["HEARTBEAT"]
    finally:
        conn.close()
        rx.close()


def test_one_thread_receives_while_another_sends():
    """pymavlink's common pattern: a receiving thread, the main thread sending and reading
    the connection's state at the same time."""
    port = free_port()
    peer_port = free_port()
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", peer_port))
    peer.settimeout(5)
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    enc = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    got, stop = [], threading.Event()

    def receive():
        while not stop.is_set():
            m = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2)
            if m is not None:
                got.append(m)
    t = threading.Thread(target=receive)
    t.start()
    try:
        # The peer is known to the link (udpin answers whoever spoke) before it is sent to.
        peer.sendto(enc.heartbeat_encode(2, 3, 81, 100, 4).pack(enc), ("127.0.0.1", port))
        deadline = time.time() + 5
        while conn.target_system != 1 and time.time() < deadline:
            time.sleep(0.01)
        for i in range(20):
            peer.sendto(enc.heartbeat_encode(2, 3, 81, i, 4).pack(enc), ("127.0.0.1", port))
            conn.mav.heartbeat_send(6, 8, 0, 0, 4)
            _ = conn.target_system, conn.messages, conn.flightmode
            time.sleep(0.01)
        deadline = time.time() + 5
        while len(got) < 21 and time.time() < deadline:
            time.sleep(0.05)
        assert [m.custom_mode for m in got] == [100] + list(range(20))
        assert conn.target_system == 1 and conn.messages["HEARTBEAT"].custom_mode == 19
        back = 0
        try:
            while back < 20:
                peer.recv(300)
                back += 1
        except socket.timeout:
            pass
        assert back == 20
    finally:
        stop.set()
        t.join()
        conn.close()


def test_flightmode_as_pymavlink_names_it():
    """`flightmode` from HEARTBEATs of ArduPilot's vehicles and PX4, beside pymavlink's
    mode_string_v10 of the same HEARTBEAT."""
    from pymavlink import mavutil as pm
    port = free_port()
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    enc = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    cases = []
    for mav_type in (2, 1, 10, 12, 13, 20):  # quadrotor, fixed wing, ground rover, submarine, hexa, VTOL
        for custom in range(0, 30):
            cases.append((3, mav_type, 1 | 128, custom))
    cases.append((3, 2, 0, 4))  # no custom mode
    for main in range(0, 10):
        for sub in range(0, 11):
            cases.append((12, 2, 1, (main << 16) | (sub << 24)))
    try:
        mismatches = []
        for autopilot, mav_type, base, custom in cases:
            msg = enc.heartbeat_encode(mav_type, autopilot, base, custom, 4)
            tx.sendto(msg.pack(enc), ("127.0.0.1", port))
            hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
            assert hb is not None and hb.custom_mode == custom
            want = pm.mode_string_v10(msg)
            if conn.flightmode != want:
                mismatches.append((autopilot, mav_type, base, custom, conn.flightmode, want))
        assert not mismatches, mismatches
    finally:
        tx.close()
        conn.close()


def test_mode_mapping_as_pymavlink():
    """ArduPilot's modes by pymavlink's names (mode_mapping_byname), and set_mode by them."""
    from pymavlink import mavutil as pm
    port, peer_port = free_port(), free_port()
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.bind(("127.0.0.1", peer_port))
    tx.settimeout(5)
    enc = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    try:
        for mav_type in (2, 1, 10, 12, 13, 20):
            tx.sendto(enc.heartbeat_encode(mav_type, 3, 129, 0, 4).pack(enc), ("127.0.0.1", port))
            assert conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5) is not None
            assert conn.mode_mapping() == pm.mode_mapping_byname(mav_type), mav_type
        conn.set_mode("FBWA")  # the last HEARTBEAT said a VTOL: Plane's modes
        got = apm.MAVLink(None).parse_buffer(tx.recv(1024))
        assert [(m.command, m.param1, m.param2) for m in got] == [(176, 1.0, 5.0)]
    finally:
        tx.close()
        conn.close()


def test_signing_set_up_before_any_peer():
    """setup_signing on a udpin link nobody has spoken to yet: the peer that comes later is
    held to it (its signed frames verified, its unsigned ones refused) and answered signed."""
    key = bytes(range(32))
    port = free_port()
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    peer.settimeout(5)
    try:
        conn.setup_signing(key, link_id=3)
        plain = apm.MAVLink(None, srcSystem=1, srcComponent=1)
        signed = apm.MAVLink(None, srcSystem=1, srcComponent=1)
        signed.signing.secret_key = key
        signed.signing.sign_outgoing = True
        signed.signing.link_id = 1
        signed.signing.timestamp = int((time.time() - 1420070400) * 100000)
        peer.sendto(plain.heartbeat_encode(2, 3, 81, 7, 4).pack(plain), ("127.0.0.1", port))
        peer.sendto(signed.heartbeat_encode(2, 3, 81, 8, 4).pack(signed), ("127.0.0.1", port))
        hb = conn.wait_heartbeat(timeout=5)
        assert hb is not None and hb.custom_mode == 8 and hb.get_signed() and hb.get_link_id() == 1
        assert conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.3) is None
        conn.mav.heartbeat_send(6, 8, 0, 0, 4)
        checker = apm.MAVLink(None)
        checker.signing.secret_key = key
        got = checker.parse_buffer(peer.recv(1024))
        assert [m.get_type() for m in got] == ["HEARTBEAT"] and got[0].get_signed()
        assert got[0].get_link_id() == 3
    finally:
        peer.close()
        conn.close()


def test_a_timeout_too_long_to_count_waits_for_the_message():
    """pymavlink waits `timeout` seconds whatever their number: 1e300 (or infinity) is
    "forever", never "at once". The message is sent 0.3 s after the call starts."""
    port = free_port()
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    enc = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for timeout in (1e300, float("inf")):
            timer = threading.Timer(0.3, lambda: out.sendto(
                enc.attitude_encode(1, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03).pack(enc), ("127.0.0.1", port)))
            timer.start()
            m = conn.recv_match(type="ATTITUDE", blocking=True, timeout=timeout)
            timer.join()
            assert m is not None and m.time_boot_ms == 1, timeout
    finally:
        out.close()
        conn.close()


def test_messages_hold_what_recv_match_filtered_out_as_pymavlinks_do():
    """Frames `recv_match` does not return still become the latest of their type, as in
    pymavlink (its `post_message` runs for every frame): the same datagrams to a pymavlink
    and a mavstack connection, the same calls, the same `messages` after each, and a
    condition over a type that was filtered out."""
    from pymavlink import mavutil as pymavutil
    ports = free_port(), free_port()
    conns = [pymavutil.mavlink_connection("udpin:127.0.0.1:%d" % ports[0]),
             mavutil.mavlink_connection("udpin:127.0.0.1:%d" % ports[1])]
    enc = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(*frames):
        for f in frames:
            for p in ports:
                out.sendto(f.pack(enc), ("127.0.0.1", p))

    def att(t):
        return enc.attitude_encode(t, 0.1 * t, 0.2, 0.3, 0.01, 0.02, 0.03)

    def gpi(t):
        return enc.global_position_int_encode(t, -353632610 + t, 1491652300, 584000, 10000, 1, 2, 3, 9000)

    def latest(c):
        # pymavlink's dict starts with two entries of its own.
        return {k: v.to_dict() for k, v in c.messages.items() if k not in ("MAV", "HOME")}

    try:
        send(enc.heartbeat_encode(2, 3, 81, 4, 4), att(1), gpi(2),
             enc.vfr_hud_encode(1.5, 2.5, 90, 50, 10.0, 0.5), att(3), gpi(4),
             enc.sys_status_encode(1, 1, 1, 500, 12000, -1, 80, 0, 0, 0, 0, 0, 0), gpi(5))
        steps = []
        for c in conns:
            seen = []
            for _ in range(2):
                m = c.recv_match(type="ATTITUDE", blocking=True, timeout=5)
                seen.append((m.time_boot_ms, m is c.messages["ATTITUDE"], latest(c)))
            seen.append((c.recv_match(type="ATTITUDE", blocking=True, timeout=0.5), latest(c)))
            steps.append(seen)
        assert steps[0] == steps[1]
        assert steps[1][2][1]["GLOBAL_POSITION_INT"]["time_boot_ms"] == 5
        assert set(steps[1][2][1]) == {"HEARTBEAT", "ATTITUDE", "GLOBAL_POSITION_INT", "VFR_HUD", "SYS_STATUS"}

        send(att(6), gpi(7), att(8))
        got = [c.recv_match(type="ATTITUDE", condition="GLOBAL_POSITION_INT.time_boot_ms == 7",
                            blocking=True, timeout=5) for c in conns]
        assert [m.time_boot_ms for m in got] == [8, 8]
        assert latest(conns[0]) == latest(conns[1])
    finally:
        for c in conns:
            c.close()


def test_live_frames_short_and_long_come_whole():
    """A live message keeps a short frame inside itself and a long one apart: frames on
    both sides of that line (80 and 81 bytes), the longest (280, signed) and a 40-byte
    ATTITUDE come back byte for byte and decode as pymavlink decodes them. The timeouts
    are ints, as scripts write them."""
    port = free_port()
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    enc = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    signer = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    signer.signing.secret_key = bytes(range(32))
    signer.signing.sign_outgoing = True
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def rtcm(n):
        # Every data byte non-zero: MAVLink 2 keeps the payload's 2 + n bytes.
        return enc.gps_rtcm_data_encode(0, n, [1 + i % 200 for i in range(n)] + [0] * (180 - n))

    frames = [bytes(enc.attitude_encode(7, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03).pack(enc)),
              bytes(rtcm(66).pack(enc)), bytes(rtcm(67).pack(enc)),
              bytes(signer.encapsulated_data_encode(9, [255 - i % 250 for i in range(253)]).pack(signer))]
    assert [len(f) for f in frames] == [40, 80, 81, 280]
    try:
        assert conn.recv_match(blocking=True, timeout=0) is None
        # A vehicle's HEARTBEAT makes system 1 the target, whose latest messages
        # `messages` holds.
        out.sendto(bytes(enc.heartbeat_encode(2, 3, 81, 4, 4).pack(enc)), ("127.0.0.1", port))
        assert conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5) is not None
        for f in frames:
            out.sendto(f, ("127.0.0.1", port))
            m = conn.recv_match(blocking=True, timeout=5)
            assert m is not None, len(f)
            assert bytes(m.get_msgbuf()) == f
            ref = apm.MAVLink(None)
            if len(f) == 280:
                ref.signing.secret_key = bytes(range(32))
            expected = ref.parse_char(f)
            assert m.to_dict() == expected.to_dict(), len(f)
            assert conn.messages[m.get_type()].get_msgbuf() == m.get_msgbuf()
    finally:
        out.close()
        conn.close()
