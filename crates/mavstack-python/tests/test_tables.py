"""mavstack.read_tlog: every table equals pymavlink's values row by row, and pyarrow, polars
and pandas take the tables."""

import math

import pyarrow as pa
import pytest

import mavstack
from conftest import KEY, reference

FIXED = ["timestamp_us", "sysid", "compid", "seq", "signed"]


def same_value(a, b):
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b))
    return a == b


def expected_row(m, raw=False):
    """A pymavlink message as the row of our table (the columns of docs/contracts/python-api.md)."""
    buf = bytes(m.get_msgbuf())
    row = {
        "timestamp_us": 0 if raw else None,
        "sysid": m.get_srcSystem(),
        "compid": m.get_srcComponent(),
        "seq": m.get_seq(),
        "signed": buf[0] == 0xFD and bool(buf[2] & 1),
    }
    for f in m.ordered_fieldnames:
        raw_text = getattr(m, "_%s_raw" % f, None)
        if raw_text is not None:
            row[f] = raw_text.split(b"\0", 1)[0].decode("latin-1")
        else:
            row[f] = getattr(m, f)
    return row


def check_tables(path, dialect, key=None, types=None, raw=False):
    pairs = reference(path, dialect, key=key, raw=raw)
    tables = mavstack.read_tlog(path, types=types, dialect=dialect, key=key)
    by_type = {}
    for _, m, from_reader in pairs:
        if types is None or m.get_type() in types:
            by_type.setdefault(m.get_type(), []).append((m, from_reader))
    assert list(tables) == list(by_type), "types, in order of first appearance"
    rows = 0
    for name, table in tables.items():
        assert table.num_rows == len(by_type[name])
        t = pa.table(table)
        assert t.column_names == FIXED + list(by_type[name][0][0].ordered_fieldnames)
        got = t.to_pylist()
        for (m, from_reader), row in zip(by_type[name], got):
            want = expected_row(m, raw)
            if want["timestamp_us"] is None and not from_reader:
                want["timestamp_us"] = row["timestamp_us"]
            if want["timestamp_us"] is None:
                # pymavlink's _timestamp is the record's µs × 1e-6.
                assert row["timestamp_us"] * 1.0e-6 == m._timestamp
                want["timestamp_us"] = row["timestamp_us"]
            bad = {k: (want[k], row[k]) for k in want if not same_value(want[k], row[k])}
            assert not bad, "%s row differs (pymavlink, mavstack): %s" % (name, bad)
        rows += len(got)
    return tables, rows


def test_every_type_of_ardupilotmega_row_by_row(corpora):
    _, rows = check_tables(corpora["apm_tlog"], "ardupilotmega")
    assert rows > 3000


def test_every_message_of_all_row_by_row(corpora):
    tables, rows = check_tables(corpora["all_tlog"], "all")
    import pymavlink.dialects.v20.all as alld
    assert len(tables) == len(alld.mavlink_map) and rows > 2000


def test_raw_capture_and_key(corpora):
    check_tables(corpora["apm_raw"], "ardupilotmega", key=KEY, raw=True)


def test_types_selects_tables(corpora):
    tables, _ = check_tables(corpora["apm_tlog"], "ardupilotmega", types=["ATTITUDE", "HEARTBEAT", "NO_SUCH"])
    assert set(tables) == {"ATTITUDE", "HEARTBEAT"}


def test_schema_types_and_units(corpora):
    t = pa.table(mavstack.read_tlog(corpora["apm_tlog"], types=["ATTITUDE"])["ATTITUDE"])
    s = t.schema
    assert s.field("timestamp_us").type == pa.int64()
    assert s.field("seq").type == pa.uint8() and s.field("signed").type == pa.bool_()
    assert s.field("roll").type == pa.float32()
    assert s.field("time_boot_ms").type == pa.uint32()
    assert s.field("roll").metadata == {b"units": b"rad"}
    gps = mavstack.read_tlog(corpora["all_tlog"], types=["GPS_RAW_INT", "STATUSTEXT", "SERVO_OUTPUT_RAW", "GPS_STATUS"], dialect="all")
    g = pa.table(gps["GPS_RAW_INT"]).schema
    assert g.field("lat").type == pa.int32() and g.field("time_usec").type == pa.uint64()
    assert pa.table(gps["STATUSTEXT"]).schema.field("text").type == pa.utf8()
    assert pa.types.is_fixed_size_list(pa.table(gps["GPS_STATUS"]).schema.field("satellite_prn").type)


def test_polars_pandas_and_a_stream_consumed_once(corpora):
    import pandas as pd
    import polars as pl
    ref = pa.table(mavstack.read_tlog(corpora["apm_tlog"], types=["ATTITUDE"])["ATTITUDE"])
    df = pl.DataFrame(mavstack.read_tlog(corpora["apm_tlog"], types=["ATTITUDE"])["ATTITUDE"])
    assert df.height == ref.num_rows and df["roll"].to_list() == ref.column("roll").to_pylist()
    # polars.from_arrow gives a stream as a Series of structs.
    s = pl.from_arrow(mavstack.read_tlog(corpora["apm_tlog"], types=["ATTITUDE"])["ATTITUDE"])
    assert s.struct.unnest().equals(df)
    pdf = pa.table(mavstack.read_tlog(corpora["apm_tlog"], types=["ATTITUDE"])["ATTITUDE"]).to_pandas()
    assert isinstance(pdf, pd.DataFrame) and list(pdf["seq"]) == ref.column("seq").to_pylist()
    t = mavstack.read_tlog(corpora["apm_tlog"], types=["ATTITUDE"])["ATTITUDE"]
    reader = pa.RecordBatchReader.from_stream(t)
    assert sum(b.num_rows for b in reader) == ref.num_rows
    with pytest.raises(ValueError, match="consumed"):
        pa.table(t)


def test_batches_of_a_long_log(tmp_path):
    """More rows than one batch: the stream is several batches, in order."""
    import pymavlink.dialects.v20.ardupilotmega as apm
    from conftest import write_tlog
    mav = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = []
    for i in range(150_000):
        frames.append(apm.MAVLink_attitude_message(i, 0.0, 0.0, 0.0, 0, 0, 0).pack(mav))
        mav.seq = (mav.seq + 1) % 256
    path = write_tlog(str(tmp_path / "long.tlog"), frames, link_bits=False)
    reader = pa.RecordBatchReader.from_stream(mavstack.read_tlog(path, progress=True)["ATTITUDE"])
    batches = list(reader)
    assert len(batches) == 3
    t = pa.Table.from_batches(batches)
    assert t.column("time_boot_ms").to_pylist() == list(range(150_000))


def test_readme_notebook_example(tmp_path, corpora, monkeypatch):
    """The package README's example runs as written (with matplotlib when it is installed)."""
    import re
    import os
    import shutil
    readme = open(os.path.join(os.path.dirname(__file__), "..", "README.md")).read()
    code = re.search(r"## A notebook.*?```python\n(.*?)```", readme, re.S).group(1)
    shutil.copy(corpora["apm_tlog"], tmp_path / "flight.tlog")
    monkeypatch.chdir(tmp_path)
    import matplotlib
    matplotlib.use("Agg")
    exec(compile(code, "README.md", "exec"), {})
    assert (tmp_path / "roll.png").stat().st_size > 1000
