"""pymavlink's ``mavutil`` entry point for logs, at native speed.

``mavlink_connection(path, dialect=...)`` takes the arguments pymavlink's does for a log file
and returns a reader with pymavlink's ``recv_match``, ``recv_msg``, iteration and
``messages``. Only files: for serial ports and sockets use pymavlink or the ``mavstack`` CLI.
"""

import os

from mavstack._native import mavlogfile, open_log

__all__ = ["mavlink_connection", "mavlogfile"]

# pymavlink's keyword arguments that mean nothing for reading a log file.
_IGNORED = {
    "baud", "source_system", "source_component", "planner_format", "robust_parsing",
    "notimestamps", "input", "autoreconnect", "zero_time_base", "retries", "reconnect_delay",
    "use_native", "force_connected", "progress_callback", "udp_timeout",
}


def mavlink_connection(device, dialect="ardupilotmega", key=None, **kwargs):
    """Opens the log ``device`` (a path): ``.tlog`` by its extension, anything else as raw
    frames (``_timestamp`` 0.0 there).

    ``dialect`` is a built-in dialect's name (``mavstack.dialects()``) or an XML file's path.
    ``key`` (32 bytes, or 64 hex digits) verifies signatures: frames whose signature fails or
    replays an older timestamp are dropped and counted, verified ones have ``get_signed()``.
    pymavlink's other keyword arguments (``robust_parsing``, ``notimestamps``, ...) are
    accepted and have no effect, but ``write=True`` is refused: the reader is read-only.
    """
    if kwargs.pop("write", False) or kwargs.pop("append", False):
        raise ValueError("mavstack.mavutil.mavlink_connection reads logs; it does not write them")
    unknown = sorted(set(kwargs) - _IGNORED)
    if unknown:
        raise TypeError("mavlink_connection: unexpected keyword argument(s): %s" % ", ".join(unknown))
    return open_log(os.fspath(device), dialect=dialect, key=key)
