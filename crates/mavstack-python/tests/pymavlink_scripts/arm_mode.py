"""Change mode, arm and disarm, as pymavlink's helpers do it (each asked again until the
vehicle's HEARTBEAT shows it: the script runs through a lossy link too)."""
import sys
import time

from pymavlink import mavutil

conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
print("mode %s armed %s" % (conn.flightmode, bool(conn.motors_armed())))
print("GUIDED is %s" % conn.mode_mapping()["GUIDED"])


def until(action, pred, what):
    for _ in range(10):
        action()
        deadline = time.time() + 1.5
        while time.time() < deadline:
            if conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5) and pred():
                return
    sys.exit("timed out: " + what)


def acked(action, command):
    for _ in range(10):
        action()
        ack = conn.recv_match(type="COMMAND_ACK", condition="COMMAND_ACK.command == %d" % command,
                              blocking=True, timeout=1)
        if ack is not None:
            return ack.result
    sys.exit("no COMMAND_ACK for %d" % command)


print("set_mode ack %d" % acked(lambda: conn.set_mode("GUIDED"), 176))
until(lambda: None, lambda: conn.flightmode == "GUIDED", "GUIDED")
print("mode %s" % conn.flightmode)
print("arm ack %d" % acked(conn.arducopter_arm, 400))
until(conn.arducopter_arm, lambda: conn.motors_armed(), "armed")
print("armed %s" % bool(conn.motors_armed()))
print("disarm ack %d" % acked(conn.arducopter_disarm, 400))
until(conn.arducopter_disarm, lambda: not conn.motors_armed(), "disarmed")
print("armed %s" % bool(conn.motors_armed()))
until(lambda: conn.set_mode(conn.mode_mapping()["LOITER"]), lambda: conn.flightmode == "LOITER", "LOITER")
print("mode %s" % conn.flightmode)
conn.close()
