"""A log read message by message with pymavlink's API: the message counts per type, the
largest roll, and the GPS fixes as (time, lat, lon).

    python log_reading.py flight.tlog

Typed: `mypy --strict` and pyright (strict) pass on it.
"""

import sys
from collections import Counter
from typing import List, Tuple

from mavstack import mavutil


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    log = mavutil.mavlink_connection(sys.argv[1], dialect="ardupilotmega")
    if not isinstance(log, mavutil.mavlogfile):
        print("%s is not a log file" % sys.argv[1])
        return 2
    counts: "Counter[str]" = Counter()
    for m in log:
        counts[m.get_type()] += 1
    for name, n in counts.most_common(5):
        print("%-24s %d" % (name, n))

    log.rewind()
    max_roll = 0.0
    while (att := log.recv_match(type="ATTITUDE")) is not None:
        max_roll = max(max_roll, abs(att.roll))
    print("largest |roll|: %.3f rad" % max_roll)

    log.rewind()
    fixes: List[Tuple[float, float, float]] = []
    while (gps := log.recv_match(type="GLOBAL_POSITION_INT")) is not None:
        fixes.append((gps._timestamp, gps.lat / 1e7, gps.lon / 1e7))
    if fixes:
        t, lat, lon = fixes[-1]
        print("%d positions, last at %.1f: %.6f, %.6f" % (len(fixes), t, lat, lon))
    print(log.stats())
    return 0


if __name__ == "__main__":
    sys.exit(main())
