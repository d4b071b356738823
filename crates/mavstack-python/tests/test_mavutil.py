"""mavstack.mavutil against pymavlink's mavutil on the same files: every message equal field by
field, and the reader's edges (conditions, bad input)."""

import os
import random

import pytest

import mavstack
from mavstack import mavutil
from conftest import KEY, KEY_HEX, free_port, make_raw, norm, pymavlink_log, reference, write_tlog


def facts(m, timestamps=True):
    """What must be equal between pymavlink's message and ours."""
    h = m.get_header()
    out = {
        "type": m.get_type(),
        "id": m.get_msgId(),
        "sys": m.get_srcSystem(),
        "comp": m.get_srcComponent(),
        "seq": m.get_seq(),
        "signed": m.get_signed(),
        "crc": m.get_crc(),
        "msgbuf": bytes(m.get_msgbuf()),
        "header": (h.msgId, h.incompat_flags, h.compat_flags, h.mlen, h.seq, h.srcSystem, h.srcComponent),
        "fieldnames": list(m.get_fieldnames()),
        "ordered": list(m.ordered_fieldnames),
        "dict": norm(m.to_dict()),
        "attrs": norm([getattr(m, f) for f in m.get_fieldnames()]),
        "str": str(m),
    }
    if timestamps:
        out["ts"] = m._timestamp
        out["link"] = m._link
    return out


def check_same(path, dialect, key=None, raw=False, min_messages=100):
    pairs = reference(path, dialect, key=key, raw=raw)
    assert len(pairs) >= min_messages
    for i, (b, a, from_reader) in enumerate(pairs):
        fa, fb = facts(a, from_reader and not raw), facts(b, from_reader and not raw)
        assert fa == fb, "message %d differs:\npymavlink %s\nmavstack  %s" % (
            i, {k: v for k, v in fa.items() if fb.get(k) != v}, {k: v for k, v in fb.items() if fa.get(k) != v})
    log = mavutil.mavlink_connection(path, dialect=dialect, key=key)
    mine = list(log)
    assert len(mine) == len(pairs)
    return mine, log


def test_raw_ardupilotmega_with_garbage_unknown_ids_and_bad_crcs(corpora):
    mine, log = check_same(corpora["apm_raw"], "ardupilotmega", raw=True, min_messages=3000)
    s = log.stats()
    assert s["bad_crc"] > 0 and s["unknown_id"] > 0 and s["skipped_bytes"] > 0
    assert {m.get_type() for m in mine} >= {"HEARTBEAT", "ATTITUDE", "PARAM_VALUE", "STATUSTEXT"}
    assert all(m._timestamp == 0.0 for m in mine)


def test_raw_signed_frames_verified_with_the_key(corpora):
    mine, log = check_same(corpora["apm_raw"], "ardupilotmega", key=KEY, raw=True, min_messages=3000)
    s = log.stats()
    assert s["bad_signature"] > 0
    assert sum(m.get_signed() for m in mine) > 1000
    assert all(m.get_link_id() is not None for m in mine if m.get_signed())


def test_tlog_ardupilotmega_timestamps_and_link_bits(corpora):
    mine, _ = check_same(corpora["apm_tlog"], "ardupilotmega", min_messages=3000)
    assert {m._link for m in mine} == {0, 1, 2, 3}


def test_tlog_with_key_as_hex(corpora):
    mine, log = check_same(corpora["apm_tlog"], "ardupilotmega", key=KEY_HEX, min_messages=3000)
    assert log.stats()["bad_signature"] > 0


def test_tlog_of_every_message_of_all(corpora):
    mine, _ = check_same(corpora["all_tlog"], "all", min_messages=2000)
    import pymavlink.dialects.v20.all as alld
    assert len({m.get_msgId() for m in mine}) == len(alld.mavlink_map)


# Dialects without common.xml (no HEARTBEAT): the corpus writer needs MAV_TYPE; they load.
NO_COMMON = ("csAirLink", "icarous", "test")


@pytest.mark.parametrize("dialect", [d for d in mavstack.dialects() if d not in ("all", "ardupilotmega")])
def test_every_builtin_dialect(tmp_path, dialect):
    if dialect in NO_COMMON:
        empty = tmp_path / "empty.raw"
        empty.write_bytes(b"")
        assert mavutil.mavlink_connection(str(empty), dialect=dialect).dialect == dialect
        return
    raw = make_raw(str(tmp_path), dialect, dialect, 21, frames=300)
    check_same(raw, dialect, raw=True, min_messages=10)


def test_a_dialect_from_an_xml_file(corpora):
    import pymavlink
    xml = os.path.join(os.path.dirname(pymavlink.__file__), "dialects", "v20", "ardupilotmega.xml")
    a = [facts(m) for m in mavutil.mavlink_connection(corpora["apm_tlog"], dialect=xml)]
    b = [facts(m) for m in mavutil.mavlink_connection(corpora["apm_tlog"], dialect="ardupilotmega")]
    assert a == b and len(a) > 3000


def multi_system_log(path):
    """Two systems' ATTITUDE and HEARTBEAT, written by pymavlink (a tlog or, by the
    extension, raw frames)."""
    import pymavlink.dialects.v20.ardupilotmega as apm
    rng = random.Random(5)
    frames = []
    senders = {s: apm.MAVLink(None, srcSystem=s, srcComponent=1) for s in (1, 2)}
    for i in range(600):
        s = 1 + i % 2
        mav = senders[s]
        if i % 10 < 2:
            msg = apm.MAVLink_heartbeat_message(2, 3, 0x81 if i % 40 < 20 else 0x01, i, 4, 3)
        else:
            msg = apm.MAVLink_attitude_message(i, rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3), 0.1, 0, 0, 0)
        frames.append(msg.pack(mav))
        mav.seq = (mav.seq + 1) % 256
    if path.endswith(".raw"):
        with open(path, "wb") as f:
            f.write(b"".join(frames))
        return path
    return write_tlog(path, frames)


@pytest.mark.parametrize("condition,types", [
    ("ATTITUDE.roll > 0.1", "ATTITUDE"),
    ("HEARTBEAT.base_mode & 0x80 and ATTITUDE.pitch < 0", None),
    ("abs(ATTITUDE.roll) < 0.05 or HEARTBEAT.custom_mode % 7 == 0", ["ATTITUDE", "HEARTBEAT"]),
    ("ATTITUDE.roll / ATTITUDE.time_boot_ms > 0", None),
    ("NO_SUCH_MESSAGE.x > 0", None),
    (None, {"HEARTBEAT"}),
])
def test_recv_match_conditions_as_pymavlink(tmp_path, condition, types):
    # pymavlink's tlog reader (mavmmaplog) fills its table of latest messages ahead of the
    # reading (a condition sees a type's first message before it is read); its reader of
    # raw files, like ours, only what was read: compared on raw frames.
    path = multi_system_log(str(tmp_path / "two.raw"))
    def collect(log):
        out = []
        while (m := log.recv_match(condition=condition, type=types)) is not None:
            out.append((m.get_type(), m.get_srcSystem(), m.get_seq(), m.roll if m.get_type() == "ATTITUDE" else 0))
        return out
    theirs = collect(pymavlink_log(path, "ardupilotmega", raw=True))
    mine = collect(mavutil.mavlink_connection(path))
    assert mine == theirs
    if condition != "NO_SUCH_MESSAGE.x > 0":
        assert mine


def test_messages_holds_the_latest_of_each_type(tmp_path):
    path = multi_system_log(str(tmp_path / "two.raw"))
    log = mavutil.mavlink_connection(path)
    ref = pymavlink_log(path, "ardupilotmega", raw=True)
    for _ in range(57):
        log.recv_msg()
        ref.recv_msg()
    assert set(log.messages.keys()) == {k for k in ref.messages if k not in ("MAV", "HOME")}
    assert facts(log.messages["ATTITUDE"], False) == facts(ref.messages["ATTITUDE"], False)
    assert "HEARTBEAT" in log.messages and "GPS_RAW_INT" not in log.messages
    assert log.messages.get("GPS_RAW_INT") is None
    with pytest.raises(KeyError):
        log.messages["GPS_RAW_INT"]
    log.rewind()
    assert len(log.messages) == 0 and log.recv_msg().get_seq() == 0


def test_mavproxy_written_tlog(tmp_path):
    """A tlog MAVProxy wrote (two masters, its own link numbers in the timestamps' low bits)
    reads as pymavlink reads it."""
    import socket
    import subprocess
    import sys
    import time
    import pymavlink.dialects.v20.ardupilotmega as apm

    ports = [free_port(), free_port()]
    exe = os.path.join(os.path.dirname(sys.executable), "mavproxy.py")
    log_path = str(tmp_path / "mav.tlog")
    env = dict(os.environ, HOME=str(tmp_path))
    p = subprocess.Popen([sys.executable, exe, "--master=udpin:127.0.0.1:%d" % ports[0],
                          "--master=udpin:127.0.0.1:%d" % ports[1], "--logfile=" + log_path,
                          "--daemon", "--non-interactive", "--default-modules=", "--cmd=set flushlogs 1",
                          "--state-basedir=" + str(tmp_path)],
                         cwd=str(tmp_path), env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in ports]
        mavs = [apm.MAVLink(None, srcSystem=s, srcComponent=1) for s in (1, 2)]
        deadline = time.time() + 30
        sent = 0
        while time.time() < deadline:
            for i, (sock, mav) in enumerate(zip(socks, mavs)):
                msgs = [apm.MAVLink_heartbeat_message(2, 3, 0x81, sent, 4, 3),
                        apm.MAVLink_attitude_message(sent, 0.01 * i, 0.2, 0.3, 0, 0, 0)]
                for m in msgs:
                    sock.sendto(m.pack(mav), ("127.0.0.1", ports[i]))
                    mav.seq = (mav.seq + 1) % 256
            sent += 1
            time.sleep(0.05)
            if sent > 40 and os.path.exists(log_path) and os.path.getsize(log_path) > 8000:
                break
    finally:
        p.terminate()
        p.wait(timeout=20)
    pairs = reference(log_path, "ardupilotmega")
    assert len(pairs) > 100 and all(r for _, _, r in pairs)
    assert [facts(m) for m, _, _ in pairs] == [facts(t) for _, t, _ in pairs]
    links = {m._link for m, _, _ in pairs}
    assert {0, 1} <= links, links


def test_bad_input_is_counted_never_raised(tmp_path, corpora):
    data = open(corpora["apm_tlog"], "rb").read()
    cut = tmp_path / "cut.tlog"
    cut.write_bytes(data[: len(data) // 2 + 13])
    whole = list(mavutil.mavlink_connection(corpora["apm_tlog"]))
    log = mavutil.mavlink_connection(str(cut))
    part = list(log)
    assert 0 < len(part) < len(whole)
    assert [bytes(m.get_msgbuf()) for m in part] == [bytes(m.get_msgbuf()) for m in whole[: len(part)]]
    assert log.stats()["skipped_bytes"] > 0
    # A damaged middle: only the damaged records are lost.
    bad = bytearray(data)
    rng = random.Random(9)
    for at in rng.sample(range(len(bad)), 40):
        bad[at] ^= 0xFF
    damaged = tmp_path / "damaged.tlog"
    damaged.write_bytes(bytes(bad))
    got = list(mavutil.mavlink_connection(str(damaged)))
    assert len(whole) - 40 <= len(got) <= len(whole)
    def unsigned_part(m):
        # Without a key a signature is not checked: a damaged one is not noticed.
        b = bytes(m.get_msgbuf())
        return b[:-13] if b[0] == 0xFD and b[2] & 1 else b
    wanted = {unsigned_part(m) for m in whole}
    assert all(unsigned_part(m) in wanted for m in got)
    # Garbage and an empty file.
    noise = tmp_path / "noise.raw"
    noise.write_bytes(bytes(random.Random(1).randrange(256) for _ in range(200_000)))
    log = mavutil.mavlink_connection(str(noise))
    list(log)
    assert log.stats()["skipped_bytes"] > 100_000
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    assert list(mavutil.mavlink_connection(str(empty))) == []


def test_a_wrong_key_drops_every_signed_frame(corpora):
    log = mavutil.mavlink_connection(corpora["apm_tlog"], key=bytes(32))
    mine = list(log)
    assert not any(m.get_signed() for m in mine)
    assert all(not (m.get_msgbuf()[0] == 0xFD and m.get_msgbuf()[2] & 1) for m in mine)
    assert log.stats()["bad_signature"] == log.stats()["signed"] > 1000


def test_clear_errors(tmp_path, corpora):
    with pytest.raises(ValueError, match="no_such_dialect"):
        mavutil.mavlink_connection(corpora["apm_tlog"], dialect="no_such_dialect")
    with pytest.raises(OSError, match="missing.tlog"):
        mavutil.mavlink_connection(str(tmp_path / "missing.tlog"))
    with pytest.raises(ValueError, match="32 bytes"):
        mavutil.mavlink_connection(corpora["apm_tlog"], key=b"short")
    with pytest.raises(ValueError, match="key"):
        mavutil.mavlink_connection(corpora["apm_tlog"], key="zz" * 32)
    with pytest.raises(ValueError, match="reads logs"):
        mavutil.mavlink_connection(corpora["apm_tlog"], write=True)
    with pytest.raises(TypeError, match="bogus"):
        mavutil.mavlink_connection(corpora["apm_tlog"], bogus=1)
    m = mavutil.mavlink_connection(corpora["apm_tlog"]).recv_match(type="ATTITUDE")
    with pytest.raises(AttributeError, match="no_field"):
        m.no_field
    bad_xml = tmp_path / "bad.xml"
    bad_xml.write_text("<mavlink><messages><message id='x' name='A'></message></messages></mavlink>")
    with pytest.raises(ValueError, match="bad.xml"):
        mavutil.mavlink_connection(corpora["apm_tlog"], dialect=str(bad_xml))
