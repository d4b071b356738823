"""mavstack's native asyncio API: a ground station's vehicles and a served component.

    import asyncio
    import mavstack.aio

    async def main() -> None:
        async with mavstack.aio.connect("udpin:0.0.0.0:14550") as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            params = await vehicle.params.get_all()
            await vehicle.params.set("RTL_ALT", 3000)
            print(await vehicle.arm())                 # ACCEPTED, or why not
            async for m in vehicle.telemetry("ATTITUDE", rate_hz=10):
                print(m.roll)

    asyncio.run(main())

Everything runs on the stack's own runtime (one thread for every connection of the process,
the nodes' included): parameters, missions, commands and rates are the Rust
`mavstack::system::System`'s, the served component `mavstack::serve::Served`'s. No helper
process, no thread per call or per message. Results reach the asyncio loop as
``loop.call_soon_threadsafe`` would hand them, through a socket the loop watches
(``loop.add_reader``: a selector event loop, the default on Unix), without the runtime's
thread ever taking the GIL; cancelling the task that awaits an operation (or
``asyncio.wait_for`` running out) abandons the operation, and closing a connection ends its
telemetry iterators and fails its running operations with :class:`ConnectionClosed`.

Errors are :class:`Error` and its subclasses; :class:`TimeoutError` is also the builtin
``TimeoutError``, :class:`ConnectionClosed` the builtin ``ConnectionError``.
"""

from __future__ import annotations

import asyncio
import builtins
import functools
import inspect
import logging
import weakref
from dataclasses import dataclass, field
from typing import (
    Any,
    Awaitable,
    Callable,
    Dict,
    Generator,
    Iterable,
    List,
    Mapping,
    NamedTuple,
    Optional,
    Tuple,
    Union,
)

from mavstack import _native
from mavstack._native import MAVLinkMessage

__all__ = [
    "Camera",
    "CameraError",
    "CameraInfo",
    "CameraRequest",
    "CameraServer",
    "CameraSetting",
    "CaptureStatus",
    "CommandError",
    "CommandRequest",
    "CommandResult",
    "Connection",
    "ConnectionClosed",
    "ConnectionFailed",
    "Error",
    "Gimbal",
    "GimbalAttitude",
    "GimbalControl",
    "GimbalInfo",
    "Home",
    "InvalidValueError",
    "ManualControl",
    "Mission",
    "MissionError",
    "MissionItem",
    "Mode",
    "Offboard",
    "ParamError",
    "Params",
    "Photo",
    "Position",
    "SIMULATED_CAMERA_DEFINITION",
    "Server",
    "Storage",
    "SystemInfo",
    "Telemetry",
    "TimeoutError",
    "UnknownModeError",
    "Vehicle",
    "connect",
    "serve",
    "serve_camera",
]

log = logging.getLogger("mavstack.aio")

Key = Union[bytes, str, None]
Number = Union[int, float]


class Error(Exception):
    """Any failure of a mavstack.aio operation."""


class TimeoutError(Error, builtins.TimeoutError):
    """Nothing came in time: no vehicle heard, no answer after the retries."""


class ConnectionClosed(Error, ConnectionError):
    """The connection (or served component) was closed while the operation ran."""


class ConnectionFailed(Error, OSError):
    """The link could not be opened (the error names the connection string)."""


class ParamError(Error):
    """A parameter operation failed (a value the vehicle keeps refusing, a bad file)."""


class MissionError(Error):
    """A mission transfer was refused by the vehicle."""


class CommandError(Error):
    """A command could not be sent (the same command is still running)."""


class UnknownModeError(Error, ValueError):
    """A mode name the vehicle's autopilot does not have; the message lists the known ones."""


class InvalidValueError(Error, ValueError):
    """A value that cannot be sent (NaN, beyond its type's range): nothing was sent."""


class CameraError(Error):
    """A camera failed what it was asked (a photo it could not take, settings or a
    definition it could not give)."""


_KINDS: Dict[str, type[Error]] = {
    "timeout": TimeoutError,
    "closed": ConnectionClosed,
    "connection": ConnectionFailed,
    "param": ParamError,
    "mission": MissionError,
    "command": CommandError,
    "mode": UnknownModeError,
    "value": InvalidValueError,
    "camera": CameraError,
}

Settle = Callable[[bool, Any], None]
Progress = Callable[[int, int], None]


_wakers: "weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _native.AioWaker]" = \
    weakref.WeakKeyDictionary()


def _waker(loop: asyncio.AbstractEventLoop) -> _native.AioWaker:
    """The loop's waker: the stack's runtime queues results on it and writes a byte to a
    socket the loop watches; the loop's thread then settles the futures (the runtime's
    thread never takes the GIL)."""
    w = _wakers.get(loop)
    if w is None:
        w = _native.AioWaker()
        loop.add_reader(w.fileno(), w.drain)
        _wakers[loop] = w
    return w


async def _call(start: Callable[[_native.AioWaker, Settle], _native.AioOp]) -> Any:
    """Starts a native operation and awaits its result; cancelling abandons it."""
    loop = asyncio.get_running_loop()
    fut: asyncio.Future[Any] = loop.create_future()

    def settle(ok: bool, value: Any) -> None:
        # Runs on the loop's thread (the waker's drain); the future may have been
        # cancelled meanwhile.
        if fut.done():
            return
        if ok:
            fut.set_result(value)
        else:
            kind, message = value
            fut.set_exception(_KINDS.get(kind, Error)(message))

    op = start(_waker(loop), settle)
    try:
        return await fut
    finally:
        if not fut.done() or fut.cancelled():
            op.cancel()


def _wake(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


class Mode(NamedTuple):
    """A flight mode of a vehicle (``await vehicle.modes()``)."""

    name: str
    """Its name, as the vehicle gives it (AVAILABLE_MODES) or as the autopilot's table has it."""
    standard: Optional[str]
    """The standard mode it is (``position_hold``, ``safe_recovery``...), or None."""
    custom_mode: int
    """The autopilot's number for it (HEARTBEAT's ``custom_mode``)."""
    selectable: bool
    """Whether a user may select it (failsafe-only modes are not)."""


class Position(NamedTuple):
    """Where a vehicle is (``await vehicle.position()``)."""

    lat_deg: float
    lon_deg: float
    height_m: float
    """Height above home."""
    alt_m: float
    """Altitude above mean sea level."""


class Home(NamedTuple):
    """A vehicle's home (``await vehicle.home()``)."""

    lat_deg: float
    lon_deg: float
    alt_m: float
    """Altitude above mean sea level."""


class Offboard:
    """A setpoint stream (``async with vehicle.offboard(rate_hz=20) as ob``). The stream is
    the library's, on the runtime's thread: a loop busy elsewhere does not starve it. Each
    ``set_*`` replaces the setpoint sent from the next tick on; leaving the block holds
    position."""

    def __init__(self, native: Any) -> None:
        self._native = native

    @property
    def sent(self) -> int:
        """How many setpoints went out so far."""
        return int(self._native.sent)

    def set_velocity_ned(self, north: float, east: float, down: float,
                         yaw_deg: Optional[float] = None) -> None:
        """Velocity north, east, down (m/s), facing ``yaw_deg`` when given."""
        self._native.set("velocity_ned", [north, east, down, yaw_deg])

    def set_position_ned(self, north_m: float, east_m: float, down_m: float,
                         yaw_deg: Optional[float] = None) -> None:
        """Position north, east, down of the vehicle's local origin (m; down < 0 is up)."""
        self._native.set("position_ned", [north_m, east_m, down_m, yaw_deg])

    def set_velocity_body(self, forward: float, right: float, down: float,
                          yaw_rate_dps: float = 0.0) -> None:
        """Velocity in the body frame (m/s), turning at ``yaw_rate_dps``."""
        self._native.set("velocity_body", [forward, right, down, yaw_rate_dps])

    def set_attitude(self, roll_deg: float, pitch_deg: float, yaw_deg: float,
                     thrust: float) -> None:
        """Attitude (degrees) and thrust (0-1)."""
        self._native.set("attitude", [roll_deg, pitch_deg, yaw_deg, thrust])

    async def stop(self) -> None:
        """Ends the stream and holds position (also what leaving the block does)."""
        await _call(lambda lp, s: self._native.stop(lp, s))


class _OffboardBlock:
    def __init__(self, vehicle: Vehicle, rate_hz: float,
                 first: Tuple[str, List[Optional[float]]]) -> None:
        self._vehicle = vehicle
        self._rate = rate_hz
        self._first = first
        self._ob: Optional[Offboard] = None

    async def __aenter__(self) -> Offboard:
        v, kind, values = self._vehicle, self._first[0], self._first[1]
        native = await _call(
            lambda lp, s: v._native.offboard(self._rate, kind, values, lp, s))
        self._ob = Offboard(native)
        return self._ob

    async def __aexit__(self, *exc: object) -> None:
        if self._ob is not None:
            await self._ob.stop()


class ManualControl:
    """MANUAL_CONTROL at a rate (``async with vehicle.manual_control(rate_hz=20) as mc``),
    sent by the library while the block is open."""

    def __init__(self, native: Any) -> None:
        self._native = native

    def set(self, x: float, y: float, z: float, r: float, buttons: int = 0) -> None:
        """Sticks: ``x`` forward, ``y`` right, ``r`` yaw in -1..1; ``z`` throttle in 0..1
        (0.5 holds height in position modes)."""
        self._native.set(x, y, z, r, buttons)

    def close(self) -> None:
        """Stops the stream."""
        self._native.close()


class _ManualBlock:
    def __init__(self, vehicle: Vehicle, rate_hz: float) -> None:
        self._vehicle = vehicle
        self._rate = rate_hz
        self._mc: Optional[ManualControl] = None

    async def __aenter__(self) -> ManualControl:
        self._mc = ManualControl(self._vehicle._native.manual_control(self._rate))
        return self._mc

    async def __aexit__(self, *exc: object) -> None:
        if self._mc is not None:
            self._mc.close()


class SystemInfo(NamedTuple):
    """A component heard on a connection (its latest HEARTBEAT)."""

    system: int
    component: int
    autopilot: int
    mav_type: int


@dataclass
class MissionItem:
    """One MISSION_ITEM_INT: ``x``/``y`` latitude/longitude in degrees × 1e7 in the global
    frames, ``z`` the altitude in metres. ``frame`` defaults to
    MAV_FRAME_GLOBAL_RELATIVE_ALT (3)."""

    command: int
    frame: int = 3
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    current: int = 0
    autocontinue: int = 1
    seq: int = 0

    def to_dict(self) -> Dict[str, Number]:
        """The fields by name."""
        return {
            "seq": self.seq, "frame": self.frame, "command": self.command,
            "current": self.current, "autocontinue": self.autocontinue,
            "param1": self.param1, "param2": self.param2, "param3": self.param3,
            "param4": self.param4, "x": self.x, "y": self.y, "z": self.z,
        }


ItemLike = Union[MissionItem, Mapping[str, Any], Any]
_ItemTuple = Tuple[int, int, int, int, float, float, float, float, int, int, float]


def _item_tuple(item: ItemLike) -> _ItemTuple:
    """A mission item from a MissionItem, a dict or any object with MISSION_ITEM_INT's
    fields (a pymavlink message): command required, the rest as MissionItem's defaults."""
    def get(key: str, default: Any) -> Any:
        if isinstance(item, Mapping):
            return item.get(key, default)  # pyright: ignore[reportUnknownMemberType, reportUnknownVariableType]
        return getattr(item, key, default)
    command = get("command", None)
    if command is None:
        raise ValueError("a mission item needs a command: %r" % (item,))
    try:
        return (int(get("frame", 3)), int(command), int(get("current", 0)),
                int(get("autocontinue", 1)), float(get("param1", 0.0)),
                float(get("param2", 0.0)), float(get("param3", 0.0)),
                float(get("param4", 0.0)), int(get("x", 0)), int(get("y", 0)),
                float(get("z", 0.0)))
    except (TypeError, ValueError) as e:
        raise ValueError("mission item %r: %s" % (item, e)) from None


class CommandResult:
    """The final COMMAND_ACK of a command: ``str()`` names its MAV_RESULT (``ACCEPTED``,
    ``DENIED``, ...); ``statustext`` holds what the vehicle said in STATUSTEXT around a
    refusal (``PreArm: ...``). True when accepted."""

    __slots__ = ("result", "name", "progress", "result_param2", "statustext", "command")

    def __init__(self, result: int, name: str, progress: int, result_param2: int,
                 statustext: List[str], command: str) -> None:
        self.result = result
        self.name = name
        self.progress = progress
        self.result_param2 = result_param2
        self.statustext = statustext
        self.command = command

    @property
    def accepted(self) -> bool:
        """MAV_RESULT_ACCEPTED."""
        return self.result == 0

    def __bool__(self) -> bool:
        return self.accepted

    def __str__(self) -> str:
        return self.name

    def __repr__(self) -> str:
        said = " (%s)" % "; ".join(self.statustext) if self.statustext else ""
        return "<CommandResult %s: %s%s>" % (self.command, self.name, said)


class Telemetry:
    """Messages of one type from a vehicle as they come (``async for``); ends when the
    connection closes or :meth:`close` is called. Up to 1,024 unread messages are kept, the
    oldest dropped beyond (``dropped``)."""

    def __init__(self, native: _native.AioStream) -> None:
        self._native = native

    def __aiter__(self) -> Telemetry:
        return self

    async def __anext__(self) -> MAVLinkMessage:
        while True:
            m = self._native.pop()
            if m is not None:
                return m
            if self._native.ended:
                raise StopAsyncIteration
            loop = asyncio.get_running_loop()
            fut: asyncio.Future[None] = loop.create_future()
            if self._native.wait(_waker(loop), functools.partial(_wake, fut)):
                await fut

    @property
    def dropped(self) -> int:
        """Messages left out because they were not read in time."""
        return self._native.dropped

    def close(self) -> None:
        """Ends the stream."""
        self._native.close()


class Params:
    """A vehicle's parameters (``vehicle.params``)."""

    def __init__(self, native: _native.AioVehicle) -> None:
        self._native = native
        self.last_via: Optional[str] = None

    async def get_all(self, via: str = "auto",
                      progress: Optional[Progress] = None) -> Dict[str, Number]:
        """The whole table, name → value (``int`` for integer types, ``float`` for REAL32),
        in the vehicle's order: over MAVFTP (``@PARAM/param.pck``) when the vehicle offers it
        (``via="auto"``), else PARAM_REQUEST_LIST with the missing ones asked for again;
        ``via="ftp"`` or ``"list"`` forces one. ``last_via`` tells which it was.
        ``progress(done, total)`` is called on the loop as it comes (bytes of the file over
        MAVFTP, parameters otherwise; the latest values when several came at once)."""
        table, how = await _call(lambda lp, s: self._native.params_all(via, progress, lp, s))
        self.last_via = how
        return table  # type: ignore[no-any-return]

    async def get(self, name: str) -> Number:
        """One parameter's value."""
        return await _call(lambda lp, s: self._native.param_get(name, lp, s))  # type: ignore[no-any-return]

    async def set(self, name: str, value: Number) -> Number:
        """Sets a parameter in its type on the vehicle (read first) and returns the value in
        force once the vehicle confirmed it."""
        return await _call(lambda lp, s: self._native.param_set(name, value, lp, s))  # type: ignore[no-any-return]


class Mission:
    """A vehicle's plans (``vehicle.mission``): ``kind`` is ``"mission"``, ``"fence"`` or
    ``"rally"``.

    With ``plan=True`` (the default) a mission's item 0 is home, as in a QGC plan file,
    whatever the autopilot: ArduPilot stores it as item 0 (and puts its own home there),
    PX4 has no home item (it is left out on upload and read from HOME_POSITION on
    download). With ``plan=False`` the items go and come as the vehicle stores them."""

    def __init__(self, native: _native.AioVehicle) -> None:
        self._native = native

    async def upload(self, items: Iterable[ItemLike], kind: str = "mission",
                     plan: bool = True, progress: Optional[Progress] = None) -> None:
        """Uploads ``items`` (MissionItem, dicts or objects with MISSION_ITEM_INT's
        fields; ``seq`` is their order); ``progress(sent, count)`` as the vehicle asks for
        them (in the vehicle's items: PX4's have no home)."""
        tuples = [_item_tuple(i) for i in items]
        await _call(lambda lp, s: self._native.mission_upload(tuples, kind, plan, progress, lp, s))

    async def download(self, kind: str = "mission", plan: bool = True,
                       progress: Optional[Progress] = None) -> List[MissionItem]:
        """The vehicle's plan; ``progress(received, count)`` as items come."""
        tuples = await _call(
            lambda lp, s: self._native.mission_download(kind, plan, progress, lp, s))
        return [MissionItem(command=t[1], frame=t[0], current=t[2], autocontinue=t[3],
                            param1=t[4], param2=t[5], param3=t[6], param4=t[7], x=t[8],
                            y=t[9], z=t[10], seq=i) for i, t in enumerate(tuples)]

    async def clear(self, kind: str = "mission") -> None:
        """Clears the vehicle's plan."""
        await _call(lambda lp, s: self._native.mission_clear(kind, lp, s))


def _command_result(t: Tuple[int, str, int, int, List[str], str]) -> CommandResult:
    return CommandResult(*t)


class Vehicle:
    """A vehicle found on a connection (``await gcs.vehicle()``). Its operations run one
    after the other in the order they were started."""

    def __init__(self, native: _native.AioVehicle) -> None:
        self._native = native
        self.params = Params(native)
        self.mission = Mission(native)

    @property
    def system(self) -> int:
        """Its system id."""
        return self._native.system

    @property
    def component(self) -> int:
        """The component that answered (the autopilot's)."""
        return self._native.component

    @property
    def autopilot(self) -> int:
        """MAV_AUTOPILOT of its HEARTBEAT (3 ArduPilot, 12 PX4)."""
        return self._native.autopilot

    @property
    def mav_type(self) -> int:
        """MAV_TYPE of its HEARTBEAT."""
        return self._native.mav_type

    def __repr__(self) -> str:
        return "<Vehicle %d/%d autopilot %d type %d>" % (
            self.system, self.component, self.autopilot, self.mav_type)

    async def command(self, command: Union[int, str], *params: float,
                      frame: Optional[int] = None) -> CommandResult:
        """Sends a command (a MAV_CMD number, or its name with or without ``MAV_CMD_``) with
        up to seven parameters, retried until acknowledged: COMMAND_LONG, or COMMAND_INT
        with ``frame`` (params 5 and 6 then x and y as integers). Returns the final ACK as
        a :class:`CommandResult`, accepted or not; raises :class:`TimeoutError` when none
        came."""
        p = [float(x) for x in params]
        t = await _call(lambda lp, s: self._native.command(command, p, frame, lp, s))
        return _command_result(t)

    async def arm(self, force: bool = False) -> CommandResult:
        """MAV_CMD_COMPONENT_ARM_DISARM with 1 (``force``: 21196, past the checks)."""
        t = await _call(lambda lp, s: self._native.arm(force, lp, s))
        return _command_result(t)

    async def disarm(self, force: bool = False) -> CommandResult:
        """MAV_CMD_COMPONENT_ARM_DISARM with 0 (``force``: even in the air)."""
        t = await _call(lambda lp, s: self._native.disarm(force, lp, s))
        return _command_result(t)

    async def set_mode(self, name: str) -> CommandResult:
        """Switches to a mode by the vehicle's name (ArduPilot ``GUIDED``, ``RTL``; PX4
        ``AUTO.MISSION``, ``mission``, ``Hold``) or a standard name (``position_hold``,
        ``safe_recovery``, ``mission``, ``land``, ``takeoff``...), and waits until the
        vehicle reports it; :class:`UnknownModeError` lists the known ones."""
        t = await _call(lambda lp, s: self._native.set_mode(name, lp, s))
        return _command_result(t)

    async def modes(self) -> List[Mode]:
        """Its modes: from AVAILABLE_MODES where the vehicle offers them, else the
        autopilot's table."""
        t = await _call(lambda lp, s: self._native.modes(lp, s))
        return [Mode(*m) for m in t]

    async def mode(self) -> Optional[Mode]:
        """The mode it is in (CURRENT_MODE, else HEARTBEAT)."""
        t = await _call(lambda lp, s: self._native.mode(lp, s))
        return None if t is None else Mode(*t)

    @property
    def armed(self) -> bool:
        """Whether its latest HEARTBEAT says armed."""
        return bool(self._native.armed)

    @property
    def in_air(self) -> bool:
        """Whether it is in the air (EXTENDED_SYS_STATE, else armed and above home)."""
        return bool(self._native.in_air)

    async def takeoff(self, height_m: float,
                      progress: Optional[Progress] = None) -> None:
        """Takes off to ``height_m`` above home (whatever the autopilot's convention) and
        returns once it reports 95 % of it; raises :class:`CommandError` (with the
        vehicle's reasons) when refused, :class:`InvalidValueError` when not armed or the
        height is not a number (nothing sent)."""
        await _call(lambda lp, s: self._native.takeoff(float(height_m), progress, lp, s))

    async def land(self, wait: bool = True) -> None:
        """Lands where it is; with ``wait``, returns once landed and disarmed."""
        await _call(lambda lp, s: self._native.fly("land", wait, lp, s))

    async def return_home(self, wait: bool = True) -> None:
        """Returns home (RTL, Return); with ``wait``, returns once landed and disarmed."""
        await _call(lambda lp, s: self._native.fly("return_home", wait, lp, s))

    async def hold(self) -> None:
        """Holds position (LOITER, Hold)."""
        await _call(lambda lp, s: self._native.fly("hold", False, lp, s))

    async def goto(self, lat_deg: float, lon_deg: float, height_m: float,
                   yaw_deg: Optional[float] = None, wait: bool = True) -> None:
        """Goes to a point at ``height_m`` above home; with ``wait``, returns within 1.5 m
        of it."""
        await _call(lambda lp, s: self._native.goto(
            float(lat_deg), float(lon_deg), float(height_m),
            None if yaw_deg is None else float(yaw_deg), wait, lp, s))

    async def position(self) -> Optional[Position]:
        """Where it is (GLOBAL_POSITION_INT, asked for if none came yet)."""
        t = await _call(lambda lp, s: self._native.position(lp, s))
        return None if t is None else Position(*t)

    async def home(self) -> Optional[Home]:
        """Its home (HOME_POSITION, asked for if none came yet)."""
        t = await _call(lambda lp, s: self._native.home(lp, s))
        return None if t is None else Home(*t)

    async def inject_rtcm(self, data: Union[bytes, bytearray, memoryview]) -> int:
        """Sends one RTCM message (usually one RTCM3 frame, up to 720 bytes) as RTK
        corrections in GPS_RTCM_DATA: up to 180 bytes in one message, longer in fragments
        of 180 with the vehicle's next sequence id (an empty last one when the length is a
        multiple of 180). Returns how many GPS_RTCM_DATA it took;
        :class:`InvalidValueError` for an empty message or one over 720 bytes (nothing
        sent)."""
        return await _call(lambda lp, s: self._native.inject_rtcm(bytes(data), lp, s))  # type: ignore[no-any-return]

    async def shell(self, command: str, timeout: float = 30.0) -> str:
        """Runs one command line on the vehicle's shell (SERIAL_CONTROL to the SHELL device,
        as PX4's nsh) and returns its output: what the shell printed between the echo of
        the line and the next prompt, safe to print. :class:`TimeoutError` when the shell
        never answers (ArduPilot has none) or the prompt does not come back within
        ``timeout`` seconds; :class:`InvalidValueError` for a line with a line break."""
        return await _call(lambda lp, s: self._native.shell(command, float(timeout), lp, s))  # type: ignore[no-any-return]

    async def gimbals(self) -> List[Gimbal]:
        """Its gimbals (the gimbal protocol v2: each gimbal manager's
        GIMBAL_MANAGER_INFORMATION), in the order found; empty when it has none."""
        return await _payload.gimbals_of(self._native)

    async def cameras(self) -> List[Camera]:
        """Its cameras (the camera protocol v2: CAMERA_INFORMATION from its components),
        in the order found; empty when it has none."""
        return await _payload.cameras_of(self._native)

    def offboard(self, rate_hz: float = 20.0) -> _OffboardBlock:
        """``async with vehicle.offboard(rate_hz=20) as ob``: a setpoint stream (zero
        velocity at first), PX4 OFFBOARD or ArduPilot GUIDED once setpoints flow; leaving
        the block holds position."""
        return _OffboardBlock(self, rate_hz, ("velocity_ned", [0.0, 0.0, 0.0, None]))

    def manual_control(self, rate_hz: float = 20.0) -> _ManualBlock:
        """``async with vehicle.manual_control(rate_hz=20) as mc``: MANUAL_CONTROL (centred
        sticks at first) while the block is open."""
        return _ManualBlock(self, rate_hz)

    def telemetry(self, name: str, rate_hz: Optional[float] = None) -> Telemetry:
        """Messages ``name`` from the vehicle from now on (``async for``); with ``rate_hz``
        the vehicle is asked for that rate (SET_MESSAGE_INTERVAL, or REQUEST_DATA_STREAM
        where that is refused or ignored)."""
        return Telemetry(self._native.telemetry(name, rate_hz))


class Connection:
    """A ground station's link (``mavstack.aio.connect``): ``async with`` or ``await`` it to
    open it."""

    def __init__(self, device: str, source_system: int, source_component: int,
                 dialect: str, key: Key, link_id: int) -> None:
        self._args = (device, source_system, source_component, dialect, key, link_id)
        self._native: Optional[_native.AioLink] = None

    async def open(self) -> Connection:
        """Opens the link (once)."""
        if self._native is None:
            a = self._args
            self._native = await _call(
                lambda lp, s: _native.aio_connect(a[0], a[1], a[2], a[3], a[4], a[5], lp, s))
        return self

    def __await__(self) -> Generator[Any, None, Connection]:
        return self.open().__await__()

    async def __aenter__(self) -> Connection:
        return await self.open()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def _link(self) -> _native.AioLink:
        if self._native is None:
            raise ConnectionClosed("the connection is not open: use `async with` or `await`")
        return self._native

    async def vehicle(self, timeout: float = 10.0, *, system: Optional[int] = None,
                      component: Optional[int] = None) -> Vehicle:
        """The first autopilot heard from now on (or system ``system``), within
        ``timeout`` seconds (:class:`TimeoutError` otherwise); a vehicle heard in MAVLink 1
        is asked to switch to MAVLink 2 first."""
        link = self._link()
        native = await _call(lambda lp, s: link.vehicle(system, component, float(timeout), lp, s))
        return Vehicle(native)

    def send(self, message: str, /, **fields: Any) -> None:
        """Sends ``message`` (a name) with ``fields`` by name (pymavlink's ``*_send``
        arguments; the fields not given are zero) as this ground station, on its link;
        returns at once (the node frames it in the link's version and signing)."""
        self._link().send(message, fields)

    def systems(self) -> List[SystemInfo]:
        """The components heard on the link and not silent for 3 s."""
        return [SystemInfo(*t) for t in self._link().systems()]

    async def close(self) -> None:
        """Closes the link: telemetry iterators end, running operations raise
        :class:`ConnectionClosed`."""
        if self._native is not None and not self._native.closed:
            link = self._native
            await _call(lambda lp, s: link.close(lp, s))

    @property
    def closed(self) -> bool:
        """Whether it was closed."""
        return self._native is not None and self._native.closed

    @property
    def identity(self) -> Tuple[int, int]:
        """Its own (system, component)."""
        return self._link().identity


def connect(device: str, *, source_system: int = 255, source_component: int = 190,
            dialect: str = "ardupilotmega", key: Key = None, link_id: int = 0) -> Connection:
    """A ground station on ``device``: the connection strings of ``mavstack`` and
    ``mavutil`` (``udpin:0.0.0.0:14550``, ``udpout:HOST:PORT``, ``tcp:HOST:PORT``,
    ``tcpin:...``, ``serial:/dev/ttyUSB0:57600``, link options after ``?``), as system
    ``source_system``, component ``source_component``, sending a GCS HEARTBEAT every second;
    ``key`` (32 bytes or 64 hex digits) signs the link. Use as ``async with connect(...) as
    gcs`` or ``gcs = await connect(...)``."""
    return Connection(device, source_system, source_component, dialect, key, link_id)


# ----- serving ---------------------------------------------------------------------------

MAV_RESULT = {"ACCEPTED": 0, "TEMPORARILY_REJECTED": 1, "DENIED": 2, "UNSUPPORTED": 3,
              "FAILED": 4, "IN_PROGRESS": 5, "CANCELLED": 6}


@dataclass(frozen=True)
class CommandRequest:
    """A command a served component received: ``command`` its MAV_CMD, ``name`` without
    ``MAV_CMD_``, its seven ``params`` (COMMAND_INT: x and y as the 5th and 6th, ``frame``
    set), ``sender`` (system, component)."""

    command: int
    name: str
    params: Tuple[float, ...]
    sender: Tuple[int, int]
    frame: Optional[int] = None
    token: int = field(default=0, repr=False)


HandlerResult = Union[None, bool, int, str, Tuple[Union[int, str], int]]
Handler = Callable[[CommandRequest], Union[HandlerResult, Awaitable[HandlerResult]]]


def _result_code(r: HandlerResult) -> Tuple[int, int]:
    """A handler's answer as (MAV_RESULT, result_param2): None or True ACCEPTED, False
    FAILED, an int the MAV_RESULT, a name (``"DENIED"``), or (result, param2)."""
    if isinstance(r, tuple):
        code, _ = _result_code(r[0])
        return code, int(r[1])
    if r is None or r is True:
        return 0, 0
    if r is False:
        return 4, 0
    if isinstance(r, int):
        return r, 0
    name = r.upper().removeprefix("MAV_RESULT_")
    if name in MAV_RESULT:
        return MAV_RESULT[name], 0
    raise ValueError("a command handler returns None, a bool, a MAV_RESULT or its name, not %r"
                     % (r,))


class Server:
    """A component served on its own link (``mavstack.aio.serve``): it sends HEARTBEAT,
    answers parameter requests from its table and hands every command to its handler
    (a function or a coroutine function; each command in a task of its own, retries and
    duplicates answered by the stack). ``async with`` or ``await`` it to start it."""

    def __init__(self, args: Tuple[Any, ...], handler: Optional[Handler]) -> None:
        self._args = args
        self._handler = handler
        self._native: Optional[_native.AioServer] = None
        self._pump: Optional[asyncio.Task[None]] = None
        self._running: set[asyncio.Task[None]] = set()

    async def start(self) -> Server:
        """Opens the link and starts serving (once)."""
        if self._native is None:
            a = self._args
            native: _native.AioServer = await _call(lambda lp, s: _native.aio_serve(
                a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9], lp, s))
            self._native = native
            self._pump = asyncio.get_running_loop().create_task(self._serve(native))
        return self

    def __await__(self) -> Generator[Any, None, Server]:
        return self.start().__await__()

    async def __aenter__(self) -> Server:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def _server(self) -> _native.AioServer:
        if self._native is None:
            raise ConnectionClosed("the server is not started: use `async with` or `await`")
        return self._native

    async def _serve(self, native: _native.AioServer) -> None:
        loop = asyncio.get_running_loop()
        while True:
            t = native.pop_request()
            if t is None:
                if native.ended:
                    return
                fut: asyncio.Future[None] = loop.create_future()
                if native.wait_request(_waker(loop), functools.partial(_wake, fut)):
                    await fut
                continue
            token, sysid, compid, cmd, name, params, frame = t
            request = CommandRequest(cmd, name, tuple(params), (sysid, compid), frame, token)
            task = loop.create_task(self._answer(native, request))
            self._running.add(task)
            task.add_done_callback(self._running.discard)

    async def _answer(self, native: _native.AioServer, request: CommandRequest) -> None:
        code, param2 = 3, 0  # UNSUPPORTED without a handler
        if self._handler is not None:
            try:
                r = self._handler(request)
                if inspect.isawaitable(r):
                    r = await r
                code, param2 = _result_code(r)
            except asyncio.CancelledError:
                code, param2 = 6, 0
                native.answer(request.token, code, param2)
                raise
            except Exception:
                log.exception("command handler failed on %s", request.name)
                code, param2 = 4, 0
        native.answer(request.token, code, param2)

    async def params(self) -> Dict[str, Number]:
        """The table now."""
        s = self._server()
        return await _call(lambda lp, st: s.params(lp, st))  # type: ignore[no-any-return]

    async def set_param(self, name: str, value: Number) -> Number:
        """Sets (or adds) a parameter here and tells the ground stations (PARAM_VALUE);
        returns the value in force (in an existing parameter's type)."""
        s = self._server()
        return await _call(lambda lp, st: s.set_param(name, value, lp, st))  # type: ignore[no-any-return]

    def send(self, message: str, /, **fields: Any) -> None:
        """Sends ``message`` (a name) with ``fields`` by name (the others zero) as this
        component, to every peer of its link (telemetry of your own: ``server.send(
        "NAMED_VALUE_FLOAT", name="TEMP", value=21.5)``); returns at once."""
        self._server().send(message, fields)

    def changes(self) -> List[Tuple[str, Number]]:
        """Parameters ground stations set since the last call, in order: (name, value)."""
        return self._server().changes()

    async def close(self) -> None:
        """Stops serving: running handlers are cancelled, the link is closed."""
        if self._native is None:
            return
        native = self._native
        for t in list(self._running):
            t.cancel()
        await _call(lambda lp, s: native.close(lp, s))
        if self._pump is not None:
            self._pump.cancel()
            try:
                await self._pump
            except asyncio.CancelledError:
                pass
            self._pump = None


def serve(device: str, *, system: int = 1, component: int = 191,
          params: Optional[Mapping[str, Number]] = None,
          on_command: Optional[Handler] = None, mav_type: int = 18, autopilot: int = 8,
          encoding: str = "bytewise", dialect: str = "ardupilotmega", key: Key = None,
          link_id: int = 0) -> Server:
    """A component of system ``system``, component ``component`` on ``device`` (the
    strings of :func:`connect`), sending HEARTBEAT (``mav_type``, default
    MAV_TYPE_ONBOARD_CONTROLLER; ``autopilot``, default MAV_AUTOPILOT_INVALID) every second;
    ``params`` its parameter table (``int`` values are INT32, ``float`` REAL32; sent
    ``"bytewise"`` or ``"c_cast"`` as ArduPilot); ``on_command(request)`` answers each
    command: None/True accept it, False fails it, or a MAV_RESULT (number or name), or
    (result, result_param2); an exception answers FAILED. Without a handler commands are
    UNSUPPORTED."""
    table = list((params or {}).items())
    args = (device, system, component, mav_type, autopilot, table, encoding, dialect, key,
            link_id)
    return Server(args, on_command)


# The payload half (gimbals, cameras, a served camera): its own file, this module's names.
from mavstack import _payload  # noqa: E402
from mavstack._payload import (  # noqa: E402
    Camera,
    CameraInfo,
    CameraRequest,
    CameraServer,
    CameraSetting,
    CaptureStatus,
    Gimbal,
    GimbalAttitude,
    GimbalControl,
    GimbalInfo,
    Photo,
    SIMULATED_CAMERA_DEFINITION,
    Storage,
    serve_camera,
)
