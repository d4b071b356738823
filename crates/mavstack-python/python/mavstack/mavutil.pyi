from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Union

from mavstack._native import Key, LiveLink, MAVLinkMessage, Types, mavlogfile

class _Constants:
    """Every enum entry of the dialect by name (``mavutil.mavlink.MAV_CMD_...``) and the
    ``MAVLINK_TYPE_*`` codes."""
    def __getattr__(self, name: str) -> int: ...

mavlink: _Constants

class MAVLink:
    """pymavlink's ``MAVLink`` object of a live connection: ``<message>_send(...)`` and
    ``<message>_encode(...)`` for every message of the dialect, with pymavlink's arguments."""
    srcSystem: int
    srcComponent: int
    def send(self, mavmsg: MAVLinkMessage, force_mavlink1: bool = False) -> None: ...
    def __getattr__(self, name: str) -> Callable[..., Any]: ...

class mavlive:
    """A live MAVLink connection with pymavlink's API, backed by a mavstack node."""
    address: str
    source_system: int
    source_component: int
    mav: MAVLink
    messages: Dict[str, MAVLinkMessage]
    target_system: int
    target_component: int
    flightmode: str
    mav_type: Optional[int]
    base_mode: int
    def __init__(
        self,
        device: str,
        source_system: int = 255,
        source_component: int = 0,
        dialect: str = "ardupilotmega",
        key: Key = None,
    ) -> None: ...
    def recv_match(
        self,
        condition: Optional[str] = None,
        type: Types = None,
        blocking: bool = False,
        timeout: Optional[float] = None,
    ) -> Optional[MAVLinkMessage]: ...
    def recv_msg(self) -> Optional[MAVLinkMessage]: ...
    def wait_heartbeat(self, blocking: bool = True, timeout: Optional[float] = None) -> Optional[MAVLinkMessage]: ...
    def motors_armed(self) -> int: ...
    def mode_mapping(self) -> Optional[Dict[str, int]]: ...
    def set_mode(self, mode: Union[str, int], custom_mode: int = 0, custom_sub_mode: int = 0) -> None: ...
    def set_mode_apm(self, mode: Union[str, int]) -> None: ...
    def arducopter_arm(self) -> None: ...
    def arducopter_disarm(self) -> None: ...
    def param_fetch_all(self) -> None: ...
    def param_fetch_one(self, name: Union[str, bytes, int]) -> None: ...
    def param_set_send(self, parm_name: str, parm_value: float, parm_type: Optional[int] = None) -> None: ...
    def setup_signing(
        self,
        secret_key: bytes,
        sign_outgoing: bool = True,
        allow_unsigned_callback: Optional[Callable[[MAVLink, int], bool]] = None,
        initial_timestamp: Optional[int] = None,
        link_id: Optional[int] = None,
    ) -> None: ...
    def disable_signing(self) -> None: ...
    def write(self, buf: Union[bytes, bytearray]) -> None: ...
    def close(self) -> None: ...
    def stats(self) -> Dict[str, int]: ...
    def __enter__(self) -> "mavlive": ...
    def __exit__(self, *args: Any) -> bool: ...

def mavlink_connection(
    device: Union[str, PathLike],
    baud: int = 57600,
    source_system: int = 255,
    source_component: int = 0,
    dialect: Optional[str] = None,
    key: Key = None,
    **kwargs: Any,
) -> Union[mavlogfile, mavlive]: ...
