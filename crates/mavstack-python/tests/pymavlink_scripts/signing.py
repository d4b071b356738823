"""Signing setup: SETUP_SIGNING to the vehicle, then signed traffic both ways."""
import sys
import time

from pymavlink import mavutil

KEY = bytes(range(32))
conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
ts, tc = conn.target_system, conn.target_component
stamp = int((time.time() - 1420070400) * 100000)
conn.mav.setup_signing_send(ts, tc, list(KEY), stamp)
conn.setup_signing(KEY, sign_outgoing=True)
# Answers come signed now: the next HEARTBEAT and a parameter read.
hb = None
deadline = time.time() + 5
while time.time() < deadline:
    hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=2)
    if hb is not None and hb.get_signed():
        break
print("heartbeat signed %s" % (hb is not None and hb.get_signed()))
conn.mav.param_request_read_send(ts, tc, b"RTL_ALT", -1)
pv = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=5)
print("param answer %s signed %s" % (pv.param_id if pv else None, pv.get_signed() if pv else None))
conn.close()
