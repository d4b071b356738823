"""Connect and wait for a heartbeat: who the vehicle is, and what pymavlink makes of it."""
import sys

from pymavlink import mavutil

conn = mavutil.mavlink_connection(sys.argv[1])
hb = conn.wait_heartbeat(timeout=10)
if hb is None:
    sys.exit("no HEARTBEAT within 10 s")
print("heartbeat from %d/%d" % (hb.get_srcSystem(), hb.get_srcComponent()))
print("type %d autopilot %d" % (hb.type, hb.autopilot))
print("target %d/%d" % (conn.target_system, conn.target_component))
print("mode %s armed %s" % (conn.flightmode, bool(conn.motors_armed())))
print("fields %s" % ",".join(hb.get_fieldnames()))
print("in messages %s" % ("HEARTBEAT" in conn.messages))
conn.close()
