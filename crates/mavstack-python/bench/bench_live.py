"""Receive loop on a live UDP stream, mavstack.mavutil against pymavlink's mavutil: messages
handled per CPU second of the receiving process (its runtime thread included).

Receiving: a sender process writes ATTITUDE and GLOBAL_POSITION_INT (pymavlink-encoded, MAVLink 2) as fast
as it can to the receiver's udpin port; the receiver loops over recv_match(blocking=True) for
--seconds and reads one field of each message. `--pack N` puts N frames in each datagram (as
`mavstack router`'s `pack=true` and some radios do): the kernel's cost per datagram, which both
receivers pay once per datagram, is then shared by N messages. Sending: `mav.attitude_send(...)` 50,000 times
to a UDP port read by a thread of the same process (how many arrive is printed); the rate and
the CPU seconds of the process. `--latency`: instead, a sender writes one SYSTEM_TIME every
5 ms stamped with its time.monotonic_ns() (in time_unix_usec) just before sendto; the receiver
subtracts the stamp from time.monotonic_ns() as soon as recv_match returns: p50 and p99 from the
frame given to the socket to Python holding the message, one at a time, for each receiver, and
the receiving process's CPU time per message at that rate (200 a second). Usage:
    bench_live.py [--seconds 5] [--pack 1] [--latency]
"""

import argparse
import os
import socket
import subprocess
import sys
import time

os.environ["MAVLINK20"] = "1"


def sender(port, pack):
    from pymavlink.dialects.v20 import ardupilotmega as apm
    mav = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = []
    for i in range(256):
        frames.append(bytes(mav.attitude_encode(i * 10, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03).pack(mav)))
        frames.append(bytes(mav.global_position_int_encode(i * 10, -353632610, 1491652300, 584000,
                                                           10000, 1, 2, 3, 9000).pack(mav)))
    frames = [b"".join(frames[i:i + pack]) for i in range(0, len(frames), pack)]
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    while True:
        for f in frames:
            try:
                s.sendto(f, ("127.0.0.1", port))
            except OSError:
                pass


def latency_sender(port, period=0.005):
    from pymavlink.dialects.v20 import ardupilotmega as apm
    mav = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    while True:
        frame = bytes(mav.system_time_encode(time.monotonic_ns(), 0).pack(mav))
        s.sendto(frame, ("127.0.0.1", port))
        time.sleep(period)


def latency_receive(which, port, seconds):
    if which == "mavstack":
        from mavstack import mavutil
    else:
        from pymavlink import mavutil
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    conn.recv_match(type="SYSTEM_TIME", blocking=True, timeout=10)
    lat = []
    t0, c0 = time.time(), time.process_time()
    while time.time() - t0 < seconds:
        m = conn.recv_match(type="SYSTEM_TIME", blocking=True, timeout=1)
        now = time.monotonic_ns()
        if m is not None:
            lat.append(now - m.time_unix_usec)
    cpu = time.process_time() - c0
    conn.close()
    lat.sort()
    print("%s %d %.1f %.1f %.1f" % (which, len(lat), lat[len(lat) // 2] / 1000, lat[int(len(lat) * 0.99)] / 1000,
                                    cpu / max(len(lat), 1) * 1e6))


def receive(which, port, seconds):
    if which == "mavstack":
        from mavstack import mavutil
    else:
        from pymavlink import mavutil
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % port)
    conn.recv_match(type="ATTITUDE", blocking=True, timeout=10)
    n = 0
    c0, t0 = time.process_time(), time.time()
    while time.time() - t0 < seconds:
        m = conn.recv_match(type=["ATTITUDE", "GLOBAL_POSITION_INT"], blocking=True, timeout=1)
        if m is not None:
            _ = m.time_boot_ms
            n += 1
    cpu, wall = time.process_time() - c0, time.time() - t0
    if os.environ.get("BENCH_THREADS"):
        tick = os.sysconf("SC_CLK_TCK")
        for tid in os.listdir("/proc/self/task"):
            with open("/proc/self/task/%s/stat" % tid) as f:
                parts = f.read().rsplit(")", 1)[1].split()
            name = open("/proc/self/task/%s/comm" % tid).read().strip()
            print("# thread %s %s cpu %.2f s" % (tid, name, (int(parts[11]) + int(parts[12])) / tick), file=sys.stderr)
    conn.close()
    print("%s %d %.3f %.3f" % (which, n, cpu, wall))


def send_rate(which, count=50000):
    import threading
    if which == "mavstack":
        from mavstack import mavutil
    else:
        from pymavlink import mavutil
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(1.0)
    got = [0]

    def reader():
        try:
            while True:
                rx.recv(300)
                got[0] += 1
        except socket.timeout:
            pass
    th = threading.Thread(target=reader)
    th.start()
    conn = mavutil.mavlink_connection("udpout:127.0.0.1:%d" % rx.getsockname()[1],
                                      source_system=255, source_component=190)
    c0, t0 = time.process_time(), time.time()
    for i in range(count):
        conn.mav.attitude_send(i, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03)
    cpu, wall = time.process_time() - c0, time.time() - t0
    th.join()
    conn.close()
    print("%s %d %.3f %.3f %d" % (which, count, cpu, wall, got[0]))


def latency(seconds):
    for which in ("pymavlink", "mavstack"):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        s.close()
        recv = subprocess.Popen([sys.executable, __file__, "--role", "latency-" + which, "--port", str(port),
                                 "--seconds", str(seconds)], stdout=subprocess.PIPE, text=True)
        time.sleep(1.0)
        send = subprocess.Popen([sys.executable, __file__, "--role", "latency-send", "--port", str(port)])
        out = recv.communicate()[0].split()
        send.kill()
        send.wait()
        _, n, p50, p99, cpu = out
        print("latency %-9s %6d messages one at a time: p50 %7.1f us, p99 %7.1f us, CPU %6.1f us per message"
              % (which, int(n), float(p50), float(p99), float(cpu)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--role", default=None)
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--pack", type=int, default=1)
    ap.add_argument("--latency", action="store_true")
    a = ap.parse_args()
    if a.role == "send":
        return sender(a.port, max(1, a.pack))
    if a.role == "latency-send":
        return latency_sender(a.port)
    if a.role and a.role.startswith("latency-"):
        return latency_receive(a.role[8:], a.port, a.seconds)
    if a.latency:
        return latency(a.seconds)
    if a.role and a.role.startswith("send-"):
        return send_rate(a.role[5:])
    if a.role:
        return receive(a.role, a.port, a.seconds)
    for which in ("pymavlink", "mavstack"):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        s.close()
        recv = subprocess.Popen([sys.executable, __file__, "--role", which, "--port", str(port),
                                 "--seconds", str(a.seconds)], stdout=subprocess.PIPE, text=True)
        time.sleep(1.0)
        send = subprocess.Popen([sys.executable, __file__, "--role", "send", "--port", str(port),
                                 "--pack", str(a.pack)])
        out = recv.communicate()[0].split()
        send.kill()
        send.wait()
        _, n, cpu, wall = out
        n, cpu, wall = int(n), float(cpu), float(wall)
        print("receive %-9s (%d a datagram) %8d messages in %.2f s, %.2f CPU s: %9.0f messages per CPU second, %9.0f per second"
              % (which, a.pack, n, wall, cpu, n / cpu, n / wall))
    for which in ("pymavlink", "mavstack"):
        out = subprocess.run([sys.executable, __file__, "--role", "send-" + which], check=True,
                             stdout=subprocess.PIPE, text=True).stdout.split()
        _, n, cpu, wall, got = out
        n, cpu, wall, got = int(n), float(cpu), float(wall), int(got)
        print("send    %-9s %8d attitude_send in %.2f s (%.0f per second), %.2f CPU s with the reader; %d arrived"
              % (which, n, wall, n / wall, cpu, got))


if __name__ == "__main__":
    main()
