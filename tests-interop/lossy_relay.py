#!/usr/bin/env python3
"""A tiny UDP relay that drops a fraction of datagrams each way (seeded, so reproducible) and
may delay the rest by a fixed time each way (a radio link's latency).

    vehicle --udpout--> [listen]  relay  [ephemeral] --> forward (a GCS on udpin)
    vehicle <---------- [listen]  relay  [ephemeral] <-- GCS replies

The side that sends first to `--listen` is the "near" peer (e.g. `mavstack vehicle
udpout:127.0.0.1:LISTEN`); datagrams from it go to `--forward` (e.g. MAVProxy
`--master=udpin:127.0.0.1:FORWARD`), whose replies come back to the relay's other socket and go
to the near peer's last address. Each direction has its own random stream, so the drop pattern
of one does not depend on the traffic of the other.

Command line (runs until SIGINT/SIGTERM, then prints a JSON line of counters on stderr):

    lossy_relay.py --listen 127.0.0.1:14600 --forward 127.0.0.1:14550 --loss 0.2 --seed 1 \
        [--delay-ms 100]

As a library:

    relay = LossyRelay(("127.0.0.1", 0), ("127.0.0.1", gcs_port), loss=0.2, seed=1)
    relay.start()            # a daemon thread; relay.listen_port is where the vehicle sends
    ...
    relay.stop(); relay.stats  # {"up": {...}, "down": {...}}
"""

import argparse
import heapq
import itertools
import json
import random
import select
import signal
import socket
import sys
import threading
import time


def _addr(text):
    host, _, port = text.rpartition(":")
    return (host or "127.0.0.1", int(port))


class LossyRelay:
    """Relays datagrams between one near peer and one far address, dropping some."""

    def __init__(self, listen, forward, loss=0.2, seed=1, loss_up=None, loss_down=None,
                 tap=None, delay=0.0):
        # tap(way, datagram, dropped), if given, sees every datagram ("up": near -> far)
        self.tap = tap
        # delay: seconds each datagram kept is held before it goes on (each way), in order
        self.delay = delay
        self._held = []  # heap of (due, n, sock, data, dest)
        self._n = itertools.count()
        self.forward = forward
        self.loss_up = loss if loss_up is None else loss_up  # near -> far
        self.loss_down = loss if loss_down is None else loss_down  # far -> near
        self._rng_up = random.Random(f"{seed}/up")
        self._rng_down = random.Random(f"{seed}/down")
        self.near = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.far = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for s in (self.near, self.far):
            # Room for a burst (a whole parameter list is ~1,000 datagrams): the relay
            # must lose only what it chooses to drop.
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 8 << 20)
        self.near.bind(listen)
        self.far.bind((listen[0], 0))
        self.listen_port = self.near.getsockname()[1]
        self.near_peer = None
        self.stats = {
            "up": {"datagrams": 0, "dropped": 0, "bytes": 0},
            "down": {"datagrams": 0, "dropped": 0, "bytes": 0, "no_peer": 0},
        }
        self._stop = threading.Event()
        self._thread = None

    def start(self):
        self._thread = threading.Thread(target=self.run, name="lossy-relay", daemon=True)
        self._thread.start()
        return self

    def stop(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2)
        self.near.close()
        self.far.close()

    def run(self):
        socks = [self.near, self.far]
        while not self._stop.is_set():
            wait = 0.1
            if self._held:
                wait = min(wait, max(0.0, self._held[0][0] - time.monotonic()))
            try:
                ready, _, _ = select.select(socks, [], [], wait)
            except (OSError, ValueError):
                return
            self._release()
            for sock in ready:
                try:
                    data, addr = sock.recvfrom(65535)
                except OSError:
                    continue
                if sock is self.near:
                    self.near_peer = addr
                    self._pass("up", data, self._rng_up, self.loss_up, self.far, self.forward)
                elif addr == self.forward or addr[1] == self.forward[1]:
                    if self.near_peer is None:
                        self.stats["down"]["no_peer"] += 1
                        continue
                    self._pass(
                        "down", data, self._rng_down, self.loss_down, self.near, self.near_peer
                    )

    def _pass(self, way, data, rng, loss, sock, dest):
        st = self.stats[way]
        st["datagrams"] += 1
        st["bytes"] += len(data)
        dropped = rng.random() < loss
        if self.tap is not None:
            self.tap(way, data, dropped)
        if dropped:
            st["dropped"] += 1
            return
        if self.delay > 0:
            heapq.heappush(self._held, (time.monotonic() + self.delay, next(self._n), sock, data, dest))
            return
        self._send(sock, data, dest)

    def _release(self):
        now = time.monotonic()
        while self._held and self._held[0][0] <= now:
            _, _, sock, data, dest = heapq.heappop(self._held)
            self._send(sock, data, dest)

    @staticmethod
    def _send(sock, data, dest):
        try:
            sock.sendto(data, dest)
        except OSError:
            pass  # the far side is not listening yet: a lost datagram like any other


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--listen", type=_addr, required=True, help="HOST:PORT the near peer sends to")
    ap.add_argument("--forward", type=_addr, required=True, help="HOST:PORT of the far peer")
    ap.add_argument("--loss", type=float, default=0.2, help="drop probability each way")
    ap.add_argument("--loss-up", type=float, help="near -> far drop probability")
    ap.add_argument("--loss-down", type=float, help="far -> near drop probability")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--delay-ms", type=float, default=0.0, help="hold each datagram this long (each way)")
    args = ap.parse_args()
    relay = LossyRelay(args.listen, args.forward, args.loss, args.seed, args.loss_up, args.loss_down,
                       delay=args.delay_ms / 1000.0)
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    relay.start()
    print(json.dumps({"listen_port": relay.listen_port}), flush=True)
    while not done.wait(0.5):
        pass
    relay.stop()
    print(json.dumps(relay.stats), file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
