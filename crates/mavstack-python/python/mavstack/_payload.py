"""A vehicle's gimbals and cameras, and a camera served from Python: the payload half of
:mod:`mavstack.aio` (its names are :mod:`mavstack.aio`'s; import them from there).

Each method calls one method of the Rust ``mavstack::system::Gimbal`` or ``Camera`` (or
``mavstack::serve::Camera``) and converts its result; the protocols (discovery, control,
limits, capture announcements and their resends, the camera definition and its exclusions)
are the Rust library's.
"""

from __future__ import annotations

import asyncio
import functools
from dataclasses import dataclass
from typing import (
    TYPE_CHECKING,
    Any,
    Callable,
    Dict,
    Generator,
    List,
    NamedTuple,
    Optional,
    Tuple,
    Union,
)

from mavstack import _native

if TYPE_CHECKING:
    from mavstack.aio import Key


def _aio() -> Any:
    """mavstack.aio, imported when first needed: it imports this module at its end."""
    from mavstack import aio
    return aio


async def _call(start: Callable[[_native.AioWaker, Any], _native.AioOp]) -> Any:
    """mavstack.aio's ``_call``: starts a native operation and awaits its result."""
    return await _aio()._call(start)

Limits = Optional[Tuple[float, float]]
SettingValue = Union[int, float, str]


class GimbalInfo(NamedTuple):
    """What a gimbal manager says about its gimbal (GIMBAL_MANAGER_INFORMATION)."""
    manager_system: int
    manager_component: int
    device_id: int
    cap_flags: int
    pitch_limits: Limits
    yaw_limits: Limits
    roll_limits: Limits
    vendor: str
    model: str
    custom_name: str


class GimbalAttitude(NamedTuple):
    """Where a gimbal looks (GIMBAL_DEVICE_ATTITUDE_STATUS, in degrees): ``yaw_deg`` in
    ``frame`` (``"vehicle"``: from the nose; ``"earth"``: from north), the other frame's
    yaw where the vehicle's heading is known."""
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    frame: str
    yaw_vehicle_deg: Optional[float]
    yaw_earth_deg: Optional[float]
    failure_flags: int


class GimbalControl(NamedTuple):
    """Who controls a gimbal: (system, component) of the primary and secondary
    controllers, None where nobody does."""
    primary: Optional[Tuple[int, int]]
    secondary: Optional[Tuple[int, int]]


class Gimbal:
    """A gimbal of a vehicle (``await vehicle.gimbals()``). Angles outside the manager's
    limits and values that are not numbers raise :class:`InvalidValueError` before
    anything is sent."""

    def __init__(self, native: _native.AioGimbal) -> None:
        self._native = native

    @property
    def info(self) -> GimbalInfo:
        """What its manager said when it was found."""
        return GimbalInfo(*self._native.info)

    async def take_control(self, secondary: bool = False) -> None:
        """Takes primary (or secondary) control of it."""
        await _call(lambda lp, s: self._native.take_control(secondary, lp, s))

    async def release_control(self) -> None:
        """Gives up control of it."""
        await _call(lambda lp, s: self._native.release_control(lp, s))

    async def set_angles(self, pitch_deg: float, yaw_deg: float,
                         frame: str = "vehicle") -> None:
        """Points it at ``pitch_deg`` (positive up) and ``yaw_deg`` (positive right) in
        ``frame`` (``"vehicle"`` or ``"earth"``); returns once the manager accepted."""
        await _call(lambda lp, s: self._native.set_angles(
            float(pitch_deg), float(yaw_deg), frame, lp, s))

    async def set_rates(self, pitch_dps: float, yaw_dps: float,
                        frame: str = "vehicle") -> None:
        """Turns it at ``pitch_dps`` and ``yaw_dps`` degrees per second."""
        await _call(lambda lp, s: self._native.set_rates(
            float(pitch_dps), float(yaw_dps), frame, lp, s))

    async def point_at(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        """Keeps it on a location (``alt_m`` above mean sea level): DO_SET_ROI_LOCATION."""
        await _call(lambda lp, s: self._native.point_at(
            float(lat_deg), float(lon_deg), float(alt_m), lp, s))

    async def clear_roi(self) -> None:
        """Stops keeping it on a location."""
        await _call(lambda lp, s: self._native.clear_roi(lp, s))

    async def attitude(self, timeout: float = 5.0) -> GimbalAttitude:
        """Where it looks now (asked for when no report came within a second)."""
        t = await _call(lambda lp, s: self._native.attitude(float(timeout), lp, s))
        return GimbalAttitude(*t)

    async def control(self, timeout: float = 5.0) -> GimbalControl:
        """Who controls it (GIMBAL_MANAGER_STATUS)."""
        t = await _call(lambda lp, s: self._native.control(float(timeout), lp, s))
        return GimbalControl(*t)


class CameraInfo(NamedTuple):
    """A camera's CAMERA_INFORMATION."""
    system: int
    component: int
    vendor: str
    model: str
    firmware: Optional[str]
    resolution: Optional[Tuple[int, int]]
    focal_length_mm: Optional[float]
    flags: int
    definition_uri: str
    definition_version: int


@dataclass(frozen=True)
class Photo:
    """A photo's CAMERA_IMAGE_CAPTURED: its index, when (µs since 1970) and where it was
    taken (degrees, metres above mean sea level and above home), the camera's attitude
    quaternion, its file's URL and whether it succeeded."""
    index: int
    time_utc_us: int
    lat_deg: float
    lon_deg: float
    alt_m: float
    relative_alt_m: float
    q: Tuple[float, float, float, float]
    file_url: str
    success: bool


class CaptureStatus(NamedTuple):
    """A camera's CAMERA_CAPTURE_STATUS."""
    photo_busy: bool
    interval_on: bool
    interval_s: float
    video_on: bool
    recording_s: float
    available_mib: float
    image_count: int


@dataclass(frozen=True)
class Storage:
    """One of a camera's STORAGE_INFORMATION (``status`` and ``kind`` as the message's
    STORAGE_STATUS and STORAGE_TYPE numbers; ``count`` how many storages it has)."""
    id: int
    count: int
    status: int
    total_mib: float
    used_mib: float
    available_mib: float
    kind: int
    name: str


class CameraSetting(NamedTuple):
    """A camera setting (PARAM_EXT_*) as its definition file describes it: its value and
    that value's option name, the options it may take now (narrowed by the other
    settings), whether another setting's choice rules it out now (``excluded``) and
    whether it can be set at all."""
    name: str
    value: SettingValue
    option: Optional[str]
    description: str
    options: List[Tuple[str, SettingValue]]
    excluded: bool
    read_only: bool


class Camera:
    """A camera of a vehicle (``await vehicle.cameras()``): a component of its own or the
    autopilot's. A setting its definition rules out raises :class:`InvalidValueError`
    before anything is sent; a photo that fails raises :class:`CameraError`."""

    def __init__(self, native: _native.AioCamera) -> None:
        self._native = native

    @property
    def info(self) -> CameraInfo:
        """Its CAMERA_INFORMATION, as it was when found."""
        t = self._native.info
        return CameraInfo(*t)

    async def take_photo(self) -> Photo:
        """Takes a photo and returns its CAMERA_IMAGE_CAPTURED (asked for again by its
        index when the announcement is lost)."""
        t = await _call(lambda lp, s: self._native.take_photo(lp, s))
        index, time_us, lat, lon, alt, rel, q, url, ok = t
        return Photo(index, time_us, lat, lon, alt, rel, tuple(q), url, ok)

    async def start_video(self) -> None:
        """Starts recording."""
        await _call(lambda lp, s: self._native.start_video(lp, s))

    async def stop_video(self) -> None:
        """Stops recording."""
        await _call(lambda lp, s: self._native.stop_video(lp, s))

    async def start_photo_interval(self, seconds: float, count: int = 0) -> None:
        """Photos every ``seconds``, ``count`` of them (0: until stopped)."""
        await _call(lambda lp, s: self._native.start_photo_interval(
            float(seconds), int(count), lp, s))

    async def stop_photo_interval(self) -> None:
        """Stops the photos at an interval."""
        await _call(lambda lp, s: self._native.stop_photo_interval(lp, s))

    async def set_mode(self, mode: str) -> None:
        """Switches to ``"photo"`` or ``"video"`` mode."""
        await _call(lambda lp, s: self._native.set_mode(mode, lp, s))

    async def capture_status(self) -> CaptureStatus:
        """What it is doing now."""
        return CaptureStatus(*await _call(lambda lp, s: self._native.capture_status(lp, s)))

    async def storage(self) -> List[Storage]:
        """Its storage."""
        items = await _call(lambda lp, s: self._native.storage(lp, s))
        return [Storage(*t) for t in items]

    async def settings(self) -> List[CameraSetting]:
        """Its settings, described by its definition file (fetched over MAVFTP for an
        ``mftp://`` URI)."""
        items = await _call(lambda lp, s: self._native.settings(lp, s))
        return [CameraSetting(n, v, o, d, list(opts), x, ro)
                for n, v, o, d, opts, x, ro in items]

    async def set(self, name: str, value: Union[str, int, float]) -> SettingValue:
        """Sets setting ``name`` to ``value`` (an option's name or a value), checked
        against the definition and the other settings first; returns the value it took."""
        return await _call(lambda lp, s: self._native.set(name, str(value), lp, s))  # type: ignore[no-any-return]


class CameraRequest(NamedTuple):
    """What a served camera's ground station asked for: ``kind`` is ``"photo"`` (take
    photo ``number`` and answer with :meth:`CameraServer.photo_taken`), ``"video_start"``
    (stream ``number``), ``"video_stop"`` (``number`` ms recorded), ``"mode"`` (``text``
    ``"photo"`` or ``"video"``), ``"setting"`` (setting ``text`` changed) or
    ``"format"`` (storage formatted)."""
    kind: str
    number: int
    text: str


class CameraServer:
    """A camera served as a component of its own (``mavstack.aio.serve_camera``): it
    sends HEARTBEAT as MAV_TYPE_CAMERA and answers the camera protocol (information,
    settings from its definition file, served over MAVFTP; storage, capture status,
    photos, intervals, video, modes). What needs the real camera comes out of
    ``async for request in server``; a photo is answered with :meth:`photo_taken`.
    ``async with`` or ``await`` it to start it."""

    def __init__(self, args: Tuple[Any, ...]) -> None:
        self._args = args
        self._native: Optional[_native.AioCameraServer] = None

    async def start(self) -> CameraServer:
        """Opens the link and starts serving (once)."""
        if self._native is None:
            a = self._args
            self._native = await _call(lambda lp, s: _native.aio_serve_camera(
                a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9], lp, s))
        return self

    def __await__(self) -> Generator[Any, None, CameraServer]:
        return self.start().__await__()

    async def __aenter__(self) -> CameraServer:
        return await self.start()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def _server(self) -> _native.AioCameraServer:
        if self._native is None:
            raise _aio().ConnectionClosed(
                "the camera is not started: use `async with` or `await`")
        return self._native

    def __aiter__(self) -> CameraServer:
        return self

    async def __anext__(self) -> CameraRequest:
        native = self._server()
        loop = asyncio.get_running_loop()
        while True:
            t = native.pop_event()
            if t is not None:
                return CameraRequest(*t)
            if native.ended:
                raise StopAsyncIteration
            fut: asyncio.Future[None] = loop.create_future()
            if native.wait_event(_aio()._waker(loop), functools.partial(_aio()._wake, fut)):
                await fut

    def photo_taken(self, index: int, file_url: Optional[str],
                    size_mib: float = 0.0) -> None:
        """Photo ``index`` was taken and stored at ``file_url`` (None: it failed),
        taking ``size_mib`` of the storage: the camera announces it
        (CAMERA_IMAGE_CAPTURED) and answers the request."""
        self._server().photo_taken(int(index), file_url, float(size_mib))

    async def settings(self) -> Dict[str, SettingValue]:
        """Its settings now, by name."""
        s = self._server()
        return await _call(lambda lp, st: s.settings(lp, st))  # type: ignore[no-any-return]

    @property
    def address(self) -> str:
        """The connection string (keys redacted)."""
        return self._server().address

    async def close(self) -> None:
        """Stops serving and closes the link."""
        if self._native is None:
            return
        native = self._native
        await _call(lambda lp, s: native.close(lp, s))


def serve_camera(device: str, *, system: int = 1, component: int = 100,
                 vendor: str = "mavstack", model: str = "Python camera",
                 definition: Optional[bytes] = None, storage_mib: float = 1024.0,
                 dialect: str = "common", key: "Key" = None,
                 link_id: int = 0) -> CameraServer:
    """A camera, component ``component`` (MAV_COMP_ID_CAMERA by default) of system
    ``system``, on ``device`` (the strings of :func:`connect`). ``definition``: a camera
    definition file (XML bytes; ``mavstack.aio.SIMULATED_CAMERA_DEFINITION`` is the
    simulator's), served over MAVFTP as ``mftp://camera.xml`` and its settings answered
    with PARAM_EXT_*; without one the camera has no settings. ``storage_mib``: the
    storage it reports."""
    args = (device, system, component, vendor, model, definition, storage_mib, dialect,
            key, link_id)
    return CameraServer(args)


SIMULATED_CAMERA_DEFINITION: bytes = _native.SIMULATED_CAMERA_DEFINITION


async def gimbals_of(native: _native.AioVehicle) -> List[Gimbal]:
    """The vehicle's gimbals (GimbalDiscovery)."""
    items = await _call(lambda lp, s: native.gimbals(lp, s))
    return [Gimbal(g) for g in items]


async def cameras_of(native: _native.AioVehicle) -> List[Camera]:
    """The vehicle's cameras (CameraDiscovery)."""
    items = await _call(lambda lp, s: native.cameras(lp, s))
    return [Camera(c) for c in items]
