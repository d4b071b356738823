"""Upload a mission with MISSION_ITEM_INT and read it back."""
import sys

from pymavlink import mavutil

M = mavutil.mavlink
conn = mavutil.mavlink_connection(sys.argv[1])
if conn.wait_heartbeat(timeout=10) is None:
    sys.exit("no HEARTBEAT within 10 s")
ts, tc = conn.target_system, conn.target_component
home = (-353632610, 1491652300)
plan = [(M.MAV_CMD_NAV_WAYPOINT, 0, home[0], home[1], 0.0)]
plan += [(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 20.0)]
plan += [(M.MAV_CMD_NAV_WAYPOINT, 2.0, home[0] + 1000 * i, home[1] + 500 * i, 30.0 + i) for i in range(1, 4)]
plan += [(M.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0.0)]


def item(seq):
    cmd, p1, x, y, z = plan[seq]
    return conn.mav.mission_item_int_encode(ts, tc, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, cmd,
                                           0, 1, p1, 0, 0, 0, x, y, z)


conn.mav.mission_count_send(ts, tc, len(plan))
while True:
    m = conn.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True, timeout=5)
    if m is None:
        sys.exit("upload stalled")
    if m.get_type() == "MISSION_ACK":
        print("upload ack %d" % m.type)
        break
    conn.mav.send(item(m.seq))
conn.mav.mission_request_list_send(ts, tc)
m = conn.recv_match(type="MISSION_COUNT", blocking=True, timeout=5)
print("count %d" % m.count)
for seq in range(m.count):
    conn.mav.mission_request_int_send(ts, tc, seq)
    it = conn.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=5)
    print("item %d cmd %d frame %d p1 %r x %d y %d z %r" % (it.seq, it.command, it.frame, it.param1, it.x, it.y, it.z))
conn.mav.mission_ack_send(ts, tc, M.MAV_MISSION_ACCEPTED)
conn.close()
