"""A live link with pymavlink's API: the first vehicle's heartbeat, its mode, a parameter set
and read back, then its attitude at 10 Hz for a few seconds.

    python live_link.py udpin:0.0.0.0:14550 [SECONDS]

Typed: `mypy --strict` and pyright (strict) pass on it; `m.roll` is a float because
`recv_match(type="ATTITUDE")` returns the ATTITUDE message's class (mavstack.messages).
"""

import sys
import time
from typing import TYPE_CHECKING, List

from mavstack import mavutil

if TYPE_CHECKING:
    from mavstack.messages.ardupilotmega import MAVLink_attitude_message


def attitude_for(conn: mavutil.mavlive, seconds: float) -> List["MAVLink_attitude_message"]:
    """The ATTITUDE messages received within `seconds`."""
    got: List["MAVLink_attitude_message"] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        m = conn.recv_match(type="ATTITUDE", blocking=True, timeout=0.5)
        if m is not None:
            got.append(m)
    return got


def main() -> int:
    device = sys.argv[1] if len(sys.argv) > 1 else "udpin:0.0.0.0:14550"
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 3.0
    conn = mavutil.mavlink_connection(device)
    if not isinstance(conn, mavutil.mavlive):
        print("%s is a log file, not a live link" % device)
        return 2
    hb = conn.wait_heartbeat(timeout=10)
    if hb is None:
        print("no heartbeat")
        return 1
    print("vehicle %d type %d autopilot %d mode %s" % (conn.target_system, hb.type, hb.autopilot,
                                                     conn.flightmode))
    conn.param_set_send("RTL_ALT", 3000)
    conn.param_fetch_one("RTL_ALT")
    p = conn.recv_match(type="PARAM_VALUE", condition='PARAM_VALUE.param_id == "RTL_ALT"',
                        blocking=True, timeout=5)
    if p is not None:
        print("parameter %s = %g" % (p.param_id, p.param_value))
    conn.mav.command_long_send(conn.target_system, conn.target_component,
                               mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                               mavutil.mavlink.MAVLINK_MSG_ID_ATTITUDE, 100000, 0, 0, 0, 0, 0)
    att = attitude_for(conn, seconds)
    if att:
        print("%d ATTITUDE, last roll %.3f rad pitch %.3f rad" % (len(att), att[-1].roll,
                                                                 att[-1].pitch))
    conn.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
