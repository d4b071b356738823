#!/usr/bin/env python3
"""MAVFTP interoperability: mavstack's server and client against independent peers.

    ftp_interop.py --mavstack target/debug/mavstack [--big-mb 1] [--lossy]

1. pymavlink 2.4.50's `pymavlink.mavftp.MAVFTP` as the client of `mavstack vehicle
   --ftp-root DIR --ftp-writable` over TCP: list, get (bytes compared), crc (compared with a
   CRC32 computed here: reflected 0xEDB88320, zero seed, no final inversion), put, mkdir,
   rename, rm, rmdir, and paths that leave the root (`..`, an absolute path, a symbolic link
   inside DIR that leads out) refused with nothing outside DIR changed.
2. MAVSDK 4.1.0's ftp plugin (the native ctypes binding) against the same server.
3. `mavstack ftp` against MAVSDK's ftp_server (a Mavsdk of component type AUTOPILOT serving
   a root directory), over UDP.
4. `mavstack ftp` against `mavstack vehicle`.
5. With --lossy: steps 1 and 4 again through tests-interop/lossy_relay.py, 20 % loss each
   way (the relay has no delay option: loss only).

One `ok  ...` or `FAIL ...` line per check, throughput lines for the big file, and a summary;
exit status 1 if anything failed. A peer that cannot be imported is a FAIL, never a skip.
"""

import argparse
import asyncio
import json
import logging
import os
import random
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import traceback

os.environ["MAVLINK20"] = "1"
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from interop_checks import (  # noqa: E402
    Proc, Results, diff_bytes, free_port, quiet_mavsdk, read, show_mavsdk_log,
)

BURST = 80 * 239  # pymavlink's burst_read_size 80 × 239-byte payloads


# ---------------------------------------------------------------- CRC32 as MAVFTP servers do it

def _crc_table():
    table = []
    for n in range(256):
        c = n
        for _ in range(8):
            c = (c >> 1) ^ 0xEDB88320 if c & 1 else c >> 1
        table.append(c)
    return table


_CRC_TABLE = _crc_table()


def mavftp_crc32(data, crc=0):
    """Reflected 0xEDB88320, seed 0, no final inversion (ArduPilot's crc_crc32)."""
    t = _CRC_TABLE
    for b in data:
        crc = t[(crc ^ b) & 0xFF] ^ (crc >> 8)
    return crc


def _crc_bitwise(data):
    crc = 0
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xEDB88320 if crc & 1 else crc >> 1
    return crc


# ---------------------------------------------------------------- results

R = Results()


# ---------------------------------------------------------------- the file set

def free_both():
    """A port free for UDP and TCP at once."""
    for _ in range(200):
        p = free_port(socket.SOCK_DGRAM)
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
                s.bind(("127.0.0.1", p))
            return p
        except OSError:
            continue
    raise RuntimeError("no free port")


DEEP = "a/b/c/d/e/f"
# `mavstack vehicle` serves ArduPilot's packed parameter file beside DIR: its root lists it.
VEHICLE_ROOT_EXTRA = {"@PARAM": ("dir", None)}


def want_listing(disk, remote, vehicle):
    want = disk_listing(disk)
    if vehicle and remote == "/":
        want.update(VEHICLE_ROOT_EXTRA)
    return want


def make_tree(base, big_mb, seed=7):
    """DIR (served) beside OUTSIDE (never to be touched) and a sentinel file; returns
    (root, {relpath: bytes}, outside snapshot function)."""
    rng = random.Random(seed)
    root = os.path.join(base, "root")
    outside = os.path.join(base, "outside")
    os.makedirs(os.path.join(root, DEEP))
    os.makedirs(outside)
    files = {
        "empty.bin": b"",
        "one.bin": b"\x5a",
        "small.bin": bytes(rng.getrandbits(8) for _ in range(239)),
        "burst.bin": bytes(rng.getrandbits(8) for _ in range(BURST)),
        "big.bin": rng.randbytes(int(big_mb * (1 << 20))),
        "name with spaces.txt": b"spaces in the name\n" * 37,
        f"{DEEP}/deep.txt": b"six directories down\n" * 50,
    }
    for rel, data in files.items():
        with open(os.path.join(root, rel), "wb") as f:
            f.write(data)
    with open(os.path.join(base, "sentinel.txt"), "wb") as f:
        f.write(b"must not change\n")
    with open(os.path.join(outside, "secret.txt"), "wb") as f:
        f.write(b"secret outside the root\n")
    # a directory of symbolic links leading out of the root
    os.makedirs(os.path.join(root, "esc"))
    os.symlink("../../outside", os.path.join(root, "esc", "out"))
    os.symlink("../../sentinel.txt", os.path.join(root, "esc", "sentinel"))

    def snapshot():
        snap = {}
        for d, _, names in os.walk(base):
            if os.path.abspath(d).startswith(os.path.abspath(root)):
                continue
            for n in names:
                p = os.path.join(d, n)
                with open(p, "rb") as f:
                    snap[os.path.relpath(p, base)] = f.read()
            snap[os.path.relpath(d, base) + "/"] = None
        return snap

    return root, files, snapshot


def disk_listing(path):
    out = {}
    for n in os.listdir(path):
        p = os.path.join(path, n)
        if os.path.isdir(p):
            out[n] = ("dir", None)
        elif os.path.isfile(p):
            out[n] = ("file", os.path.getsize(p))
    return out


# ---------------------------------------------------------------- processes

def start_vehicle(binary, link, root, work, tag):
    cmd = [binary, "vehicle", link, "--ftp-root", root, "--ftp-writable", "--start-mavlink2"]
    v = Proc(cmd, os.path.join(work, f"vehicle-{slug(tag)}.log"))
    if link.startswith("tcpin:"):
        port = int(link.rsplit(":", 1)[1])
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            if not v.alive():
                raise RuntimeError(f"vehicle exited {v.p.returncode}: {v.tail()}")
            try:
                with socket.create_connection(("127.0.0.1", port), 0.5):
                    break
            except OSError:
                time.sleep(0.1)
        else:
            raise RuntimeError(f"vehicle not listening on {port}: {v.tail()}")
    else:
        time.sleep(0.3)
        if not v.alive():
            raise RuntimeError(f"vehicle exited {v.p.returncode}: {v.tail()}")
    return v


def mavstack_ftp(binary, args, conn, extra=(), timeout=120):
    cmd = [binary, "ftp", args[0], conn, *extra, *args[1:]]
    t = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, timeout=timeout, check=False)
    return p.returncode, p.stdout.decode(errors="replace"), p.stderr.decode(errors="replace"), \
        time.monotonic() - t


def done_seconds(stderr):
    for line in stderr.splitlines():
        if line.startswith("ftp: done in "):
            return float(line.split()[3])
    return None


# ---------------------------------------------------------------- 1: pymavlink MAVFTP client

class LogCatcher(logging.Handler):
    def __init__(self):
        super().__init__(logging.DEBUG)
        self.lines = []

    def emit(self, record):
        try:
            self.lines.append(record.getMessage())
        except Exception:  # noqa: BLE001
            pass

    def since(self, n):
        return self.lines[n:]


CATCH = LogCatcher()


def slug(tag):
    return "".join(c if c.isalnum() else "-" for c in tag.split("→")[0])


def pymavlink_client(conn, root, files, work, tag, timeout, lossy=False):
    try:
        from pymavlink import mavutil
        from pymavlink.mavftp import MAVFTP
    except Exception as e:  # noqa: BLE001
        R.fail(f"{tag}: import pymavlink.mavftp", f"{type(e).__name__}: {e}")
        return
    logging.getLogger().addHandler(CATCH)
    logging.getLogger().setLevel(logging.INFO)
    master = mavutil.mavlink_connection(conn, source_system=255, source_component=190)
    try:
        hb = master.wait_heartbeat(timeout=15)
        if not R.check(f"{tag}: heartbeat", hb is not None, f"no HEARTBEAT on {conn}"):
            return
        settings = None
        if not lossy:
            # Simple operations end on idle detection: 0.7 s instead of 3.7 s of quiet.
            from pymavlink.mavftp import MAVFTPSettings

            settings = MAVFTPSettings([
                ("debug", int, 0), ("pkt_loss_tx", int, 0), ("pkt_loss_rx", int, 0),
                ("max_backlog", int, 5), ("burst_read_size", int, 80), ("write_size", int, 80),
                ("write_qsize", int, 5), ("idle_detection_time", float, 0.7),
                ("read_retry_time", float, 0.6), ("retry_time", float, 0.5)])
        ftp = MAVFTP(master, 1, 1, settings)
        _pymavlink_steps(ftp, root, files, work, tag, timeout, lossy)
    finally:
        master.close()


def _quiet(fn, *args):
    try:
        return fn(*args)
    except Exception:  # noqa: BLE001
        return None


def _py_ok(ret):
    return ret is not None and int(ret.error_code) == 0


def _py_err(ret, mark):
    if ret is None:
        return "no result"
    logs = " / ".join(CATCH.since(mark)[-6:])
    return f"{ret.operation_name} error {int(ret.error_code)} ({ret.error_code!r}); log: {logs}"


def _pymavlink_steps(ftp, root, files, work, tag, timeout, lossy):
    # pymavlink retries opens, reads and writes, never a list, crc, mkdir, rm, rmdir or
    # rename: on a lossy link those are tried again here, as a user would (up to 6 times).
    tries = 6 if lossy else 1
    sl = slug(tag)

    def listing(path):
        mark = len(CATCH.lines)
        ret = ftp.cmd_ftp(["list", path])
        if not _py_ok(ret) or ret.directory_listing is None:
            raise RuntimeError(_py_err(ret, mark))
        return {e.name: ("dir", None) if e.is_dir else ("file", e.size_b)
                for e in ret.directory_listing if e.name not in (".", "..")}

    for remote, disk in (("/", root), (f"/{DEEP}", os.path.join(root, DEEP))):
        want = want_listing(disk, remote, True)
        for attempt in range(tries):
            last = attempt == tries - 1
            got = R.guard(f"{tag}: list {remote}", listing, remote) if last else \
                _quiet(listing, remote)
            if got == want or last:
                if got is not None:
                    R.check(f"{tag}: list {remote}" + (f" (try {attempt + 1})" if attempt else ""),
                            got == want, f"got {got}, on disk {want}")
                break

    local_dir = os.path.join(work, f"get-{slug(tag)}")
    os.makedirs(local_dir)
    for i, (rel, data) in enumerate(files.items()):
        local = os.path.join(local_dir, f"{i}.bin")
        mark = len(CATCH.lines)
        t = time.monotonic()
        ftp.cmd_ftp(["get", "/" + rel, local])
        ret = ftp.process_ftp_reply("get", timeout=timeout)
        dt = time.monotonic() - t
        got = read(local) if os.path.exists(local) else None
        if R.check(f"{tag}: get /{rel} ({len(data)} bytes)", got == data,
                   f"{diff_bytes(got, data)}; {_py_err(ret, mark)}") and rel == "big.bin":
            R.rate(f"{tag} get big.bin", len(data), dt)

    def crc(remote):
        mark = len(CATCH.lines)
        ret = ftp.cmd_ftp(["crc", remote])
        if not _py_ok(ret):
            raise RuntimeError(_py_err(ret, mark))
        for line in reversed(CATCH.since(mark)):
            if line.startswith("crc: "):
                return int(line.split()[-3], 16)
        raise RuntimeError(f"no crc logged: {CATCH.since(mark)}")

    for rel, data in files.items():
        for attempt in range(tries - 1):
            got = _quiet(crc, "/" + rel)
            if got is not None:
                break
        else:
            got = R.guard(f"{tag}: crc /{rel}", crc, "/" + rel)
        if got is not None:
            want = mavftp_crc32(data)
            R.check(f"{tag}: crc /{rel}", got == want, f"server {got:08x}, ours {want:08x}")

    # put, mkdir, rename, rm, rmdir
    up = random.Random(tag).randbytes(5003)
    local = os.path.join(work, f"put-{sl}.bin")
    with open(local, "wb") as f:
        f.write(up)
    p = os.path.join(root, f"put-{sl}.bin")
    mark = len(CATCH.lines)
    asked = ftp.session
    ftp.cmd_ftp(["put", local, f"/put-{sl}.bin"])
    ret = ftp.process_ftp_reply("put", timeout=timeout)
    got = read(p) if os.path.exists(p) else None
    # After a get, pymavlink asks for session 1 and, unless CreateFile's ACK is already
    # waiting when it first looks, sends its first WriteFiles in that session before the
    # ACK. ArduPilot adopts the id asked for (ftp.current_session = request.session), and
    # so does mavstack's server when that id is free.
    R.check(f"{tag}: put /put-{sl}.bin in session {asked} (5003 bytes)", got == up,
            f"{diff_bytes(got, up)}; {_py_err(ret, mark)}")
    if got is not None and got == up:
        got = _quiet(crc, f"/put-{sl}.bin")
        for _ in range(tries - 1):
            if got is not None:
                break
            got = _quiet(crc, f"/put-{sl}.bin")
        R.check(f"{tag}: crc of the put file", got == mavftp_crc32(up), f"server {got}")

    def simple(args, name, disk_ok):
        for attempt in range(tries):
            mark = len(CATCH.lines)
            ret = ftp.cmd_ftp(args)
            if _py_ok(ret) and disk_ok():
                R.ok(f"{tag}: {name}" + (f" (try {attempt + 1})" if attempt else ""))
                return
            if lossy and disk_ok():  # done, its reply lost; a retry was refused
                R.ok(f"{tag}: {name} (done on disk; reply lost on try {attempt + 1})")
                return
        R.fail(f"{tag}: {name}", f"{_py_err(ret, mark)}; disk {sorted(os.listdir(root))}")

    d = f"dir-{sl}"
    simple(["mkdir", f"/{d}"], f"mkdir /{d}", lambda: os.path.isdir(os.path.join(root, d)))
    simple(["rename", f"/put-{sl}.bin", f"/{d}/moved.bin"], f"rename into /{d}",
           lambda: not os.path.exists(p) and read(os.path.join(root, d, "moved.bin")) == up)
    simple(["rm", f"/{d}/moved.bin"], f"rm /{d}/moved.bin",
           lambda: not os.path.exists(os.path.join(root, d, "moved.bin")))
    simple(["rmdir", f"/{d}"], f"rmdir /{d}", lambda: not os.path.exists(os.path.join(root, d)))

    if lossy:
        return  # refusals are checked on the clean link
    # paths that leave the root
    for remote in ("../outside/secret.txt", "/../sentinel.txt", "/etc/passwd",
                   "a/../../sentinel.txt", "/esc/sentinel", "/esc/out/secret.txt"):
        local = os.path.join(local_dir, "escaped.bin")
        if os.path.exists(local):
            os.unlink(local)
        mark = len(CATCH.lines)
        ftp.cmd_ftp(["get", remote, local])
        ret = ftp.process_ftp_reply("get", timeout=timeout)
        R.check(f"{tag}: get {remote} refused", not _py_ok(ret) and not os.path.exists(local),
                f"got {len(read(local)) if os.path.exists(local) else 'no'} bytes, "
                f"{_py_err(ret, mark)}")
    for args in (["put", "../sentinel.txt"], ["put", "/esc/out/planted.txt"],
                 ["mkdir", "../made"], ["mkdir", "/esc/out/made"], ["rm", "../sentinel.txt"],
                 ["rm", "/esc/out/secret.txt"], ["rename", "/one.bin", "../moved.bin"],
                 ["rmdir", "../outside"], ["crc", "/esc/sentinel"], ["list", "/esc/out"],
                 ["list", ".."]):
        mark = len(CATCH.lines)
        if args[0] == "put":
            ftp.cmd_ftp(["put", __file__, args[1]])
            ret = ftp.process_ftp_reply("put", timeout=timeout)
        else:
            ret = ftp.cmd_ftp(args)
        R.check(f"{tag}: {' '.join(args)} refused", not _py_ok(ret), _py_err(ret, mark))


# ---------------------------------------------------------------- 2: MAVSDK ftp client

async def mavsdk_client(url, root, files, work, tag):
    try:
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
        from mavsdk.asyncio.plugins.ftp import FtpAsync, FtpError
    except Exception as e:  # noqa: BLE001
        R.fail(f"{tag}: import mavsdk.asyncio ftp", f"{type(e).__name__}: {e}")
        return
    cfg = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    mav = Mavsdk(cfg)
    try:
        await mav.add_any_connection(url)
        system = await mav.first_autopilot(timeout_s=15)
        if not R.check(f"{tag}: first_autopilot on {url}", system is not None, "none within 15 s"):
            return
        ftp = FtpAsync(system)
        await _mavsdk_steps(ftp, FtpError, root, files, work, tag)
        ftp.destroy()
    finally:
        mav.destroy()


async def _with_timeout(coro, seconds=60):
    return await asyncio.wait_for(coro, seconds)


async def _mavsdk_steps(ftp, FtpError, root, files, work, tag):  # noqa: N803
    async def aguard(name, coro, seconds=60):
        try:
            return True, await _with_timeout(coro, seconds)
        except Exception as e:  # noqa: BLE001
            R.fail(name, f"{type(e).__name__}: {e}")
            return False, None

    for remote, disk in (("/", root), (f"/{DEEP}", os.path.join(root, DEEP))):
        ok, data = await aguard(f"{tag}: list_directory {remote}", ftp.list_directory(remote))
        if ok:
            got = {}
            for e in data.entries:
                if e.name in (".", ".."):
                    continue
                kind = int(e.entry_type)
                got[e.name] = ("dir", None) if kind == 2 else ("file", e.size_bytes) \
                    if kind == 1 else ("?", None)
            want = want_listing(disk, remote, True)
            R.check(f"{tag}: list_directory {remote}", got == want, f"got {got}, on disk {want}")

    async def download(remote, local_dir, burst):
        last = None
        async for result, prog in ftp.download(remote, local_dir, burst):
            last = (result, prog)
        return last

    for burst in (True, False):
        local_dir = os.path.join(work, f"get-{slug(tag)}-{'burst' if burst else 'read'}")
        os.makedirs(local_dir)
        for rel, data in files.items():
            if not burst and len(data) > 200_000:
                continue  # ReadFile one by one: only the small ones
            name = f"{tag}: download /{rel} ({len(data)} bytes, use_burst={burst})"
            t = time.monotonic()
            ok, _ = await aguard(name, download("/" + rel, local_dir, burst), 120)
            dt = time.monotonic() - t
            if not ok:
                continue
            local = os.path.join(local_dir, os.path.basename(rel))
            got = read(local) if os.path.exists(local) else None
            if R.check(name, got == data, diff_bytes(got, data)) and rel == "big.bin":
                R.rate(f"{tag} download big.bin (burst)", len(data), dt)

    for rel, data in files.items():
        local = os.path.join(work, f"ident-{slug(tag)}.bin")
        with open(local, "wb") as f:
            f.write(data)
        ok, same = await aguard(f"{tag}: are_files_identical /{rel}",
                                ftp.are_files_identical(local, "/" + rel))
        if ok:
            R.check(f"{tag}: are_files_identical /{rel}", same is True, f"returned {same}")
    # a differing file must not be found identical
    local = os.path.join(work, f"ident-{slug(tag)}.bin")
    with open(local, "wb") as f:
        f.write(files["small.bin"][:-1] + b"\x00")
    ok, same = await aguard(f"{tag}: are_files_identical (differs)",
                            ftp.are_files_identical(local, "/small.bin"))
    if ok:
        R.check(f"{tag}: are_files_identical (differs)", same is False, f"returned {same}")

    d = f"dir-{slug(tag)}"
    ok, _ = await aguard(f"{tag}: create_directory /{d}", ftp.create_directory(f"/{d}"))
    if ok:
        R.check(f"{tag}: create_directory /{d}", os.path.isdir(os.path.join(root, d)))
    up = random.Random(tag).randbytes(7777)
    local = os.path.join(work, f"up-{slug(tag)}.bin")
    with open(local, "wb") as f:
        f.write(up)

    async def upload():
        async for _ in ftp.upload(local, f"/{d}"):
            pass

    ok, _ = await aguard(f"{tag}: upload up-{slug(tag)}.bin to /{d}", upload(), 60)
    target = os.path.join(root, d, f"up-{slug(tag)}.bin")
    if ok:
        got = read(target) if os.path.exists(target) else None
        R.check(f"{tag}: upload up-{slug(tag)}.bin to /{d} (7777 bytes)", got == up,
                diff_bytes(got, up))
    ok, _ = await aguard(f"{tag}: rename", ftp.rename(f"/{d}/up-{slug(tag)}.bin", f"/{d}/renamed.bin"))
    if ok:
        R.check(f"{tag}: rename", not os.path.exists(target)
                and os.path.exists(os.path.join(root, d, "renamed.bin")))
    ok, _ = await aguard(f"{tag}: remove_file", ftp.remove_file(f"/{d}/renamed.bin"))
    if ok:
        R.check(f"{tag}: remove_file", not os.path.exists(os.path.join(root, d, "renamed.bin")))
    ok, _ = await aguard(f"{tag}: remove_directory", ftp.remove_directory(f"/{d}"))
    if ok:
        R.check(f"{tag}: remove_directory", not os.path.exists(os.path.join(root, d)))

    # refused: leaving the root
    local_dir = os.path.join(work, f"esc-{slug(tag)}")
    os.makedirs(local_dir)
    for remote in ("../outside/secret.txt", "/esc/sentinel"):
        try:
            await _with_timeout(download(remote, local_dir, True), 60)
            R.fail(f"{tag}: download {remote} refused", f"succeeded: {os.listdir(local_dir)}")
        except FtpError as e:
            R.ok(f"{tag}: download {remote} refused", str(e.result if hasattr(e, 'result') else e))
        except Exception as e:  # noqa: BLE001
            R.fail(f"{tag}: download {remote} refused", f"{type(e).__name__}: {e}")
    try:
        await _with_timeout(ftp.remove_file("../sentinel.txt"), 60)
        R.fail(f"{tag}: remove_file ../sentinel.txt refused", "succeeded")
    except FtpError:
        R.ok(f"{tag}: remove_file ../sentinel.txt refused")
    except Exception as e:  # noqa: BLE001
        R.fail(f"{tag}: remove_file ../sentinel.txt refused", f"{type(e).__name__}: {e}")


# ---------------------------------------------------------------- 3/4: the mavstack client

def mavstack_client(binary, conn, root, files, work, tag, extra=(), writable_root=None,
                    crc_check=True, vehicle=True):
    """`mavstack ftp` against a server serving `root` (on disk here)."""
    writable_root = writable_root or root

    def run(args, name):
        rc, out, err, dt = mavstack_ftp(binary, args, conn, extra)
        if rc != 0:
            R.fail(name, f"exit {rc}: {err.strip()[-600:]} {out.strip()[-300:]}")
            return None
        return out, err, dt

    for remote, disk in (("/", root), (f"/{DEEP}", os.path.join(root, DEEP))):
        r = run(["ls", remote, "--json"], f"{tag}: ls {remote}")
        if r is not None:
            got = {}
            try:
                for line in r[0].splitlines():
                    if line.strip():
                        e = json.loads(line)
                        if e["name"] in (".", ".."):
                            continue
                        got[e["name"]] = (e["type"], e["size"])
            except (ValueError, KeyError) as e:
                R.fail(f"{tag}: ls {remote}", f"{e}: {r[0][:400]}")
                continue
            want = want_listing(disk, remote, vehicle)
            R.check(f"{tag}: ls {remote}", got == want, f"got {got}, on disk {want}")

    local_dir = os.path.join(work, f"get-{slug(tag)}")
    os.makedirs(local_dir)
    for i, (rel, data) in enumerate(files.items()):
        local = os.path.join(local_dir, f"{i}.bin")
        name = f"{tag}: get /{rel} ({len(data)} bytes)"
        r = run(["get", "/" + rel, local], name)
        if r is None:
            continue
        got = read(local) if os.path.exists(local) else None
        if R.check(name, got == data, diff_bytes(got, data)) and rel == "big.bin":
            secs = done_seconds(r[1])
            R.rate(f"{tag} get big.bin", len(data), secs if secs else r[2])

    if crc_check:
        for rel, data in files.items():
            r = run(["crc", "/" + rel], f"{tag}: crc /{rel}")
            if r is not None:
                want = f"{mavftp_crc32(data):08x}  /{rel}"
                R.check(f"{tag}: crc /{rel}", r[0].strip() == want,
                        f"printed {r[0].strip()!r}, ours {want!r}")

    d = f"dir-{slug(tag)}"
    up = random.Random(tag).randbytes(BURST + 11)
    local = os.path.join(work, f"put-{slug(tag)}.bin")
    with open(local, "wb") as f:
        f.write(up)
    if run(["mkdir", f"/{d}"], f"{tag}: mkdir /{d}") is not None:
        R.check(f"{tag}: mkdir /{d}", os.path.isdir(os.path.join(writable_root, d)))
    target = os.path.join(writable_root, d, "put.bin")
    if run(["put", local, f"/{d}/put.bin"], f"{tag}: put /{d}/put.bin") is not None:
        got = read(target) if os.path.exists(target) else None
        R.check(f"{tag}: put /{d}/put.bin ({len(up)} bytes)", got == up, diff_bytes(got, up))
        r = run(["crc", f"/{d}/put.bin"], f"{tag}: crc of the put file")
        if r is not None:
            want = f"{mavftp_crc32(up):08x}  /{d}/put.bin"
            R.check(f"{tag}: crc of the put file", r[0].strip() == want, f"{r[0].strip()!r}")
    moved = os.path.join(writable_root, d, "moved.bin")
    if run(["mv", f"/{d}/put.bin", f"/{d}/moved.bin"], f"{tag}: mv") is not None:
        R.check(f"{tag}: mv", not os.path.exists(target) and os.path.exists(moved))
    if run(["rm", f"/{d}/moved.bin"], f"{tag}: rm") is not None:
        R.check(f"{tag}: rm", not os.path.exists(moved))
    if run(["rmdir", f"/{d}"], f"{tag}: rmdir") is not None:
        R.check(f"{tag}: rmdir", not os.path.exists(os.path.join(writable_root, d)))

    # failures: a missing file, and leaving the root, exit non-zero
    for args in (["get", "/no-such-file", os.path.join(local_dir, "x")],
                 ["get", "../outside/secret.txt", os.path.join(local_dir, "x")],
                 ["rm", "/no-such-file"]):
        rc, out, err, _ = mavstack_ftp(binary, args, conn, extra)
        R.check(f"{tag}: {args[0]} {args[1]} fails", rc != 0 and err.strip() != ""
                and not os.path.exists(os.path.join(local_dir, "x")),
                f"exit {rc}, stderr {err.strip()[-200:]!r}")


# ---------------------------------------------------------------- 3: MAVSDK's ftp_server

def mavsdk_server(binary, base, files, work, big_mb):
    tag = "3 mavstack-ftp→mavsdk-server"
    try:
        from mavsdk.component_type import ComponentType
        from mavsdk.mavsdk import Configuration, Mavsdk
        from mavsdk.plugins.ftp_server import FtpServer
    except Exception as e:  # noqa: BLE001
        R.fail(f"{tag}: import mavsdk ftp_server", f"{type(e).__name__}: {e}")
        return
    root = os.path.join(os.path.dirname(base), "mavsdk-root")
    os.makedirs(os.path.join(root, DEEP))
    for rel, data in files.items():
        with open(os.path.join(root, rel), "wb") as f:
            f.write(data)
    cfg = Configuration.create_with_component_type(ComponentType.AUTOPILOT)
    sysid, compid = cfg.system_id, cfg.component_id
    mav = Mavsdk(cfg)
    port = free_both()
    server = None
    try:
        mav.add_any_connection(f"udpout://127.0.0.1:{port}")
        comp = mav.server_component()
        server = FtpServer(comp)
        server.set_root_dir(root)
        R.ok(f"{tag}: MAVSDK {mav.version()} serving as system {sysid} component {compid}")
        mavstack_client(binary, f"udpin:127.0.0.1:{port}", root, files, work, tag,
                        extra=["--target-system", str(sysid), "--target-component",
                               str(compid), "--timeout", "10"], vehicle=False)
    finally:
        if server is not None:
            server.destroy()
        mav.destroy()


# ---------------------------------------------------------------- main

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mavstack", required=True)
    ap.add_argument("--big-mb", type=float, default=1.0)
    ap.add_argument("--lossy", action="store_true",
                    help="also run steps 1 and 4 through lossy_relay.py, 20 %% loss each way")
    ap.add_argument("--only-lossy", action="store_true", help="run step 5 alone")
    ap.add_argument("--steps", default="1234", help="which of steps 1-4 to run")
    args = ap.parse_args()
    binary = os.path.abspath(args.mavstack)
    t0 = time.monotonic()

    R.check("crc32 table = bitwise", mavftp_crc32(b"123456789") == _crc_bitwise(b"123456789"))
    rc = subprocess.run([binary, "ftp", "--help"], capture_output=True, check=False).returncode
    if not R.check("mavstack ftp exists", rc == 0, f"`{binary} ftp --help` exits {rc}"):
        return R.summary("ftp_interop", t0)

    quiet_mavsdk()
    work = tempfile.mkdtemp(prefix="ftp-interop-")
    procs = []
    try:
        base = os.path.join(work, "tree")
        root, files, snapshot = make_tree(base, args.big_mb)
        before = snapshot()
        if not args.only_lossy:
            port = free_both()
            vehicle = start_vehicle(binary, f"tcpin:127.0.0.1:{port}", root, work, "tcp")
            procs.append(vehicle)
            timeout = 60 + 30 * args.big_mb
            if "1" in args.steps:
                R.guard("1 pymavlink", pymavlink_client, f"tcp:127.0.0.1:{port}", root, files,
                        work, "1 pymavlink→mavstack", timeout)
            if "2" in args.steps:
                R.guard("2 mavsdk", asyncio.run, mavsdk_client(
                    f"tcpout://127.0.0.1:{port}", root, files, work, "2 mavsdk→mavstack"))
            if "4" in args.steps:
                R.guard("4 mavstack", mavstack_client, binary, f"tcp:127.0.0.1:{port}", root,
                        files, work, "4 mavstack→mavstack")
            R.check("vehicle still running", vehicle.alive(), vehicle.tail())
            vehicle.stop()
            if "3" in args.steps:
                R.guard("3 mavsdk-server", mavsdk_server, binary, base, files, work,
                        args.big_mb)
        if args.lossy or args.only_lossy:
            from lossy_relay import LossyRelay

            for n, step in ((1, "pymavlink"), (4, "mavstack")):
                fwd = free_both()
                relay = LossyRelay(("127.0.0.1", 0), ("127.0.0.1", fwd), loss=0.2, seed=n)
                relay.start()
                vehicle = start_vehicle(binary, f"udpout:127.0.0.1:{relay.listen_port}", root,
                                        work, f"lossy{n}")
                procs.append(vehicle)
                tag = f"5 lossy {step}→mavstack"
                try:
                    if n == 1:
                        R.guard(f"{tag}", pymavlink_client, f"udpin:127.0.0.1:{fwd}", root,
                                files, work, tag, 120 + 60 * args.big_mb, lossy=True)
                    else:
                        R.guard(f"{tag}", mavstack_client, binary, f"udpin:127.0.0.1:{fwd}",
                                root, files, work, tag)
                finally:
                    vehicle.stop()
                    relay.stop()
                st = relay.stats
                print(f"      relay {tag}: up {st['up']['dropped']}/{st['up']['datagrams']} "
                      f"dropped, down {st['down']['dropped']}/{st['down']['datagrams']}",
                      flush=True)
        after = snapshot()
        changed = sorted(k for k in set(before) | set(after) if before.get(k, 0) != after.get(k, 0))
        R.check("nothing outside the served root changed", not changed, f"changed: {changed}")
    finally:
        for p in procs:
            p.stop()
        if R.failed:
            show_mavsdk_log()
            print(f"      (work directory kept: {work})", flush=True)
        else:
            shutil.rmtree(work, ignore_errors=True)
    return R.summary("ftp_interop", t0)


if __name__ == "__main__":
    sys.exit(main())
