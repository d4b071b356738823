"""What the scenario scripts (version_interop.py, router_interop.py, ...) share: the failure
list a run reports at its end, free ports, the signing clock."""
import random
import socket
import sys
import time

EPOCH_2015 = 1420070400  # the signing epoch, 2015-01-01 00:00:00 UTC, in Unix seconds

failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL: " + msg, file=sys.stderr)


def check(cond, msg):
    if not cond:
        fail(msg)
    return bool(cond)


# Ports handed out: below Linux's ephemeral range (32768-60999), so that no socket bound to
# port 0 (another scenario's, a peer's) takes one between our check and its use, and picked
# at random, so that scenarios running at once rarely pick the same one. (Asking the kernel
# for a free port and closing it hands the same port to two scripts that ask in turn.)
_PORTS = (20000, 32767)
_rng = random.SystemRandom()


def free_port(kind=socket.SOCK_DGRAM, host="127.0.0.1"):
    """A port that is free on `host` for UDP and TCP alike (`kind` is kept for callers that
    say which one they need)."""
    del kind
    while True:
        port = _rng.randint(*_PORTS)
        try:
            for k in (socket.SOCK_DGRAM, socket.SOCK_STREAM):
                with socket.socket(socket.AF_INET, k) as s:
                    s.bind((host, port))
        except OSError:
            continue
        return port


def signing_now():
    """The signing timestamp of now: 10 us units since 2015-01-01 (as mavutil.setup_signing)."""
    return int((time.time() - EPOCH_2015) * 100 * 1000)
