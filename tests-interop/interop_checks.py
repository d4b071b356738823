"""What the interop scripts of this directory share: check results printed one line each
(`ok ...`, `FAIL ...`, `throughput ...`), free ports, file helpers, a logged subprocess, and
MAVSDK's log kept quiet. Used by ftp_interop.py and log_interop.py."""

import socket
import subprocess
import time
import traceback


class Results:
    def __init__(self):
        self.failed = []
        self.passed = 0
        self.throughput = []

    def ok(self, name, detail=""):
        self.passed += 1
        print(f"ok    {name}" + (f": {detail}" if detail else ""), flush=True)

    def fail(self, name, detail):
        self.failed.append(name)
        print(f"FAIL  {name}: {detail}", flush=True)

    def check(self, name, cond, detail=""):
        if cond:
            self.ok(name)
        else:
            self.fail(name, detail or "check failed")
        return cond

    def guard(self, name, fn, *args, **kw):
        """Runs fn; an exception is a FAIL of `name`."""
        try:
            return fn(*args, **kw)
        except Exception as e:  # noqa: BLE001
            tb = traceback.format_exc(limit=4).strip().splitlines()
            self.fail(name, f"{type(e).__name__}: {e} [{' | '.join(tb[-3:])}]")
            return None

    def summary(self, script, t0):
        """The last line (`SCRIPT: all N checks ok in S s`, or how many failed) and the exit
        status: 1 if anything failed."""
        dt = time.monotonic() - t0
        if self.failed:
            print(f"{script}: {len(self.failed)} FAILED, {self.passed} ok in {dt:.1f} s", flush=True)
            return 1
        print(f"{script}: all {self.passed} checks ok in {dt:.1f} s", flush=True)
        return 0

    def rate(self, who, nbytes, seconds):
        kib = nbytes / 1024 / seconds if seconds > 0 else float("inf")
        line = f"throughput  {who}: {nbytes} bytes in {seconds:.3f} s = {kib:.1f} KiB/s"
        self.throughput.append(line)
        print(line, flush=True)


def free_port(kind=socket.SOCK_STREAM):
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def read(path):
    with open(path, "rb") as f:
        return f.read()


def diff_bytes(got, want):
    if got is None:
        return "nothing"
    if len(got) != len(want):
        return f"{len(got)} bytes, want {len(want)}"
    if got == want:
        return "equal"
    first = next(i for i in range(len(got)) if got[i] != want[i])
    return f"first difference at byte {first}"


class Proc:
    def __init__(self, cmd, log):
        self.cmd = cmd
        self.log_path = log
        self._log = open(log, "wb")  # noqa: SIM115
        self.p = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=self._log,
                                  stderr=subprocess.STDOUT)

    def alive(self):
        return self.p.poll() is None

    def tail(self, n=15):
        try:
            lines = read(self.log_path).decode(errors="replace").splitlines()
            return " / ".join(lines[-n:])
        except OSError:
            return ""

    def stop(self):
        if self.p.poll() is None:
            self.p.terminate()
            try:
                self.p.wait(5)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()
        self._log.close()


# MAVSDK's last log lines (see quiet_mavsdk).
MAVSDK_LOG = []


def quiet_mavsdk():
    """MAVSDK's log goes to a list (its last lines are shown when something fails)."""
    try:
        from mavsdk.logging import log_subscribe
    except Exception:  # noqa: BLE001
        return

    def keep(level, message, _file, _line):
        MAVSDK_LOG.append(f"{level.name} {message}")
        del MAVSDK_LOG[:-200]
        return True

    log_subscribe(keep)


def show_mavsdk_log():
    """Prints MAVSDK's last log lines but its DEBUG ones (after a failure)."""
    for line in [m for m in MAVSDK_LOG if not m.startswith("DEBUG")][-15:]:
        print(f"      mavsdk log: {line}", flush=True)
