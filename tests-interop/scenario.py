"""What the scenario scripts (version_interop.py, router_interop.py) share: the failure list a
run reports at its end, free UDP ports, the signing clock."""
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


def free_port():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def signing_now():
    """The signing timestamp of now: 10 us units since 2015-01-01 (as mavutil.setup_signing)."""
    return int((time.time() - EPOCH_2015) * 100 * 1000)
