"""Signing setup: SETUP_SIGNING to the vehicle, then signed traffic both ways (asked again
when lost: the script runs through a lossy link too)."""
import sys
import time

from pymavlink import mavutil

KEY = bytes(range(32))
conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
ts, tc = conn.target_system, conn.target_component
conn.setup_signing(KEY, sign_outgoing=True)
hb = None
for _ in range(10):
    stamp = int((time.time() - 1420070400) * 100000)
    conn.mav.setup_signing_send(ts, tc, list(KEY), stamp)
    # Answers come signed once the vehicle has the key (unsigned ones are refused now).
    hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=1.5)
    if hb is not None and hb.get_signed():
        break
print("heartbeat signed %s" % (hb is not None and hb.get_signed()))
pv = None
for _ in range(10):
    conn.mav.param_request_read_send(ts, tc, b"RTL_ALT", -1)
    pv = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
    if pv is not None:
        break
print("param answer %s signed %s" % (pv.param_id if pv else None, pv.get_signed() if pv else None))
conn.close()
