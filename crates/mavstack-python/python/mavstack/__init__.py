"""mavstack: MAVLink links and logs at native speed.

- ``mavstack.mavutil.mavlink_connection("udpin:0.0.0.0:14550")`` (pymavlink's live strings:
  ``udpin:``, ``udpout:``, ``udpbcast:``, ``tcp:``, ``tcpin:``, a serial device with ``baud``)
  offers pymavlink's live API -- ``wait_heartbeat``, ``recv_match``, ``messages``,
  ``target_system``, ``mav.<message>_send(...)``, ``setup_signing``, ``set_mode`` -- over a
  mavstack node.
- ``mavstack.mavutil.mavlink_connection(path, dialect="ardupilotmega", key=None)`` reads a
  ``.tlog`` (or a raw capture) message by message with pymavlink's API: ``recv_match``,
  ``recv_msg``, iteration, ``messages``; each message has pymavlink's methods and attributes.
- ``mavstack.read_tlog(path, types=None, dialect="ardupilotmega", key=None, progress=False)``
  returns ``{name: Table}``, one Arrow table per message type (the Arrow C stream interface):
  ``pyarrow.table(t)``, ``polars.from_arrow(t)``, ``pyarrow.table(t).to_pandas()``.
"""

from mavstack._native import (
    LatestMessages,
    MAVLinkHeader,
    MAVLinkMessage,
    Table,
    __version__,
    dialects,
    mavlogfile,
    read_tlog,
)
from mavstack import mavutil

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


def __getattr__(name: str) -> object:
    # `mavstack.aio` after a plain `import mavstack`, imported when first used (asyncio
    # takes longer to import than the rest of the package).
    if name == "aio":
        import importlib

        return importlib.import_module("mavstack.aio")
    raise AttributeError("module 'mavstack' has no attribute %r" % name)
