#!/usr/bin/env python3
"""New UDP sources flooding `mavstack router`, then a real ground station through it.

    router_flood.py --mavstack BIN [--max-peers N] [--datagrams D]

The router has two links: `udpin:127.0.0.1:V?name=vehicle`, where `BIN vehicle udpout:127.0.0.1:V`
runs, and `udpin:127.0.0.1:G?name=gcs&max_peers=N`. D datagrams reach G, each from a source
port of its own (a socket each): every other one garbage (random bytes that hold no MAVLink
frame), the rest a HEARTBEAT packed by pymavlink 2.4.50 (each from a system id of its own).
Then a pymavlink ground station on a new port of its own sends HEARTBEATs to G until the
vehicle's HEARTBEAT comes back (the flood's peers must fall quiet for 3 s before one makes room)
and fetches every parameter (PARAM_REQUEST_LIST; missing indices asked by PARAM_REQUEST_READ).

Checks, on the router's stats objects and on what pymavlink decoded:
 1. after the flood, and again at the end: at most N entries of link `gcs` (one per peer);
 2. `dropped` of link `gcs` counts `not_mavlink` (the garbage made no peer) and `peer_refused`
    (HEARTBEATs from new sources while the link was full of busy peers);
 3. the ground station gets every parameter: param_count of them, each index once;
 4. the router exits 0 on SIGTERM.

Prints "router_flood: ... ok" and exits 0, or FAIL lines and exit 1.
"""

import argparse
import os
import random
import socket
import sys
import tempfile
import time

os.environ.setdefault("MAVLINK20", "1")
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from pymavlink import mavutil  # noqa: E402

import gcs_common as gc  # noqa: E402

M = mavutil.mavlink


def flood(port, datagrams, seed=7):
    """Sends `datagrams` datagrams to 127.0.0.1:port, each from a socket of its own; returns
    (garbage, heartbeats) sent."""
    rng = random.Random(seed)
    garbage = heartbeats = 0
    for i in range(datagrams):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            s.bind(("127.0.0.1", 0))
            if i % 2 == 0:
                # No 0xFD or 0xFE: nothing a parser could take for the start of a frame.
                data = bytes(rng.choice([b for b in range(256) if b not in (0xFD, 0xFE)])
                             for _ in range(rng.randint(1, 64)))
                garbage += 1
            else:
                mav = M.MAVLink(None, srcSystem=1 + (i // 2) % 250, srcComponent=190)
                data = mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav)
                heartbeats += 1
            s.sendto(data, ("127.0.0.1", port))
        finally:
            s.close()
    return garbage, heartbeats


def peers_of(stats, name):
    return [e for e in gc.link_stats(stats, name) if e.get("peer") is not None]


def wait_stats(router, after, timeout=5.0):
    """The first stats object printed after `after` stats objects."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        all_ = router.stats()
        if len(all_) > after:
            return all_[-1]
        router.check_alive()
        time.sleep(0.1)
    gc.fail(f"no stats object from the router within {timeout} s\n{router.describe()}")
    return None


def fetch_params(gcs, target, timeout=30.0):
    """Every parameter of `target` by PARAM_REQUEST_LIST, gaps asked again by index: {index: name}
    and the param_count."""
    got, count = {}, None
    gcs.mav.param_request_list_send(*target)
    deadline = time.monotonic() + timeout
    last = time.monotonic()
    while time.monotonic() < deadline:
        m = gcs.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
        if m is not None and m.get_srcSystem() == target[0]:
            count = m.param_count
            got[m.param_index] = m.param_id
            last = time.monotonic()
            if len(got) == count:
                return got, count
            continue
        if count is not None and time.monotonic() - last > 1.0:
            for i in range(count):
                if i not in got:
                    gcs.mav.param_request_read_send(target[0], target[1], b"", i)
            last = time.monotonic()
        elif count is None and time.monotonic() - last > 2.0:
            gcs.mav.param_request_list_send(*target)
            last = time.monotonic()
    return got, count


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mavstack")
    ap.add_argument("--max-peers", type=int, default=16)
    ap.add_argument("--datagrams", type=int, default=5000)
    args = ap.parse_args()
    binary = gc.mavstack_bin(args.mavstack)
    workdir = tempfile.mkdtemp(prefix="router-flood-")
    router = vehicle = gcs = None
    n = args.max_peers
    try:
        for attempt in range(3):
            vport, gport = gc.free_udp_port(), gc.free_udp_port()
            links = [f"udpin:127.0.0.1:{vport}?name=vehicle",
                     f"udpin:127.0.0.1:{gport}?name=gcs&max_peers={n}"]
            try:
                router = gc.Router(binary, links, workdir)
                break
            except gc.Failure as e:
                if attempt == 2 or "in use" not in str(e).lower():
                    raise
        vehicle = gc.Vehicle(binary, f"udpout:127.0.0.1:{vport}", workdir=workdir)

        garbage, heartbeats = flood(gport, args.datagrams)
        seen = len(router.stats())
        stats = wait_stats(router, seen)
        peers = peers_of(stats, "gcs")
        if len(peers) > n:
            gc.fail(f"after {garbage} garbage datagrams and {heartbeats} HEARTBEATs from new sources, "
                    f"link gcs has {len(peers)} peers, more than max_peers={n}\n{router.describe()}")
        dropped = gc.link_dropped(stats, "gcs")
        if not 0 < dropped.get("not_mavlink", 0) <= garbage:
            gc.fail(f"link gcs: not_mavlink {dropped.get('not_mavlink')} after {garbage} garbage "
                    f"datagrams from new sources\n{router.describe()}")
        if dropped.get("peer_refused", 0) == 0:
            gc.fail(f"link gcs: no peer_refused after {heartbeats} HEARTBEATs from new sources "
                    f"with max_peers={n}\n{router.describe()}")

        # A real ground station from a new port: its HEARTBEATs get it a place once the flood's
        # peers have been quiet long enough.
        gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{gport}", source_system=255,
                                         source_component=190)
        hb = None
        deadline = time.monotonic() + 20.0
        while hb is None and time.monotonic() < deadline:
            gcs.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            m = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if m is not None and m.get_srcSystem() == 1 and m.type != M.MAV_TYPE_GCS:
                hb = m
        if hb is None:
            gc.fail(f"no vehicle HEARTBEAT through the router within 20 s after the flood\n"
                    f"{router.describe()}")
        target = (hb.get_srcSystem(), hb.get_srcComponent())
        got, count = fetch_params(gcs, target)
        if count is None or len(got) != count or sorted(got) != list(range(count)):
            gc.fail(f"parameter fetch through the router: {len(got)} of {count} "
                    f"(missing {[i for i in range(count or 0) if i not in got][:10]})\n"
                    f"{router.describe()}")

        seen = len(router.stats())
        stats = wait_stats(router, seen)
        peers = peers_of(stats, "gcs")
        if len(peers) > n:
            gc.fail(f"link gcs has {len(peers)} peers at the end, more than max_peers={n}")
        refused = gc.link_dropped(stats, "gcs").get("peer_refused", 0)
        router.stop()
        print(f"router_flood: {garbage} garbage + {heartbeats} HEARTBEAT datagrams from new "
              f"sources: at most {n} peers ({len(peers)} at the end), {refused} refused; "
              f"{count} parameters fetched through the router ok")
    except gc.Failure as e:
        print(f"FAIL: {e}")
        if vehicle is not None:
            print(f"--- vehicle log ---\n{vehicle.log(1500)}")
        sys.exit(1)
    finally:
        if gcs is not None:
            gcs.close()
        if vehicle is not None:
            vehicle.stop()
        if router is not None and router.rc is None:
            router.kill()


if __name__ == "__main__":
    main()
