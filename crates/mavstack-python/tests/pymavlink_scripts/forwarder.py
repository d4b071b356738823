"""A two-link forwarder: every message from one link written to the other, as it came."""
import sys
import time

from pymavlink import mavutil

vehicle = mavutil.mavlink_connection(sys.argv[1])
gcs = mavutil.mavlink_connection(sys.argv[2])
if vehicle.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
seen = {"to gcs": set(), "to vehicle": set()}
deadline = time.time() + 20
answered = False
while time.time() < deadline and not answered:
    for src, dst, way in ((vehicle, gcs, "to gcs"), (gcs, vehicle, "to vehicle")):
        m = src.recv_msg()
        while m is not None:
            dst.write(m.get_msgbuf())
            seen[way].add(m.get_type())
            if way == "to gcs" and m.get_type() == "PARAM_VALUE" and m.param_id == "RTL_ALT":
                answered = True
            m = src.recv_msg()
    time.sleep(0.005)
print("forwarded HEARTBEAT to gcs %s" % ("HEARTBEAT" in seen["to gcs"]))
print("forwarded PARAM_REQUEST_READ to vehicle %s" % ("PARAM_REQUEST_READ" in seen["to vehicle"]))
print("answer forwarded %s" % answered)
vehicle.close()
gcs.close()
