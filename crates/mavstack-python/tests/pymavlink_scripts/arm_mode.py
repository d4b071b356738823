"""Change mode, arm and disarm, as pymavlink's helpers do it."""
import sys
import time

from pymavlink import mavutil

conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
print("mode %s armed %s" % (conn.flightmode, bool(conn.motors_armed())))
print("GUIDED is %s" % conn.mode_mapping()["GUIDED"])


def wait(pred, what):
    deadline = time.time() + 10
    while time.time() < deadline:
        if conn.recv_match(type="HEARTBEAT", blocking=True, timeout=2) and pred():
            return True
    sys.exit("timed out: " + what)


conn.set_mode("GUIDED")
ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
print("set_mode ack %d %d" % (ack.command, ack.result))
wait(lambda: conn.flightmode == "GUIDED", "GUIDED")
print("mode %s" % conn.flightmode)
conn.arducopter_arm()
ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
print("arm ack %d %d" % (ack.command, ack.result))
wait(lambda: conn.motors_armed(), "armed")
print("armed %s" % bool(conn.motors_armed()))
conn.arducopter_disarm()
ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
print("disarm ack %d %d" % (ack.command, ack.result))
wait(lambda: not conn.motors_armed(), "disarmed")
print("armed %s" % bool(conn.motors_armed()))
conn.set_mode(conn.mode_mapping()["LOITER"])
wait(lambda: conn.flightmode == "LOITER", "LOITER")
print("mode %s" % conn.flightmode)
conn.close()
