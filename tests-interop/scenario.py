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


def main(scenarios, doc):
    """The command line of a scenario script: `SCENARIO --mavstack BIN`; runs it, prints
    "<scenario>: <summary> (<seconds> s) ok" and exits 0, or exits 1 after the FAIL lines (a
    crash of the harness is a failure with its reason, never a pass)."""
    import argparse
    import os

    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenario", choices=sorted(scenarios))
    ap.add_argument("--mavstack", required=True)
    a = ap.parse_args()
    if not (os.path.isfile(a.mavstack) and os.access(a.mavstack, os.X_OK)):
        print("FAIL: mavstack binary %s is not an executable file" % a.mavstack, file=sys.stderr)
        sys.exit(1)
    t0 = time.monotonic()
    try:
        summary = scenarios[a.scenario](a.mavstack)
    except Exception as e:
        import traceback

        traceback.print_exc()
        fail("%s crashed: %r" % (a.scenario, e))
        summary = None
    if failures:
        print("%s: %d failures" % (a.scenario, len(failures)), file=sys.stderr)
        sys.exit(1)
    if summary is None:
        print("FAIL: %s ended early without a failure" % a.scenario, file=sys.stderr)
        sys.exit(1)
    print("%s: %s (%.1f s) ok" % (a.scenario, summary, time.monotonic() - t0))
