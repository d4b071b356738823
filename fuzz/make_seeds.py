#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets whose seeds come from pymavlink (the peer):
json_frames, tlog, services and bridge. Run with the project's virtualenv (scripts/setup-peers.sh):

    .venv/bin/python fuzz/make_seeds.py

The JSON lines are pymavlink's own decoding of frames it packed (tests-interop/make_corpus.py),
the tlog records are frames pymavlink packed with timestamps, some damaged; the service
records are messages pymavlink packed, in the record format of
mavstack_services::fuzz_services: [control, sysid, compid, id index, len, payload].
Deterministic: the same files every run.
"""
import os
import random
import struct
import subprocess
import sys
import tempfile

from pymavlink.dialects.v20 import common as mav

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.join(HERE, "corpus")
# The order of mavstack_services::fuzzing::IDS.
IDS = [0, 20, 21, 22, 23, 39, 40, 41, 42, 43, 44, 45, 46, 47, 51, 73, 75, 76, 77, 111, 148, 244, 300, 30]


def write(target, name, data):
    folder = os.path.join(CORPUS, target)
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, name), "wb") as f:
        f.write(data)


def packer():
    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    m.robust_parsing = True
    return m


def json_frame_seeds(rng):
    with tempfile.TemporaryDirectory() as tmp:
        prefix = os.path.join(tmp, "c")
        key = "5a" * 32
        subprocess.run(
            [sys.executable, os.path.join(HERE, "..", "tests-interop", "make_corpus.py"), prefix,
             "--dialect", "ardupilotmega", "--seed", "11", "--frames", "300", "--key", key],
            check=True, capture_output=True)
        with open(prefix + ".jsonl", "rb") as f:
            lines = f.read().splitlines()
    picked = rng.sample(lines, 48)
    for i in range(0, len(picked), 2):
        write("json_frames", "pymavlink_%02d" % (i // 2), b"\n".join(picked[i:i + 2]) + b"\n")
    hand = [
        b'{"name":"HEARTBEAT","fields":{"type":2,"autopilot":3,"base_mode":81}}',
        b'{"msgid":30,"version":1,"fields":{"roll":"NaN","pitch":"inf","yaw":"-inf"}}',
        b'{"name":"STATUSTEXT","fields":{"severity":6,"text":"caf\\u00e9 \\u0000 tail"}}',
        b'{"name":"PARAM_SET","fields":{"param_id":"RTL_ALT","param_value":1500.0}}',
        b'{"name":"COMMAND_LONG","seq":9,"sysid":3,"compid":4,"fields":{"command":400,"param1":1}}',
        b'{"name":"GPS_RAW_INT","version":1,"fields":{"fix_type":3,"alt_ellipsoid":12}}',
        b'{"name":"HEARTBEAT","signature":{"link_id":7,"timestamp":281474976710655}}',
        b'{"name":"NOPE"}\n{"msgid":99999999}\n{"fields":{}}\n{"name":"HEARTBEAT","fields":{"type":300}}',
    ]
    for i, line in enumerate(hand):
        write("json_frames", "hand_%02d" % i, line + b"\n")


def tlog_seeds(rng):
    m = packer()
    frames = [
        m.heartbeat_encode(2, 3, 81, 0, 4, 3).pack(m),
        m.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(m),
        m.attitude_encode(1000, 0.1, -0.2, 3.0, 0, 0, 0).pack(m),
        m.heartbeat_encode(2, 3, 81, 0, 4, 3).pack(m, force_mavlink1=True),
    ]
    ts = 1_700_000_000_000_000
    clean = b"".join(struct.pack(">Q", ts + i * 250_000) + f for i, f in enumerate(frames * 3))
    write("tlog", "clean", clean)
    damaged = bytearray(clean)
    for _ in range(6):
        damaged[rng.randrange(len(damaged))] ^= 1 << rng.randrange(8)
    write("tlog", "bit_flips", bytes(damaged))
    write("tlog", "garbage_between", clean[:60] + bytes(rng.randrange(256) for _ in range(40)) + clean[60:])
    write("tlog", "truncated", clean[:-7])
    write("tlog", "short", clean[:11])


def record(control, sysid, compid, msg, m):
    packed = msg.pack(m)
    if packed[0] == 0xFD:
        payload = packed[10:10 + packed[1]]
        msgid = packed[7] | packed[8] << 8 | packed[9] << 16
    else:
        payload = packed[6:6 + packed[1]]
        msgid = packed[5]
    return bytes([control, sysid, compid, IDS.index(msgid), len(payload)]) + payload


def services_seeds(rng):
    m = packer()
    gcs = (255, 190)
    seeds = {
        "param_fetch": [
            (0x11, *gcs, m.param_request_list_encode(1, 1)),
            (0x01, 1, 1, m.param_value_encode(b"RTL_ALT", 1500, 9, 3, 0)),
            (0x0f, 1, 1, m.param_value_encode(b"WPNAV_SPEED", 500, 9, 3, 2)),
            (0x0f, *gcs, m.param_set_encode(1, 1, b"RTL_ALT", 3000, 9)),
            (0x01, *gcs, m.param_request_read_encode(1, 1, b"", 1)),
        ],
        "param_huge_count": [
            (0x11, 1, 1, m.param_value_encode(b"X", 1, 9, 65535, 65534)),
            (0x0f, 1, 1, m.param_value_encode(b"Y", 1, 9, 65535, 3)),
        ],
        "mission_upload_to_vehicle": [
            (0x01, *gcs, m.mission_count_encode(1, 1, 2, 0)),
            (0x01, *gcs, m.mission_item_int_encode(1, 1, 0, 3, 16, 0, 1, 0, 0, 0, 0, 1, 2, 3, 0)),
            (0x01, *gcs, m.mission_item_int_encode(1, 1, 1, 3, 16, 0, 1, 0, 0, 0, 0, 1, 2, 3, 0)),
            (0x01, *gcs, m.mission_request_list_encode(1, 1, 0)),
            (0x01, *gcs, m.mission_request_int_encode(1, 1, 1, 0)),
            (0x01, *gcs, m.mission_ack_encode(1, 1, 0, 0)),
        ],
        "mission_huge_count": [
            (0x01, 9, 9, m.mission_count_encode(1, 1, 65535, 0)),
            (0x0f, 9, 9, m.mission_item_encode(1, 1, 0, 3, 16, 0, 1, 0, 0, 0, 0, 1, 2, 3, 0)),
        ],
        "mission_download": [
            (0x21, 1, 1, m.mission_count_encode(255, 190, 3, 0)),
            (0x01, 1, 1, m.mission_item_int_encode(255, 190, 0, 3, 16, 0, 1, 0, 0, 0, 0, 1, 2, 3, 0)),
            (0x0f, 1, 1, m.mission_item_int_encode(255, 190, 2, 3, 16, 0, 1, 0, 0, 0, 0, 1, 2, 3, 0)),
        ],
        "commands": [
            (0x41, *gcs, m.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)),
            (0x01, *gcs, m.command_long_encode(1, 1, 511, 0, 30, 100000, 0, 0, 0, 0, 0)),
            (0x01, *gcs, m.command_int_encode(1, 1, 0, 176, 0, 0, 1, 4, 0, 0, 0, 0, 0)),
            (0x05, 1, 1, m.command_ack_encode(400, 0)),
            (0x01, *gcs, m.command_long_encode(1, 1, 512, 0, 300, 0, 0, 0, 0, 0, 0)),
        ],
        "peers": [
            (0x01, 1, 1, m.heartbeat_encode(2, 3, 81, 0, 4, 3)),
            (0x01, 2, 1, m.heartbeat_encode(1, 12, 0, 0, 4, 3)),
            (0x0f, 1, 1, m.autopilot_version_encode(0xffff, 0, 0, 0, 0, b"\0" * 8, b"\0" * 8, b"\0" * 8, 0, 0, 0)),
            (0x0f, 3, 1, m.timesync_encode(0, 123456)),
            (0x0f, 1, 1, m.timesync_encode(99, 0)),
            (0x01, 1, 1, m.attitude_encode(1, 0, 0, 0, 0, 0, 0)),
            (0x0f, 2, 1, m.heartbeat_encode(1, 12, 0, 0, 4, 3)),
        ],
    }
    for name, records in seeds.items():
        write("services", name, b"".join(record(c, s, k, msg, m) for c, s, k, msg in records))
    for i in range(4):
        write("services", "random_%d" % i, bytes(rng.randrange(256) for _ in range(300)))


def bridge_seeds(rng):
    """mavstack_bridge::fuzzing::fuzz_bridge: a part byte, then its input. Link strings and
    topics as users and brokers write them; command and remap records (op byte, then six
    bytes, or for raw frames a length byte and the frame) around frames pymavlink packed."""
    links = [
        "mqtt://127.0.0.1:1883?fleet=demo&vid=truck-7",
        "mqtt://broker:1883?fleet=f&vid=*&user=ops&password=s3cret-pass",
        "mqtt://[::1]:1883?fleet=f&vid=a,b&trusted=true&name=cloud",
        "mqtt://h?fleet=f&vid=v&side=ground&client_id=c1",
        "mqtt://h:0?fleet=f&vid=v",
        "mqtts://h:8883?fleet=f&vid=v",
        "zenoh://127.0.0.1:7447?fleet=f&vid=v",
        "zenoh:?fleet=f&vid=v",
        "mqtt://h:1883?fleet=f&vid=v&key=00&password=p",
    ]
    for i, text in enumerate(links):
        write("bridge", "link_%d" % i, b"\x00" + text.encode())
    topics = ["mav/f/v/in", "mav/f/v/1/1/@cmd", "mav/f/v/255/190/@cmd", "mav/f/v/01/1/@cmd",
              "mav/f/v9/1/1/ATTITUDE", "mav/f/v9/@alive", "mav/f/v9/1/1/99999", "mav/f/+/1/1/X"]
    for i, text in enumerate(topics):
        write("bridge", "topic_%d" % i, b"\x01" + text.encode())
    m = packer()
    raw = [
        m.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(m),
        m.command_int_encode(1, 1, 0, 400, 0, 0, 0, 0, 0, 0, 0, 0, 0).pack(m),
        m.command_ack_encode(400, 0).pack(m),
        m.heartbeat_encode(2, 3, 0, 0, 4, 3).pack(m),
    ]

    def raw_record(op, frame):
        return bytes([op, len(frame) - 1]) + frame

    # Requests, acks and time, as the tracker meets them: a request and its ack, a request
    # left to time out, raw frames.
    write("bridge", "commands_ack", b"\x02" + bytes([0, 1, 1, 1, 1, 0, 0, 2, 1, 1, 1, 0, 0, 0]))
    write("bridge", "commands_timeout", b"\x02" + bytes([0, 1, 1, 1, 1, 0, 0] + [4, 60, 0, 0, 0, 0, 0] * 6))
    write("bridge", "commands_in_progress", b"\x02" + bytes([1, 1, 1, 1, 1, 1, 0, 2, 1, 1, 1, 0, 0, 5, 4, 100, 0, 0, 0, 0, 0]))
    write("bridge", "commands_raw", b"\x02" + raw_record(6, raw[0]) + raw_record(7, raw[2]) + raw_record(6, raw[1]))
    # Vehicles sharing sysid 1, frames to them, raw frames.
    write("bridge", "remap_shared", b"\x03" + bytes([0, 0, 1, 0, 1, 0, 0, 0, 1, 1, 1, 0, 0, 0, 0, 2, 1, 2, 1, 0, 0]))
    write("bridge", "remap_to", b"\x03" + bytes([0, 0, 1, 0, 1, 0, 0, 0, 1, 1, 1, 0, 0, 0, 0x83, 1, 1, 2, 1, 0, 0]))
    write("bridge", "remap_raw", b"\x03" + b"".join(raw_record(6 + (i % 2), f) for i, f in enumerate(raw)))
    # The same frames with one payload byte flipped (their checksums fail): requests and an ACK
    # the tracker must refuse, frames the remap must drop; then built ones damaged (op bit 6).
    def flipped(frame):
        b = bytearray(frame)
        b[12] ^= 0x01
        return bytes(b)

    write("bridge", "commands_corrupt", b"\x02" + raw_record(6, flipped(raw[0])) + raw_record(6, flipped(raw[1])) +
          bytes([0, 1, 1, 1, 1, 0, 0]) + raw_record(7, flipped(raw[2])) + bytes([0x40, 1, 1, 1, 1, 9, 0]))
    write("bridge", "remap_corrupt", b"\x03" + bytes([0, 0, 1, 0, 1, 0, 0]) +
          b"".join(raw_record(6 + (i % 2), flipped(f)) for i, f in enumerate(raw)) + bytes([0x41, 1, 1, 2, 1, 12, 0]))
    for i in range(2):
        write("bridge", "random_%d" % i, bytes([2 + i]) + bytes(rng.randrange(256) for _ in range(200)))


def main():
    rng = random.Random(20261202)
    json_frame_seeds(rng)
    tlog_seeds(rng)
    services_seeds(rng)
    bridge_seeds(rng)


if __name__ == "__main__":
    main()
