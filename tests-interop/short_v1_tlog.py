#!/usr/bin/env python3
"""Write a tlog with pymavlink's `mavlogfile` that holds MAVLink 1 frames with payloads under
4 bytes (10 and 11 bytes long), the frames pymavlink's own reader mishandles, and print what
each record holds, the expectation of any reader that loses nothing.

Usage:
  short_v1_tlog.py OUT.tlog [--records N] [--seed S]

The log is written as a pymavlink program writes one: `mavutil.mavlogfile(OUT, write=True)`,
whose `mav` (the ardupilotmega dialect, MAVLink 2) packs and sends each message through the
log file, after the record's 8-byte big-endian timestamp written to the same file. The
records mix MAVLink 2 frames (some signed), long MAVLink 1 frames and short MAVLink 1 frames
(PARAM_REQUEST_LIST, MISSION_ITEM_REACHED, EXTENDED_SYS_STATE, LOG_REQUEST_END: 2-byte
payloads; HWSTATUS, GOPRO_HEARTBEAT, CHANGE_OPERATOR_CONTROL_ACK, FENCE_FETCH_POINT: 3 bytes),
many of the short ones right after a MAVLink 2 frame. The first record is a MAVLink 2
HEARTBEAT, the last a short MAVLink 1 frame.

Prints one JSON object per record, in file order:
  {"ts_us": N, "frame": "<hex>", "type": NAME, "version": 1|2, "seq": N, "sysid": N,
   "compid": N, "msgid": N, "short_v1": bool}
where `frame` is the frame pymavlink packed (`get_msgbuf()`) and `short_v1` says whether it is
a MAVLink 1 frame with a payload under 4 bytes.

Why pymavlink's reader (`mavlogfile.recv_msg`) loses the record after such a frame when a
MAVLink 2 frame came before it: after a frame its parser expects `header + 2` bytes for the
next (12 after MAVLink 2), and `bytes_needed()` asks the file for that many before it has seen
the next frame's length byte. A MAVLink 1 frame with a payload under 4 bytes is shorter than
12 bytes, so the read takes the first bytes of the next record's timestamp too. They stay in
the parser's buffer; the next timestamp is read from the wrong place and the next frame starts
with those leftover bytes, which are damage (BAD_DATA): the next record is lost.
"""

import argparse
import json
import os
import random
import struct
import sys

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

mavutil.set_dialect("ardupilotmega")
mav = mavutil.mavlink

START_US = 1_765_000_000_000_000
KEY = bytes(range(32))


def short_message(rng, i):
    """A message whose MAVLink 1 payload is 2 or 3 bytes."""
    k = rng.randrange(8)
    if k == 0:
        return mav.MAVLink_param_request_list_message(1, 1)
    if k == 1:
        return mav.MAVLink_mission_item_reached_message(i)
    if k == 2:
        return mav.MAVLink_extended_sys_state_message(rng.randrange(5), rng.randrange(5))
    if k == 3:
        return mav.MAVLink_log_request_end_message(1, 1)
    if k == 4:
        return mav.MAVLink_hwstatus_message(4900 + rng.randrange(200), rng.randrange(4))
    if k == 5:
        return mav.MAVLink_gopro_heartbeat_message(rng.randrange(3), rng.randrange(4), 0)
    if k == 6:
        return mav.MAVLink_change_operator_control_ack_message(255, 0, rng.randrange(3))
    return mav.MAVLink_fence_fetch_point_message(1, 1, rng.randrange(10))


def long_message(rng, i):
    k = rng.randrange(5)
    if k == 0:
        return mav.MAVLink_heartbeat_message(2, 3, 81, rng.randrange(1 << 16), 4, 3)
    if k == 1:
        return mav.MAVLink_attitude_message(i, rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-3, 3),
                                            0.01, 0.02, 0.0)
    if k == 2:
        return mav.MAVLink_global_position_int_message(i, -353632620 + rng.randrange(1000), 1491652370,
                                                       584000, 10000, 0, 0, 0, rng.randrange(36000))
    if k == 3:
        return mav.MAVLink_statustext_message(6, ("check %d" % i).encode(), 0, 0)
    return mav.MAVLink_sys_status_message(1, 1, 1, 500, 12000, -1, 80, 0, 0, 0, 0, 0, 0)


def plan(rng, n):
    """(kind, message) per record: kind "v2", "v2s" (signed), "v1" or "short"."""
    out = [("v2", mav.MAVLink_heartbeat_message(2, 3, 81, 0, 4, 3))]
    while len(out) < n - 1:
        r = rng.random()
        i = len(out)
        if r < 0.25:
            # The case pymavlink loses: a short MAVLink 1 frame right after a MAVLink 2 one.
            out.append(("v2", long_message(rng, i)))
            out.append(("short", short_message(rng, i + 1)))
        elif r < 0.35:
            out.append(("short", short_message(rng, i)))
        elif r < 0.5:
            out.append(("v1", long_message(rng, i)))
        elif r < 0.6:
            out.append(("v2s", long_message(rng, i)))
        else:
            out.append(("v2", long_message(rng, i)))
    out = out[: n - 1]
    out.append(("short", short_message(rng, n)))
    return out


def write(path, n, seed):
    rng = random.Random(seed)
    open(path, "wb").close()
    log = mavutil.mavlogfile(path, write=True, source_system=1, source_component=1)
    log.mav.signing.secret_key = KEY
    log.mav.signing.link_id = 1
    log.mav.signing.timestamp = 1
    rows = []
    for i, (kind, msg) in enumerate(plan(rng, n)):
        ts = START_US + i * 20_000 + rng.randrange(1000)
        log.write(struct.pack(">Q", ts))
        log.mav.signing.sign_outgoing = kind == "v2s"
        log.mav.send(msg, force_mavlink1=kind in ("v1", "short"))
        frame = bytes(msg.get_msgbuf())
        v1 = frame[0] == 0xFE
        if v1:
            head = (1, frame[2], frame[3], frame[4], frame[5])
        else:
            head = (2, frame[4], frame[5], frame[6], frame[7] | frame[8] << 8 | frame[9] << 16)
        assert (kind == "short") == (v1 and frame[1] < 4), (kind, frame.hex())
        rows.append({"ts_us": ts, "frame": frame.hex(), "type": msg.get_type(), "version": head[0],
                     "seq": head[1], "sysid": head[2], "compid": head[3], "msgid": head[4],
                     "short_v1": kind == "short"})
    log.close()
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--records", type=int, default=500)
    ap.add_argument("--seed", type=int, default=39)
    args = ap.parse_args()
    rows = write(args.out, args.records, args.seed)
    with open(args.out, "rb") as fh:
        data = fh.read()
    # The file is exactly the records, one after another.
    assert data == b"".join(struct.pack(">Q", r["ts_us"]) + bytes.fromhex(r["frame"]) for r in rows)
    for r in rows:
        print(json.dumps(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
