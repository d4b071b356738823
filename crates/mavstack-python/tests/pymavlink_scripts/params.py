"""Fetch all parameters, then set one and read it back; lost messages are asked for again
(the script runs through a lossy link too)."""
import hashlib
import sys
import time

from pymavlink import mavutil

conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
conn.param_fetch_all()
params, count = {}, None
deadline = time.time() + 30
while time.time() < deadline and (count is None or len(params) < count):
    m = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1)
    if m is None:
        if count is None:
            conn.param_fetch_all()
        else:
            # Lost PARAM_VALUEs: ask for the missing ones by index.
            have = {p[1] for p in params.values()}
            for i in range(count):
                if i not in have:
                    conn.mav.param_request_read_send(conn.target_system, conn.target_component, b"", i)
        continue
    count = m.param_count
    params[m.param_id] = (m.param_value, m.param_index, m.param_type)
print("parameters %d of %s" % (len(params), count))
table = "".join("%s=%r\n" % (k, params[k][0]) for k in sorted(params))
print("table sha1 %s" % hashlib.sha1(table.encode()).hexdigest())
name = sorted(params)[0]
print("first %s = %r" % (name, params[name][0]))


# ArduPilot's RTL_ALT, else the first REAL32 parameter (PX4), one more than it was.
if "RTL_ALT" in params:
    target, value = "RTL_ALT", 3000.0
else:
    target = sorted(k for k in params if params[k][2] == mavutil.mavlink.MAV_PARAM_TYPE_REAL32)[0]
    value = params[target][0] + 1


def until(send):
    for _ in range(10):
        send()
        m = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1,
                            condition='PARAM_VALUE.param_id == %r and PARAM_VALUE.param_value == %r' % (target, value))
        if m is not None:
            return m.param_value
    return None


print("set %s -> %r" % (target, until(lambda: conn.param_set_send(target, value))))
print("read back %s = %r" % (target, until(lambda: conn.param_fetch_one(target))))
conn.close()
