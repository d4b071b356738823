"""A log that another program shortens while it is read: the reader raises OSError naming the
file, and the interpreter lives (a mapped file would have died of SIGBUS). Each case runs in
a fresh interpreter so that a signal shows as its exit status instead of killing pytest."""

import signal
import subprocess
import sys
import textwrap

from conftest import write_tlog


def write_heartbeats(path, records):
    """A tlog of `records` MAVLink 2 HEARTBEATs of 1/1 (29 bytes a record), packed by pymavlink."""
    from pymavlink.dialects.v20 import common
    mav = common.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = []
    for seq in range(256):
        mav.seq = seq
        frames.append(common.MAVLink_heartbeat_message(2, 3, 81, 4, 3, 3).pack(mav))
    write_tlog(path, (frames[i % 256] for i in range(records)), link_bits=False)


def run(code, path):
    """`code` in a fresh interpreter with `path` as sys.argv[1]."""
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code), path],
                          capture_output=True, text=True, timeout=120)


def died_of_signal(proc):
    return proc.returncode < 0 and "signal %s" % signal.Signals(-proc.returncode).name


def test_iteration_over_a_log_truncated_midway_raises_oserror_naming_it(tmp_path):
    path = str(tmp_path / "shrinking.tlog")
    records = 150_000  # 4.6 MB: several of the reader's 1 MiB checks
    write_heartbeats(path, records)
    proc = run("""
        import os, sys
        from mavstack import mavutil
        path = sys.argv[1]
        log = mavutil.mavlink_connection(path)
        n = 0
        try:
            for m in log:
                n += 1
                if n == 1000:
                    os.truncate(path, 4096)
        except OSError as e:
            print("raised", n, e)
        else:
            print("ended", n)
        print("alive")
    """, path)
    assert proc.returncode == 0, (died_of_signal(proc), proc.stderr)
    out = proc.stdout.splitlines()
    assert out[-1] == "alive", proc.stdout
    assert out[0].startswith("raised"), proc.stdout
    assert path in out[0] and "truncated" in out[0], out[0]
    # Raised at the next check after the truncation, not at the end of the old length.
    assert 1000 <= int(out[0].split()[1]) < records, out[0]


def test_recv_match_raises_too_and_the_end_of_a_whole_log_is_none(tmp_path):
    path = str(tmp_path / "shrinking.tlog")
    write_heartbeats(path, 2000)  # below one check: the end looks at the length
    proc = run("""
        import os, sys
        from mavstack import mavutil
        path = sys.argv[1]
        log = mavutil.mavlink_connection(path)
        assert log.recv_match(type="HEARTBEAT") is not None
        os.truncate(path, 100)
        try:
            while log.recv_match(type="HEARTBEAT") is not None:
                pass
        except OSError as e:
            print("raised", e)
        whole = sys.argv[1] + ".whole"
        open(whole, "wb").write(b"")
        print("empty", mavutil.mavlink_connection(whole).recv_msg())
    """, path)
    assert proc.returncode == 0, (died_of_signal(proc), proc.stderr)
    assert proc.stdout.startswith("raised") and path in proc.stdout, proc.stdout
    assert "empty None" in proc.stdout, proc.stdout


def test_tables_read_before_the_file_shrank_keep_their_values(tmp_path):
    path = str(tmp_path / "shrinking.tlog")
    write_heartbeats(path, 5000)
    proc = run("""
        import os, sys
        import pyarrow as pa
        import mavstack
        path = sys.argv[1]
        tables = mavstack.read_tlog(path)
        os.truncate(path, 0)
        t = pa.table(tables["HEARTBEAT"])
        print(t.num_rows, t.column("custom_mode")[0].as_py())
    """, path)
    assert proc.returncode == 0, (died_of_signal(proc), proc.stderr)
    assert proc.stdout.split() == ["5000", "4"], proc.stdout
