"""Request a message interval: SET_MESSAGE_INTERVAL, then the interval and the rate it gives
(requests asked again when lost: the script runs through a lossy link too)."""
import sys
import time

from pymavlink import mavutil

M = mavutil.mavlink
conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
ts, tc = conn.target_system, conn.target_component


def ask(send, mtype, cond):
    for _ in range(10):
        send()
        m = conn.recv_match(type=mtype, condition=cond, blocking=True, timeout=1)
        if m is not None:
            return m
    sys.exit("no " + mtype)


ack = ask(lambda: conn.mav.command_long_send(ts, tc, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                             M.MAVLINK_MSG_ID_ATTITUDE, 100000, 0, 0, 0, 0, 0),
          "COMMAND_ACK", "COMMAND_ACK.command == 511")
print("ack %d result %d" % (ack.command, ack.result))
mi = ask(lambda: conn.mav.command_long_send(ts, tc, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                            M.MAVLINK_MSG_ID_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE,
                                            0, 0, 0, 0, 0),
         "MESSAGE_INTERVAL", "MESSAGE_INTERVAL.message_id == 30")
print("MESSAGE_INTERVAL %d %d" % (mi.message_id, mi.interval_us))
conn.recv_match(type="ATTITUDE", blocking=True, timeout=5)
start, n = time.time(), 0
while time.time() - start < 3.0:
    if conn.recv_match(type="ATTITUDE", blocking=True, timeout=1):
        n += 1
print("between 5 and 13 Hz %s" % (5 <= n / 3.0 <= 13))
conn.close()
