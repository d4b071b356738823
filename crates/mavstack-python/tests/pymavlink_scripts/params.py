"""Fetch all parameters, then set one and read it back."""
import hashlib
import sys
import time

from pymavlink import mavutil

conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
conn.param_fetch_all()
params, count = {}, None
deadline = time.time() + 20
while time.time() < deadline and (count is None or len(params) < count):
    m = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
    if m is None:
        # A lost PARAM_VALUE: ask for the missing ones by index.
        for i in range(count or 0):
            if i not in [p[1] for p in params.values()]:
                conn.mav.param_request_read_send(conn.target_system, conn.target_component, b"", i)
        continue
    count = m.param_count
    params[m.param_id] = (m.param_value, m.param_index)
print("parameters %d of %s" % (len(params), count))
table = "".join("%s=%r\n" % (k, params[k][0]) for k in sorted(params))
print("table sha1 %s" % hashlib.sha1(table.encode()).hexdigest())
name = sorted(params)[0]
print("first %s = %r" % (name, params[name][0]))
conn.param_set_send("RTL_ALT", 3000)
m = conn.recv_match(type="PARAM_VALUE", condition='PARAM_VALUE.param_id == "RTL_ALT"', blocking=True, timeout=5)
print("set RTL_ALT -> %r" % (m.param_value if m else None))
conn.param_fetch_one("RTL_ALT")
m = conn.recv_match(type="PARAM_VALUE", condition='PARAM_VALUE.param_id == "RTL_ALT"', blocking=True, timeout=5)
print("read back RTL_ALT = %r" % (m.param_value if m else None))
conn.close()
