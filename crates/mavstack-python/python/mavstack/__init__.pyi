from mavstack import mavutil as mavutil
from mavstack._native import (
    LatestMessages as LatestMessages,
    MAVLinkHeader as MAVLinkHeader,
    MAVLinkMessage as MAVLinkMessage,
    Table as Table,
    __version__ as __version__,
    dialects as dialects,
    mavlogfile as mavlogfile,
    read_tlog as read_tlog,
)

__all__ = [
    "LatestMessages",
    "MAVLinkHeader",
    "MAVLinkMessage",
    "Table",
    "__version__",
    "dialects",
    "mavlogfile",
    "mavutil",
    "read_tlog",
]
