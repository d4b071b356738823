#!/usr/bin/env python3
"""A damaged tlog and a damaged raw stream, read by pymavlink and by mavstack: mavstack must
return exactly the frames pymavlink returns, in its order, with its timestamps, and the valid
records pymavlink loses after short MAVLink 1 frames as well.

Usage:
  tlog_damage.py --mavstack BIN [--records N] [--seed S] [--out DIR] [--python]

The corpus is written with pymavlink's encoder (ardupilotmega, MAVLink 2 and MAVLink 1,
MAVLink 1 frames with payloads of 2 and 3 bytes right after MAVLink 2 ones, signed frames with
a key, an id above 255). One record in ten is damaged, one kind of damage per record, every
kind in turn:
  payload bit flip, checksum bit flip, length byte flip (shorter and longer), incompat flags
  flip, message id flip (each of its three bytes), start marker flip, sequence/sysid flip,
  an unknown message id (a frame whose id no dialect defines, checksum of a made-up
  CRC_EXTRA), garbage between two records, a timestamp bit flip; and the last record is cut
  short.

The oracle is pymavlink itself: `mavutil.mavlink_connection(path)` (for a log file a
`mavmmaplog`: an indexing walk, then `mavlogfile`'s robust reading; pymavlink's default dialect
`all`, MAVLINK_DIALECT picks another) read to the end; every message that is not BAD_DATA is
a frame it returns, with `_timestamp`. With one mend, where pymavlink loses valid records and
mavstack must not (`short_v1_frames_read_whole`): a MAVLink 1 frame right after its timestamp
is read exactly as long as it is, where pymavlink's parser asks for more (12 bytes after a
MAVLink 2 frame; a MAVLink 1 frame with a payload under 4 bytes is 8 to 11 bytes long) and so
takes the next record's first timestamp bytes with it and loses that record. The script
prints what pymavlink's own reading and the mended one return, and checks the mended case
itself: wherever both return an intact MAVLink 2 record and then the intact short MAVLink 1
record after it, pymavlink's own loses the intact record that follows, and the mended
reading returns it. (Past damage the two readings can part ways: a read that lands on
a 0xFE byte followed by a small one takes only the few bytes that "frame" claims, and the two
then slide over different bytes.) mavstack is then checked, each against the mended list:
  - `mavstack decode --dialect all --keep-unknown FILE.tlog` (JSON lines): the same
    frames (header, signature timestamp and record timestamp), unknown ids included;
  - with --python, the mavstack Python package (`mavstack.mavutil.mavlink_connection`): the
    same frames of known messages (it returns no unknown ids), same bytes, same `_timestamp`.
The raw stream (the same frames without timestamps) is read by pymavlink's parser
(`parse_char` fed as `mavlogfile` with notimestamps feeds it) and by `mavstack decode` on the
.bin: every frame pymavlink returns must be among mavstack's, in order (mavstack's stream
parser resynchronises after a damaged frame at the next byte, so it may find more).
Exit status 0 when all agree; a summary line per check either way.
"""

import argparse
import contextlib
import io
import json
import os
import random
import struct
import subprocess
import sys
import tempfile

os.environ.setdefault("MAVLINK20", "1")
# pymavlink's mavutil reads with the `all` dialect unless told otherwise; mavstack is given
# the same (--dialect), so "known message" means the same on both sides.
DIALECT = os.environ.setdefault("MAVLINK_DIALECT", "all")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mav  # noqa: E402

KEY = bytes(range(32))
START_US = 1_764_000_000_000_000
DAMAGE = [
    "payload", "checksum", "length_down", "length_up", "incompat", "msgid0", "msgid1", "msgid2",
    "magic", "header", "unknown_id", "garbage", "timestamp",
]


class Sink:
    def __init__(self):
        self.buf = b""

    def write(self, b):
        self.buf += b


def encoders():
    plain = mav.MAVLink(Sink(), srcSystem=1, srcComponent=1)
    signed = mav.MAVLink(Sink(), srcSystem=1, srcComponent=1)
    signed.signing.secret_key = KEY
    signed.signing.sign_outgoing = True
    signed.signing.link_id = 1
    signed.signing.timestamp = 1
    return plain, signed


def message(rng, i):
    k = i % 7
    if k == 0:
        return mav.MAVLink_heartbeat_message(2, 3, 81, rng.randrange(1 << 16), 4, 3)
    if k == 1:
        return mav.MAVLink_attitude_message(i, rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-3, 3),
                                            0.01, 0.02, 0.0)
    if k == 2:
        return mav.MAVLink_global_position_int_message(i, -353632620 + rng.randrange(1000), 1491652370,
                                                       584000, 10000, 0, 0, 0, rng.randrange(36000))
    if k == 3:
        return mav.MAVLink_statustext_message(6, ("PreArm: check %d" % i).encode(), 0, 0)
    if k == 4:
        return mav.MAVLink_param_value_message(b"RTL_ALT", float(i % 5000), 4, 1354, i % 1354)
    if k == 5:
        return mav.MAVLink_gimbal_manager_status_message(i, 0, 1, 255, 190, 0, 0)
    return mav.MAVLink_sys_status_message(1, 1, 1, 500, 12000, -1, 80, 0, 0, 0, 0, 0, 0)


def short_message(rng, i):
    """A message whose MAVLink 1 payload is 2 or 3 bytes (a frame of 10 or 11 bytes)."""
    k = i % 4
    if k == 0:
        return mav.MAVLink_param_request_list_message(1, 1)
    if k == 1:
        return mav.MAVLink_hwstatus_message(4900 + rng.randrange(200), rng.randrange(4))
    if k == 2:
        return mav.MAVLink_extended_sys_state_message(rng.randrange(5), rng.randrange(5))
    return mav.MAVLink_gopro_heartbeat_message(rng.randrange(3), rng.randrange(4), 0)


def pack(rng, i, plain, signed):
    plain.seq = i % 256
    if i % 17 == 9:
        # Right after a MAVLink 2 frame (record i - 1 is one): the frame pymavlink's reader
        # reads too much after.
        return short_message(rng, i).pack(plain, force_mavlink1=True)
    msg = message(rng, i)
    if i % 11 == 3 and msg.id < 256:
        return msg.pack(plain, force_mavlink1=True)
    if i % 13 == 5:
        return msg.pack(signed)
    return msg.pack(plain)


def damage(rng, kind, frame):
    f = bytearray(frame)
    v2 = f[0] == 0xFD
    hl = 10 if v2 else 6
    if kind == "payload":
        f[hl + rng.randrange(max(1, f[1]))] ^= 1 << rng.randrange(8)
    elif kind == "checksum":
        f[hl + f[1] + rng.randrange(2)] ^= 1 << rng.randrange(8)
    elif kind == "length_down":
        f[1] ^= 1 << rng.randrange(max(1, f[1].bit_length()))
        f[1] = min(f[1], frame[1])
    elif kind == "length_up":
        f[1] |= 1 << rng.randrange(5, 8)
    elif kind == "incompat":
        if v2:
            f[2] ^= 1 << rng.randrange(1, 8)
        else:
            f[2] ^= 1 << rng.randrange(8)
    elif kind.startswith("msgid"):
        at = (7 + int(kind[-1])) if v2 else 5
        f[at] ^= 1 << rng.randrange(8)
    elif kind == "magic":
        f[0] ^= 1 << rng.randrange(8)
    elif kind == "header":
        f[4 if v2 else 2] ^= 1 << rng.randrange(8)
    return bytes(f)


def unknown_frame(rng, i):
    payload = bytes(rng.randrange(256) for _ in range(12))
    body = struct.pack("<BBBBBBHB", len(payload), 0, 0, i % 256, 1, 1, 0xF000 + (i % 0xFF), 0x7F) + payload
    crc = mavutil.x25crc(body)
    crc.accumulate(bytes([rng.randrange(256)]))
    return b"\xfd" + body + struct.pack("<H", crc.crc)


def write_corpus(path, raw_path, n, seed, damage_kinds):
    """Writes the tlog and the raw stream; returns the count of each kind of damage and the
    records, in order, as (timestamp in seconds as pymavlink gives it, frame, intact)."""
    rng = random.Random(seed)
    plain, signed = encoders()
    out = bytearray()
    raw = bytearray()
    kinds = {}
    records = []
    for i in range(n):
        ts = START_US + i * 20_000 + rng.randrange(1000)
        frame = pack(rng, i, plain, signed)
        kind = None
        if i % 10 == 7 and i > 0:
            kind = damage_kinds[(i // 10) % len(damage_kinds)]
            kinds[kind] = kinds.get(kind, 0) + 1
        if kind == "unknown_id":
            frame = unknown_frame(rng, i)
        elif kind == "garbage":
            junk = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
            out += junk
            raw += junk
        elif kind == "timestamp":
            ts ^= 1 << rng.randrange(64)
        elif kind is not None:
            frame = damage(rng, kind, frame)
        out += struct.pack(">Q", ts) + frame
        raw += frame
        records.append((ts * 1.0e-6, frame, kind is None))
    # The last record cut short.
    last = pack(rng, n, plain, signed)
    out += struct.pack(">Q", START_US + n * 20_000) + last[: len(last) // 2]
    raw += last[: len(last) // 2]
    with open(path, "wb") as fh:
        fh.write(out)
    with open(raw_path, "wb") as fh:
        fh.write(raw)
    return kinds, records


def quietly(read):
    """Runs `read` with pymavlink's prints about what it skipped kept off the output."""
    with contextlib.redirect_stdout(io.StringIO()):
        return read()


def pymavlink_tlog(path, mended=True):
    """(timestamp, frame bytes, known) for every message pymavlink's reader returns; `mended`,
    with `short_v1_frames_read_whole`."""
    if not mended:
        return quietly(lambda: _pymavlink_tlog(path))
    with short_v1_frames_read_whole():
        return quietly(lambda: _pymavlink_tlog(path))


@contextlib.contextmanager
def short_v1_frames_read_whole():
    """pymavlink's reader with its one loss of valid records mended, and nothing else changed:
    when its parser's buffer is empty (a frame starts right after its timestamp) and
    `bytes_needed()` asks for more bytes than the MAVLink 1 frame there is long, only the
    frame is read. Unmended, the read goes on into the next record, whose first timestamp
    bytes stay in the parser's buffer: the next timestamp is read from the wrong place and the
    next frame is BAD_DATA. mavstack reads such a record like any other (shared/DESIGN.md)."""
    original = mavutil.mavlogfile.recv

    def recv(self, n=None):
        if n is None:
            n = self.mav.bytes_needed()
        if self.mav.buf_len() == 0:
            at = self.f.tell()
            head = self.f.read(2)
            self.f.seek(at)
            if len(head) == 2 and head[0] == 0xFE and head[1] + 8 < n:
                n = head[1] + 8
        return original(self, n)

    mavutil.mavlogfile.recv = recv
    try:
        yield
    finally:
        mavutil.mavlogfile.recv = original


def messages(conn):
    """Every message `conn.recv_msg()` returns, to the first None (the end of the file)."""
    while True:
        m = conn.recv_msg()
        if m is None:
            return
        yield m


def _pymavlink_tlog(path):
    return [(m._timestamp, bytes(m.get_msgbuf()), not m.get_type().startswith("UNKNOWN_"))
            for m in messages(mavutil.mavlink_connection(path)) if m.get_type() != "BAD_DATA"]


def pymavlink_raw(path):
    """Frame bytes of every known message pymavlink's parser returns from a raw stream (the
    frames of unknown ids it returns there are mostly damage it cannot check)."""
    return quietly(lambda: _pymavlink_raw(path))


def _pymavlink_raw(path):
    return [bytes(m.get_msgbuf()) for m in messages(mavutil.mavlink_connection(path, notimestamps=True))
            if m.get_type() != "BAD_DATA" and not m.get_type().startswith("UNKNOWN_")]


def mavstack_decode(binary, path):
    out = subprocess.run([binary, "decode", "--dialect", DIALECT, "--keep-unknown", path],
                         capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit("mavstack decode %s failed (%d): %s" % (path, out.returncode, out.stderr))
    rows = []
    for line in out.stdout.splitlines():
        obj = json.loads(line)
        sig = obj.get("signature")
        rows.append((obj.get("ts_us"), (obj["version"], obj["msgid"], obj["seq"], obj["sysid"], obj["compid"],
                                        sig and sig["timestamp"])))
    return rows


def header_of(frame):
    """What `mavstack decode` prints of a frame's header: version, msgid, seq, sysid, compid,
    signature timestamp."""
    if frame[0] == 0xFD:
        sig = None
        if frame[2] & 1:
            sig = int.from_bytes(frame[-12:-6], "little")
        return (2, frame[7] | frame[8] << 8 | frame[9] << 16, frame[4], frame[5], frame[6], sig)
    return (1, frame[5], frame[2], frame[3], frame[4], None)


def first_difference(a, b):
    for i, (x, y) in enumerate(zip(a, b)):
        if x != y:
            return "at %d: pymavlink %r, mavstack %r" % (i, x, y)
    return "lengths %d (pymavlink) and %d (mavstack)" % (len(a), len(b))


def is_subsequence(small, big):
    it = iter(big)
    return all(any(x == y for y in it) for x in small)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--records", type=int, default=200_000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--out")
    ap.add_argument("--damage", default=",".join(DAMAGE),
                    help="comma-separated damage kinds, in turn (default: all of %s)" % ",".join(DAMAGE))
    ap.add_argument("--python", action="store_true", help="also check the mavstack Python package")
    args = ap.parse_args()
    out_dir = args.out or tempfile.mkdtemp(prefix="tlog-damage-")
    os.makedirs(out_dir, exist_ok=True)
    tlog = os.path.join(out_dir, "damaged.tlog")
    raw = os.path.join(out_dir, "damaged.mavlink")
    damage_kinds = args.damage.split(",")
    bad = sorted(set(damage_kinds) - set(DAMAGE))
    if bad:
        ap.error("unknown damage kind(s): %s" % ", ".join(bad))
    kinds, records = write_corpus(tlog, raw, args.records, args.seed, damage_kinds)
    failed = False

    expected = pymavlink_tlog(tlog)
    own = pymavlink_tlog(tlog, mended=False)
    damaged = sum(kinds.values())
    print("corpus: %d records, %d damaged %s; pymavlink returns %d frames (%d of known messages), "
          "mended %d (%d)" % (args.records + 1, damaged + 1, json.dumps(kinds, sort_keys=True),
                              len(own), sum(1 for e in own if e[2]),
                              len(expected), sum(1 for e in expected if e[2])))
    # The mended case, explicitly: where both readings return an intact MAVLink 2 record and
    # then the intact short MAVLink 1 record after it (each with its own timestamp), pymavlink's
    # own loses the intact record that follows and the mended one (so mavstack) returns it.
    own_read = {(t, b) for (t, b, _) in own}
    mended_read = {(t, b) for (t, b, _) in expected}
    cases = [k for k in range(1, len(records) - 1)
             if all(r[2] for r in records[k - 1:k + 2]) and records[k - 1][1][0] == 0xFD
             and records[k][1][0] == 0xFE and records[k][1][1] < 4
             and {records[k - 1][:2], records[k][:2]} <= own_read & mended_read]
    lost = [k for k in cases if records[k + 1][:2] not in own_read]
    found = [k for k in cases if records[k + 1][:2] in mended_read]
    if cases and len(lost) == len(cases) and len(found) == len(cases):
        print("ok   pymavlink loses the record after each of %d short MAVLink 1 frames it reads after a "
              "MAVLink 2 frame; the mended reading returns all %d" % (len(cases), len(found)))
    else:
        failed = True
        print("FAIL short MAVLink 1 frames after MAVLink 2 ones: %d read by both, the next record lost "
              "by pymavlink %d times, returned mended %d times" % (len(cases), len(lost), len(found)))

    got = mavstack_decode(args.mavstack, tlog)
    want = [(t, header_of(b)) for (t, b, _) in expected]
    got = [(ts * 1.0e-6, h) for (ts, h) in got]
    if got == want:
        print("ok   mavstack decode (tlog): the same %d frames (headers, signatures) with the same timestamps" % len(got))
    else:
        failed = True
        print("FAIL mavstack decode (tlog): %s" % first_difference(want, got))

    if args.python:
        from mavstack import mavutil as ms_mavutil
        conn = ms_mavutil.mavlink_connection(tlog, dialect=DIALECT)
        mine = [(m._timestamp, bytes(m.get_msgbuf())) for m in messages(conn)]
        want_known = [(t, b) for (t, b, k) in expected if k]
        if mine == want_known:
            print("ok   Python package (tlog): the same %d frames of known messages, bytes and _timestamp"
                  % len(mine))
        else:
            failed = True
            print("FAIL Python package (tlog): %s" % first_difference(want_known, mine))

    raw_expected = [header_of(b) for b in pymavlink_raw(raw)]
    raw_got = [h for (_, h) in mavstack_decode(args.mavstack, raw)]
    if is_subsequence(raw_expected, raw_got):
        print("ok   mavstack decode (raw): all %d frames pymavlink's parser returns, in order (mavstack: %d)"
              % (len(raw_expected), len(raw_got)))
    else:
        failed = True
        missing = [h for h in raw_expected if h not in set(raw_got)][:3]
        print("FAIL mavstack decode (raw): frames pymavlink returns are missing: %s" % missing)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
