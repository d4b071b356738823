"""pymavlink's ``mavutil`` entry point, at native speed: logs and live links.

``mavlink_connection(device, ...)`` takes pymavlink's arguments. A log file's path returns a
reader with pymavlink's ``recv_match``, ``recv_msg``, iteration and ``messages``. pymavlink's
live strings -- ``udpin:HOST:PORT``, ``udpout:HOST:PORT``, ``udpbcast:HOST:PORT``,
``udp:HOST:PORT`` (listening), ``tcp:HOST:PORT``, ``tcpin:HOST:PORT``, a serial device with
``baud`` (or ``DEVICE,BAUD``) -- return a live connection with pymavlink's API (``wait_heartbeat``,
``recv_match``, ``messages``, ``target_system``, ``mav.<message>_send(...)``,
``setup_signing``, ``set_mode``, ...), backed by a ``mavstack`` node: the link's MAVLink
version, signing and framing are the stack's.
"""

import keyword
import os
import re
import time

from mavstack._native import dialect_constants, mavlogfile, open_live, open_log

__all__ = ["mavlink_connection", "mavlogfile", "mavlive", "MAVLink", "mavlink"]


class _Constants:
    """pymavlink's ``mavutil.mavlink`` module as far as scripts use it for numbers: every enum
    entry of the dialect (``$MAVLINK_DIALECT``, else ardupilotmega) by name, read when first
    used, ``MAVLINK_MSG_ID_<NAME>`` of every message, and the ``MAVLINK_TYPE_*`` codes of
    PARAM_SET."""

    def __init__(self):
        self._values = None

    def _load(self):
        if self._values is None:
            values = dict(dialect_constants(os.environ.get("MAVLINK_DIALECT", "ardupilotmega")))
            values.update(MAVLINK_TYPE_CHAR=0, MAVLINK_TYPE_UINT8_T=1, MAVLINK_TYPE_INT8_T=2,
                          MAVLINK_TYPE_UINT16_T=3, MAVLINK_TYPE_INT16_T=4, MAVLINK_TYPE_UINT32_T=5,
                          MAVLINK_TYPE_INT32_T=6, MAVLINK_TYPE_UINT64_T=7, MAVLINK_TYPE_INT64_T=8,
                          MAVLINK_TYPE_FLOAT=9, MAVLINK_TYPE_DOUBLE=10)
            self._values = values
        return self._values

    def __getattr__(self, name):
        try:
            return self._load()[name]
        except KeyError:
            raise AttributeError("mavutil.mavlink has no constant %s" % name) from None

    def __dir__(self):
        return sorted(self._load())


mavlink = _Constants()

# pymavlink's keyword arguments that mean nothing for reading a log file.
_IGNORED = {
    "baud", "source_system", "source_component", "planner_format", "robust_parsing",
    "notimestamps", "input", "autoreconnect", "zero_time_base", "retries", "reconnect_delay",
    "use_native", "force_connected", "progress_callback", "udp_timeout",
}
# ... and for a live link (what the node does its own way: reconnecting, robust parsing).
_IGNORED_LIVE = {
    "planner_format", "robust_parsing", "notimestamps", "input", "autoreconnect",
    "zero_time_base", "retries", "reconnect_delay", "use_native", "force_connected",
    "progress_callback", "udp_timeout",
}
_LIVE_SCHEMES = ("udpin:", "udpout:", "udpbcast:", "udp:", "tcp:", "tcpin:", "serial:")
_HOST_PORT = re.compile(r"^[A-Za-z0-9_.\-]*:\d+$")
_SERIAL = re.compile(r"^(/dev/|COM\d+$|\\\\\.\\)", re.IGNORECASE)

# MAV_CMD_DO_SET_MODE, MAV_CMD_COMPONENT_ARM_DISARM, MAV_PARAM_TYPE_REAL32 (pymavlink's
# MAVLINK_TYPE_FLOAT default for PARAM_SET).
_DO_SET_MODE = 176
_ARM_DISARM = 400
_PARAM_FLOAT = 9


def _live_string(device, baud, listen=True):
    """The connection string for the stack's parser, or None for a file. ``udp:HOST:PORT`` and
    ``HOST:PORT`` listen unless ``listen`` is false (pymavlink's ``input=False``): then they
    send to HOST:PORT."""
    low = device.lower()
    if low.startswith("udp:") and not listen:
        return "udpout:" + device[4:]
    if low.startswith(_LIVE_SCHEMES) or "://" in device:
        return device
    if os.path.isfile(device):
        return None
    if _SERIAL.match(device):
        return device if "," in device else "%s,%d" % (device, int(baud))
    if "," in device and not os.path.exists(device):
        return device
    if _HOST_PORT.match(device):
        # pymavlink reads HOST:PORT as a UDP port to listen on (to send to, with input=False).
        return ("udpin:" if listen else "udpout:") + device
    return None


def mavlink_connection(device, baud=57600, source_system=255, source_component=0,
                       dialect=None, key=None, **kwargs):
    """Opens ``device``: a live link (pymavlink's connection strings, see the module) or a log
    file (``.tlog`` by its extension, anything else as raw frames; ``_timestamp`` 0.0 there).

    ``dialect`` is a built-in dialect's name (``mavstack.dialects()``) or an XML file's path
    (default: ``$MAVLINK_DIALECT``, else ``ardupilotmega``, as pymavlink). ``key`` (32 bytes, or
    64 hex digits) verifies signatures: in a log, frames whose signature fails or replays an
    older timestamp are dropped and counted; on a live link, every frame sent is signed and only
    signed frames are accepted. A live link sends as ``source_system``/``source_component``.
    pymavlink's other keyword arguments are accepted and have no effect, but ``write=True`` is
    refused: the log reader is read-only.
    """
    if dialect is None:
        dialect = os.environ.get("MAVLINK_DIALECT", "ardupilotmega")
    device = os.fspath(device)
    live = _live_string(device, baud, listen=kwargs.get("input", True))
    if live is not None:
        unknown = sorted(set(kwargs) - _IGNORED_LIVE)
        if unknown:
            raise TypeError("mavlink_connection: unexpected keyword argument(s): %s" % ", ".join(unknown))
        if os.environ.get("MAVLINK20") and "version=" not in live:
            # pymavlink speaks MAVLink 2 from the first frame with $MAVLINK20 set.
            live += ("&" if "?" in live else "?") + "version=2"
        return mavlive(live, source_system=source_system, source_component=source_component,
                       dialect=dialect, key=key)
    if kwargs.pop("write", False) or kwargs.pop("append", False):
        raise ValueError("mavstack.mavutil.mavlink_connection reads logs; it does not write them")
    unknown = sorted(set(kwargs) - _IGNORED)
    if unknown:
        raise TypeError("mavlink_connection: unexpected keyword argument(s): %s" % ", ".join(unknown))
    return open_log(device, dialect=dialect, key=key)


_MAV_CLASSES = {}


def _mav_class(link):
    """The ``MAVLink`` class of the link's dialect: ``<message>_encode`` and ``<message>_send``
    for every message, with pymavlink's argument names and order (XML order; extensions last,
    optional, default 0; HEARTBEAT's ``mavlink_version`` default 3). Made once per dialect."""
    cls = _MAV_CLASSES.get(link.dialect)
    if cls is not None:
        return cls
    lines = []
    for name, fields in link.message_signatures():
        lower = name.lower()
        params, args = [], []
        for fname, default, array in fields:
            arg = fname + "_" if keyword.iskeyword(fname) else fname
            if default is None:
                params.append(arg)
            elif array is None:
                params.append("%s=%d" % (arg, default))
            elif array == 0:
                params.append("%s=b''" % arg)
            else:
                params.append("%s=%r" % (arg, (default,) * array))
            args.append(arg)
        sig = ", ".join(["self"] + params)
        tup = "(" + "".join(a + ", " for a in args) + ")"
        lines.append("def %s_encode(%s):\n    return self._link.encode(%r, %s)\n" % (lower, sig, name, tup))
        lines.append("def %s_send(%s, force_mavlink1=False):\n    self._link.send_fields(%r, %s)\n"
                     % (lower, sig, name, tup))
    namespace = {}
    exec(compile("".join(lines), "<mavstack %s messages>" % link.dialect, "exec"), namespace)
    cls = type("MAVLink", (MAVLink,), {k: v for k, v in namespace.items() if not k.startswith("__")})
    _MAV_CLASSES[link.dialect] = cls
    return cls


class MAVLink:
    """pymavlink's ``MAVLink`` object of a live connection (``conn.mav``): ``<message>_send``
    and ``<message>_encode`` for every message of the dialect, ``send(msg)``, ``srcSystem``,
    ``srcComponent``."""

    def __init__(self, link):
        self._link = link
        self.srcSystem = link.src_system
        self.srcComponent = link.src_component

    def send(self, mavmsg, force_mavlink1=False):
        """Sends a message (received, or made by ``*_encode``) as this connection's own."""
        self._link.send(mavmsg)

    def __setattr__(self, name, value):
        if name in ("srcSystem", "srcComponent") and hasattr(self, name) and value != getattr(self, name):
            raise AttributeError("%s is fixed when the connection opens: pass source_system / "
                                 "source_component to mavlink_connection" % name)
        object.__setattr__(self, name, value)


class mavlive:
    """A live MAVLink connection with pymavlink's API, backed by a ``mavstack`` node (one link)."""

    def __init__(self, device, source_system=255, source_component=0, dialect="ardupilotmega",
                 key=None):
        self._link = open_live(device, source_system=source_system,
                               source_component=source_component, dialect=dialect, key=key)
        self.address = self._link.address
        self.source_system = source_system
        self.source_component = source_component
        self.mav = _mav_class(self._link)(self._link)
        self.param_fetch_start = 0
        # The receiving calls go straight to the native link.
        self.recv_match = self._link.recv_match
        self.recv_msg = self._link.recv_msg

    def recv_match(self, condition=None, type=None, blocking=False, timeout=None):  # noqa: F811
        """The next message of ``type`` (a name or a list or set of names) for which
        ``condition`` holds; with ``blocking``, waits up to ``timeout`` seconds (the GIL
        released). ``None`` when nothing matched."""
        return self._link.recv_match(condition, type, blocking, timeout)

    def recv_msg(self):  # noqa: F811
        """The next message, or ``None`` when none has arrived."""
        return self._link.recv_msg()

    def wait_heartbeat(self, blocking=True, timeout=None):
        """The next HEARTBEAT (pymavlink: so that the target system is known)."""
        return self._link.recv_match(None, "HEARTBEAT", blocking, timeout)

    @property
    def messages(self):
        """The latest message of each type from the target system, by name."""
        return self._link.messages

    @property
    def target_system(self):
        return self._link.target_system

    @target_system.setter
    def target_system(self, value):
        self._link.target_system = value

    @property
    def target_component(self):
        return self._link.target_component

    @target_component.setter
    def target_component(self, value):
        self._link.target_component = value

    @property
    def flightmode(self):
        """The target's flight mode by name, from its latest HEARTBEAT."""
        return self._link.flightmode

    @property
    def mav_type(self):
        return self._link.mav_type

    @property
    def base_mode(self):
        return self._link.base_mode

    def motors_armed(self):
        """Whether the target's latest HEARTBEAT said armed (an int, as pymavlink's)."""
        return 128 if self._link.motors_armed() else 0

    def mode_mapping(self):
        """The target's modes, name -> custom_mode; None before its HEARTBEAT."""
        return self._link.mode_mapping()

    def set_mode(self, mode, custom_mode=0, custom_sub_mode=0):
        """Asks the target to change mode (COMMAND_LONG DO_SET_MODE): a name of
        ``mode_mapping()``, or a mode number."""
        params = self._link.mode_params(mode)
        if params is None:
            print("Unknown mode '%s'" % mode)
            return
        p1, p2, p3 = params
        self.mav.command_long_send(self.target_system, self.target_component, _DO_SET_MODE, 0,
                                   p1, p2, p3, 0, 0, 0, 0)

    def set_mode_apm(self, mode):
        """As ``set_mode``."""
        self.set_mode(mode)

    def _arm(self, value):
        self.mav.command_long_send(self.target_system, self.target_component, _ARM_DISARM, 0,
                                   value, 0, 0, 0, 0, 0, 0)

    def arducopter_arm(self):
        """Asks the target to arm (COMPONENT_ARM_DISARM 1)."""
        self._arm(1)

    def arducopter_disarm(self):
        """Asks the target to disarm (COMPONENT_ARM_DISARM 0)."""
        self._arm(0)

    def param_fetch_all(self):
        """Asks for every parameter (PARAM_REQUEST_LIST); not again within 2 s."""
        if time.time() - self.param_fetch_start < 2.0:
            return
        self.param_fetch_start = time.time()
        self.mav.param_request_list_send(self.target_system, self.target_component)

    def param_fetch_one(self, name):
        """Asks for one parameter by name or index (PARAM_REQUEST_READ)."""
        try:
            idx = int(name)
            self.mav.param_request_read_send(self.target_system, self.target_component, b"", idx)
        except ValueError:
            self.mav.param_request_read_send(self.target_system, self.target_component,
                                             name if isinstance(name, bytes) else name.encode("ascii"), -1)

    def param_set_send(self, parm_name, parm_value, parm_type=None):
        """Sets a parameter (PARAM_SET; the type REAL32 unless given)."""
        if parm_type is None:
            parm_type = _PARAM_FLOAT
        self.mav.param_set_send(self.target_system, self.target_component,
                                parm_name.encode("utf8"), parm_value, parm_type)

    def setup_signing(self, secret_key, sign_outgoing=True, allow_unsigned_callback=None,
                      initial_timestamp=None, link_id=None):
        """Signs every frame sent and accepts only signed ones (MAVLink 2 signing).

        ``allow_unsigned_callback(mav, msgId)`` is asked once, here, for every message of the
        dialect: those it allows (at most 8) are accepted unsigned. ``sign_outgoing=False``
        (verify only) is not offered: the link signs and verifies together."""
        if not sign_outgoing:
            raise NotImplementedError("setup_signing(sign_outgoing=False): a mavstack link signs "
                                      "and verifies together")
        allowed = []
        if allow_unsigned_callback is not None:
            allowed = [i for i in self._link.message_ids() if allow_unsigned_callback(self.mav, i)]
        if initial_timestamp is None:
            initial_timestamp = int(max(time.time() - 1420070400, 0) * 100000)
        self._link.setup_signing(bytes(secret_key), link_id or 0, int(initial_timestamp), allowed)

    def disable_signing(self):
        """Stops signing."""
        self._link.disable_signing()

    def write(self, buf):
        """Writes whole frames (``msg.get_msgbuf()``) as they are."""
        self._link.write(bytes(buf))

    def close(self):
        """Closes the link."""
        self._link.close()

    def stats(self):
        """Counts: ``received``, ``unknown_id``."""
        return self._link.stats()

    def __enter__(self):
        return self

    def __exit__(self, *args):
        self.close()
        return False

