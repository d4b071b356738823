"""Stream ATTITUDE and print it: 20 messages at the vehicle's rate."""
import math
import sys

from pymavlink import mavutil

conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
conn.mav.request_data_stream_send(conn.target_system, conn.target_component,
                                  mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
got = []
while len(got) < 20:
    m = conn.recv_match(type="ATTITUDE", blocking=True, timeout=5)
    if m is None:
        sys.exit("ATTITUDE stopped after %d" % len(got))
    got.append(m)
print("ATTITUDE x%d from %d" % (len(got), got[0].get_srcSystem()))
print("finite %s" % all(math.isfinite(m.roll) and math.isfinite(m.yaw) for m in got))
print("time_boot_ms never back %s" % all(b.time_boot_ms >= a.time_boot_ms for a, b in zip(got, got[1:])))
print("dict keys %s" % ",".join(got[-1].to_dict()))
print("latest in messages %s" % (conn.messages["ATTITUDE"].time_boot_ms >= got[-1].time_boot_ms))
conn.close()
