"""Upload a mission with MISSION_ITEM_INT and read it back (what is lost is asked for again:
the script runs through a lossy link too)."""
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


for attempt in range(10):
    conn.mav.mission_count_send(ts, tc, len(plan))
    ack = None
    while ack is None:
        m = conn.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True, timeout=2)
        if m is None:
            break
        if m.get_type() == "MISSION_ACK":
            ack = m
        else:
            conn.mav.send(item(m.seq))
    if ack is not None and ack.type == M.MAV_MISSION_ACCEPTED:
        break
print("upload ack %s" % (ack.type if ack else None))


def ask(send, mtype, cond=None):
    for _ in range(10):
        send()
        m = conn.recv_match(type=mtype, condition=cond, blocking=True, timeout=1)
        if m is not None:
            return m
    sys.exit("no %s" % mtype)


count = ask(lambda: conn.mav.mission_request_list_send(ts, tc), "MISSION_COUNT").count
print("count %d" % count)
for seq in range(count):
    it = ask(lambda: conn.mav.mission_request_int_send(ts, tc, seq), "MISSION_ITEM_INT",
             "MISSION_ITEM_INT.seq == %d" % seq)
    print("item %d cmd %d frame %d p1 %r x %d y %d z %r" % (it.seq, it.command, it.frame, it.param1, it.x, it.y, it.z))
conn.mav.mission_ack_send(ts, tc, M.MAV_MISSION_ACCEPTED)
conn.close()
