"""A tlog that pymavlink writes with MAVLink 1 frames of payloads under 4 bytes
(tests-interop/short_v1_tlog.py: pymavlink's mavlogfile, 500 mixed records). pymavlink's own
reader loses the record after such a frame when a MAVLink 2 frame came before it (the script
says why); mavstack.mavutil reads all 500 records, each with pymavlink's values and the
`_timestamp` pymavlink gives a record, and read_tlog's tables hold them all too."""

import json
import os
import subprocess
import sys

import mavstack
from mavstack import mavutil
from conftest import ROOT, norm, pymavlink_messages

SCRIPT = os.path.join(ROOT, "tests-interop", "short_v1_tlog.py")
DIALECT = "ardupilotmega"


def write_log(tmp_path):
    """The log's path and pymavlink's description of each record it wrote."""
    path = str(tmp_path / "short_v1.tlog")
    out = subprocess.run([sys.executable, SCRIPT, path, "--records", "500"], check=True,
                         capture_output=True, text=True).stdout
    rows = [json.loads(line) for line in out.splitlines()]
    assert len(rows) == 500
    after_v2 = sum(1 for a, b in zip(rows, rows[1:]) if a["version"] == 2 and b["short_v1"])
    assert after_v2 >= 50
    return path, rows


def pymavlink_decoded(frame):
    """pymavlink's decoder on one frame alone."""
    import importlib
    mod = importlib.import_module("pymavlink.dialects.v20." + DIALECT)
    parser = mod.MAVLink(None)
    parser.robust_parsing = True
    found = parser.parse_buffer(frame) or []
    assert len(found) == 1 and found[0].get_type() not in ("BAD_DATA",), found
    return found[0]


def values(m):
    """What must be equal between pymavlink's message and ours (the timestamps apart)."""
    h = m.get_header()
    return {
        "type": m.get_type(),
        "id": m.get_msgId(),
        "sys": m.get_srcSystem(),
        "comp": m.get_srcComponent(),
        "seq": m.get_seq(),
        "signed": m.get_signed(),
        "msgbuf": bytes(m.get_msgbuf()),
        "header": (h.msgId, h.incompat_flags, h.compat_flags, h.mlen, h.seq, h.srcSystem, h.srcComponent),
        "dict": norm(m.to_dict()),
        "str": str(m),
    }


def test_every_record_after_a_short_mavlink_1_frame_is_read(tmp_path):
    path, rows = write_log(tmp_path)
    mine = list(mavutil.mavlink_connection(path, dialect=DIALECT))
    assert len(mine) == 500
    for i, (m, row) in enumerate(zip(mine, rows)):
        frame = bytes.fromhex(row["frame"])
        assert values(m) == values(pymavlink_decoded(frame)), "record %d" % i
        # pymavlink's mavlogfile: `_timestamp` is the record's µs × 1.0e-6, `_link` its low bits.
        assert (m._timestamp, m._link) == (row["ts_us"] * 1.0e-6, row["ts_us"] & 3), "record %d" % i

    # pymavlink's own reader of the same file loses records, and returns nothing we do not:
    # each message it returns is ours at its record, with the same values and `_timestamp`.
    theirs = pymavlink_messages(path, DIALECT)
    assert len(theirs) < 500
    frames = [bytes.fromhex(r["frame"]) for r in rows]
    read, at = set(), 0
    for t in theirs:
        at = frames.index(bytes(t.get_msgbuf()), at)
        assert values(t) == values(mine[at]) and t._timestamp == mine[at]._timestamp, at
        read.add(at)
        at += 1
    # Where it reads a MAVLink 2 frame and then a short MAVLink 1 frame, it loses the next record.
    cases = [k for k in range(1, 499)
             if rows[k - 1]["version"] == 2 and rows[k]["short_v1"] and {k - 1, k} <= read]
    assert len(cases) >= 20
    assert not any(k + 1 in read for k in cases)

    # Every record lands in the tables too, with its timestamp.
    import pyarrow as pa
    tables = {name: pa.table(t) for name, t in mavstack.read_tlog(path, dialect=DIALECT).items()}
    assert sum(t.num_rows for t in tables.values()) == 500
    for name, table in tables.items():
        want = [r["ts_us"] for r in rows if r["type"] == name]
        assert table.column("timestamp_us").to_pylist() == want, name

