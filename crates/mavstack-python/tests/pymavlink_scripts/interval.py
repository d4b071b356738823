"""Request a message interval: SET_MESSAGE_INTERVAL, then the rate it gives."""
import sys
import time

from pymavlink import mavutil

M = mavutil.mavlink
conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
conn.mav.command_long_send(conn.target_system, conn.target_component, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                           M.MAVLINK_MSG_ID_ATTITUDE if hasattr(M, "MAVLINK_MSG_ID_ATTITUDE") else 30,
                           100000, 0, 0, 0, 0, 0)
ack = conn.recv_match(type="COMMAND_ACK", condition="COMMAND_ACK.command == 511", blocking=True, timeout=5)
print("ack %d result %d" % (ack.command, ack.result))
conn.mav.command_long_send(conn.target_system, conn.target_component, M.MAV_CMD_REQUEST_MESSAGE, 0,
                           244, 30, 0, 0, 0, 0, 0)
mi = conn.recv_match(type="MESSAGE_INTERVAL", blocking=True, timeout=5)
print("MESSAGE_INTERVAL %d %d" % (mi.message_id, mi.interval_us))
conn.recv_match(type="ATTITUDE", blocking=True, timeout=5)
start, n = time.time(), 0
while time.time() - start < 3.0:
    if conn.recv_match(type="ATTITUDE", blocking=True, timeout=1):
        n += 1
print("about 10 Hz %s" % (7 <= n / 3.0 <= 13))
conn.close()
