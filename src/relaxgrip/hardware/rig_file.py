"""Rig files: one TOML file describes a real (or emulated) gripper rig.

A rig file names the serial port of the MCU, the two cameras (where their
frames come from, how to open them, their intrinsics and mounts), the marker,
the finger and the safety limits.  :func:`load_rig` validates it into frozen
dataclasses; :meth:`RigFile.geometry` maps it onto
:class:`relaxgrip.rig.RigGeometry`, the description perception and the twin
share.  Every bad field gives one line naming the file, the table and the key.

Lengths in the file are in millimetres (``*_mm``), as a lab measures them;
inside they become metres.  See ``docs/rig-example.toml`` (a real rig) and
``docs/rig-emulator.toml`` (the MCU emulator).
"""

from __future__ import annotations

import io
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from relaxgrip.errors import InputError
from relaxgrip.fileio import check_input_file, one_line
from relaxgrip.rig import (
    ARUCO_DICTIONARIES,
    CameraIntrinsics,
    FingerGeometry,
    IrCameraMount,
    MarkerMount,
    RgbCameraMount,
    RigGeometry,
)

__all__ = [
    "IR_SOURCES",
    "MAX_RIG_BYTES",
    "RGB_SOURCES",
    "EmulatorSpec",
    "IrCameraSpec",
    "LimitsSpec",
    "RgbCameraSpec",
    "RigFile",
    "SerialSpec",
    "ZeroPoseSpec",
    "load_rig",
    "parse_rig",
    "read_rig_text",
]

#: Where RGB frames can come from: an OpenCV ``VideoCapture`` or the MCU emulator.
RGB_SOURCES = ("opencv", "emulator")
#: Where infrared frames can come from: a UVC radiometric (Y16) camera or the MCU emulator.
IR_SOURCES = ("uvc", "emulator")
#: The widest ``open_aperture_mm`` taken (mm).
MAX_APERTURE_MM = 1000.0
#: The largest rig file read (bytes): one is a few KiB of TOML.
MAX_RIG_BYTES = 1 << 20


class _Table:
    """One TOML table being read: every key taken is checked, leftovers are errors."""

    def __init__(self, where: str, name: str, data: Any) -> None:
        self.where = where
        self.name = name
        if not isinstance(data, dict):
            raise InputError(f"{where}: [{name}] must be a table")
        self.data: dict[str, Any] = dict(data)
        self.taken: set[str] = set()

    def _field(self, key: str) -> str:
        return f"{self.where}: [{self.name}] {key}"

    def fail(self, key: str, what: str) -> InputError:
        """A one-line error naming the field."""
        return InputError(f"{self._field(key)} {what}")

    def has(self, key: str) -> bool:
        """Whether the key is present."""
        return key in self.data

    def raw(self, key: str, default: Any = None, required: bool = True) -> Any:
        """The value of ``key``, or ``default`` if absent and not required."""
        self.taken.add(key)
        if key not in self.data:
            if required:
                raise InputError(f"{self._field(key)} is missing")
            return default
        return self.data[key]

    def number(self, key: str, default: float | None = None, *, positive: bool = False,
               min_value: float | None = None, max_value: float | None = None) -> float:
        """A finite number, optionally bounded."""
        value = self.raw(key, default, required=default is None)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"must be a number, got {value!r}")
        out = float(value)
        if not math.isfinite(out):
            raise self.fail(key, f"must be finite, got {value!r}")
        if positive and not out > 0.0:
            raise self.fail(key, f"must be > 0, got {value!r}")
        if min_value is not None and out < min_value:
            raise self.fail(key, f"must be >= {min_value:g}, got {value!r}")
        if max_value is not None and out > max_value:
            raise self.fail(key, f"must be <= {max_value:g}, got {value!r}")
        return out

    def integer(self, key: str, default: int | None = None, *, min_value: int = 0,
                max_value: int | None = None) -> int:
        """An integer within bounds."""
        value = self.raw(key, default, required=default is None)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"must be an integer, got {value!r}")
        if max_value is None and value < min_value:
            raise self.fail(key, f"must be >= {min_value}, got {value}")
        if max_value is not None and not min_value <= value <= max_value:
            raise self.fail(key, f"must be in {min_value}..{max_value}, got {value}")
        return int(value)

    def string(self, key: str, default: str | None = None,
               choices: tuple[str, ...] | None = None) -> str:
        """A non-empty string, optionally one of ``choices``."""
        value = self.raw(key, default, required=default is None)
        if not isinstance(value, str) or not value:
            raise self.fail(key, f"must be a non-empty string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.fail(key, f"must be one of {', '.join(choices)}, got {value!r}")
        return value

    def numbers(self, key: str, default: tuple[float, ...] | None = None,
                length: int | None = None) -> tuple[float, ...]:
        """A list of finite numbers (of a given length)."""
        value = self.raw(key, default, required=default is None)
        if not isinstance(value, list | tuple):
            raise self.fail(key, f"must be a list of numbers, got {value!r}")
        out = []
        for item in value:
            if isinstance(item, bool) or not isinstance(item, int | float) \
                    or not math.isfinite(item):
                raise self.fail(key, f"must hold finite numbers, got {item!r}")
            out.append(float(item))
        if length is not None and len(out) != length:
            raise self.fail(key, f"needs {length} numbers, got {len(out)}")
        return tuple(out)

    def device(self, key: str) -> int | str:
        """A camera device: an index (``0``) or a path (``/dev/video2``)."""
        value = self.raw(key)
        if isinstance(value, bool) or not isinstance(value, int | str) or value in ("", ):
            raise self.fail(key, f"must be a device index or a path, got {value!r}")
        if isinstance(value, int) and value < 0:
            raise self.fail(key, f"must be a device index >= 0, got {value}")
        return value

    def done(self) -> None:
        """Reject keys nobody asked for (typos)."""
        extra = sorted(set(self.data) - self.taken)
        if extra:
            raise InputError(f"{self.where}: [{self.name}] has unknown key {extra[0]!r}")


@dataclass(frozen=True)
class SerialSpec:
    """The MCU's serial link.

    Attributes
    ----------
    port : str
        Device path (``/dev/ttyACM0``) or the emulator's pseudo-terminal link.
    baud : int
        Line speed (bit/s).
    reply_timeout_s : float
        Longest wait for an MCU answer (s).
    boot_wait_s : float
        How long the host says Hello again before the MCU answers (s): opening
        the port resets an Arduino-class MCU (DTR), whose bootloader is silent
        for a second or two.
    """

    port: str
    baud: int = 115_200
    reply_timeout_s: float = 0.1
    boot_wait_s: float = 2.5


@dataclass(frozen=True)
class RgbCameraSpec:
    """The RGB camera: where its frames come from and how to open it.

    Attributes
    ----------
    source : str
        ``opencv`` (a ``VideoCapture`` device) or ``emulator``.
    device : int or str or None
        Device index or path (``opencv`` only).
    fps : float
        Frame rate asked of the camera (Hz).
    exposure : float or None
        ``CAP_PROP_EXPOSURE`` value (driver units); ``None`` leaves auto exposure.
    stall_s : float
        A camera without a new frame for longer than this is stalled (s).
    mount : RgbCameraMount
        Intrinsics (the resolution asked of the camera) and pose.
    """

    source: str
    device: int | str | None
    fps: float
    exposure: float | None
    stall_s: float
    mount: RgbCameraMount


@dataclass(frozen=True)
class IrCameraSpec:
    """The thermal camera: source, radiometric conversion and mount.

    Attributes
    ----------
    source : str
        ``uvc`` (a UVC camera streaming 16-bit radiometric Y16 frames) or ``emulator``.
    device : int or str or None
        Device index or path (``uvc`` only).
    fps : float
        Frame rate asked of the camera (Hz).
    scale : float
        Radiometric conversion ``temp_c = raw * scale + offset_c`` (°C per count).
    offset_c : float
        Offset of that conversion (°C); ``scale = 0.01, offset_c = -273.15``
        converts centi-kelvin (PureThermal / Lepton TLinear).
    stall_s : float
        A camera without a new frame for longer than this is stalled (s).
    mount : IrCameraMount
        Intrinsics and pose.
    follow_bend : bool
        Read the fingers where their load bends them
        (:attr:`RigGeometry.ir_follow_bend`): on by default, for a camera
        and for the emulator, whose twin draws the bend.
    """

    source: str
    device: int | str | None
    fps: float
    scale: float
    offset_c: float
    stall_s: float
    mount: IrCameraMount
    follow_bend: bool = True

    def temp_c(self, raw: Any) -> Any:
        """Convert raw counts (array or number) to °C."""
        return raw * self.scale + self.offset_c


@dataclass(frozen=True)
class LimitsSpec:
    """Safety limits the host enforces (the MCU enforces its own velocity limit too).

    Attributes
    ----------
    max_motor_speed_mm_s : float
        Largest motor speed the host commands (mm/s).
    heater_duty_limit : float
        Largest heater duty the host commands (0..1).
    max_temp_c : float
        Hottest finger temperature allowed on the infrared image (°C): above
        it the host switches the heaters off.
    """

    max_motor_speed_mm_s: float = 20.0
    heater_duty_limit: float = 1.0
    max_temp_c: float = 70.0


@dataclass(frozen=True)
class EmulatorSpec:
    """Where the MCU emulator publishes its camera frames.

    Attributes
    ----------
    socket : str
        Path of the Unix socket of the frame channel.
    seed : int
        Seed of the emulated twin.
    """

    socket: str
    seed: int = 0


@dataclass(frozen=True)
class ZeroPoseSpec:
    """The marker's pose at rest in the RGB camera frame, as ``relaxgrip zero-pose`` measured it.

    Attributes
    ----------
    position_m : tuple of float
        Marker centre in the camera frame (m).
    rotation_rvec : tuple of float
        Marker rotation in the camera frame, a rotation vector (rad).
    frames : int
        Frames it was averaged over.
    spread_m : float
        Farthest a frame lay from the mean (m).
    """

    position_m: tuple[float, float, float]
    rotation_rvec: tuple[float, float, float]
    frames: int
    spread_m: float


@dataclass(frozen=True)
class RigFile:
    """A validated rig file.

    Attributes
    ----------
    path : str
        Where it was read from.
    name : str
        Free-text name of the rig.
    serial : SerialSpec
    rgb : RgbCameraSpec
    ir : IrCameraSpec
    marker : MarkerMount
    finger : FingerGeometry
    limits : LimitsSpec
    open_aperture_m : float
        Gap between the contact faces at motor position 0 (m).
    marker_finger : int
        Finger carrying the marker and the RGB camera.
    emulator : EmulatorSpec or None
        Present when a camera's source is ``emulator``.
    zero_pose : ZeroPoseSpec or None
        The marker's measured pose at rest (table ``[zero_pose]``), if measured.
    """

    path: str
    name: str
    serial: SerialSpec
    rgb: RgbCameraSpec
    ir: IrCameraSpec
    marker: MarkerMount
    finger: FingerGeometry
    limits: LimitsSpec
    open_aperture_m: float
    marker_finger: int
    emulator: EmulatorSpec | None = None
    zero_pose: ZeroPoseSpec | None = None

    @property
    def geometry(self) -> RigGeometry:
        """The rig as perception and the twin describe it."""
        return RigGeometry(finger=self.finger, marker=self.marker, rgb=self.rgb.mount,
                           ir=self.ir.mount, open_aperture_m=self.open_aperture_m,
                           marker_finger=self.marker_finger,
                           ir_follow_bend=self.ir.follow_bend,
                           marker_zero_m=(None if self.zero_pose is None
                                          else self.zero_pose.position_m))


def _intrinsics(t: _Table) -> CameraIntrinsics:
    width = t.integer("width_px", min_value=1, max_value=16384)
    height = t.integer("height_px", min_value=1, max_value=16384)
    fx = t.number("fx_px", positive=True)
    fy = t.number("fy_px", positive=True)
    cx = t.number("cx_px", (width - 1) / 2.0)
    cy = t.number("cy_px", (height - 1) / 2.0)
    dist = t.numbers("dist", ())
    if len(dist) not in (0, 4, 5, 8, 12, 14):
        raise t.fail("dist", f"needs 0, 4, 5, 8, 12 or 14 coefficients, got {len(dist)}")
    try:
        return CameraIntrinsics(width, height, fx, fy, cx, cy, dist)
    except InputError as exc:  # a bound of the intrinsics themselves: say where it was set
        raise InputError(f"{t.where}: [{t.name}] {exc}") from None


def _stall_s(t: _Table, fps: float, default_ms: float) -> float:
    stall_ms = t.number("stall_ms", max(default_ms, 3000.0 / fps), positive=True)
    if stall_ms * 1e-3 <= 1.0 / fps:
        raise t.fail("stall_ms", f"must exceed one frame period ({1000.0 / fps:.0f} ms), "
                                 f"got {stall_ms:g}")
    return stall_ms * 1e-3


def _device(t: _Table, source: str, real: str) -> int | str | None:
    if source == real:
        return t.device("device")
    if t.has("device"):
        raise t.fail("device", f"is only used with source = {real!r}")
    return None


def _rgb(t: _Table) -> RgbCameraSpec:
    source = t.string("source", choices=RGB_SOURCES)
    device = _device(t, source, "opencv")
    fps = t.number("fps", 30.0, positive=True, max_value=1000.0)
    exposure = t.number("exposure") if t.has("exposure") else None
    t.taken.add("exposure")
    intr = _intrinsics(t)
    pos = t.numbers("position_mm", (-25.0, 0.0, 0.0), length=3)
    toe = t.number("toe_in_deg", 10.0, min_value=-45.0, max_value=45.0)
    stall = _stall_s(t, fps, 200.0)
    mount = RgbCameraMount(intr, fps, (pos[0] * 1e-3, pos[1] * 1e-3, pos[2] * 1e-3), toe)
    return RgbCameraSpec(source, device, fps, exposure, stall, mount)


def _ir(t: _Table) -> IrCameraSpec:
    source = t.string("source", choices=IR_SOURCES)
    device = _device(t, source, "uvc")
    fps = t.number("fps", 1.0, positive=True, max_value=1000.0)
    scale = t.number("scale", 0.01)
    if scale == 0.0:
        raise t.fail("scale", "must not be 0")
    offset = t.number("offset_c", -273.15)
    intr = _intrinsics(t)
    pos = t.numbers("position_mm", (-70.0, 0.0, 60.0), length=3)
    pitch = t.number("pitch_down_deg", 25.0, min_value=-90.0, max_value=90.0)
    stall = _stall_s(t, fps, 2500.0)
    follow = t.raw("follow_bend", True, required=False)
    if not isinstance(follow, bool):
        raise t.fail("follow_bend", f"must be true or false, got {follow!r}")
    mount = IrCameraMount(intr, fps, (pos[0] * 1e-3, pos[1] * 1e-3, pos[2] * 1e-3), pitch)
    return IrCameraSpec(source, device, fps, scale, offset, stall, mount, follow)


def _marker(t: _Table) -> MarkerMount:
    dictionary = t.string("dictionary", "4X4_50")
    if dictionary not in ARUCO_DICTIONARIES:
        raise t.fail("dictionary", f"is not an OpenCV ArUco dictionary: {dictionary!r} "
                                   "(e.g. 4X4_50, 5X5_100)")
    marker_id = t.integer("id", 0)
    n_ids = int(MarkerMount(dictionary=dictionary).aruco_dictionary.bytesList.shape[0])
    if marker_id >= n_ids:
        raise t.fail("id", f"must be below {n_ids} for dictionary {dictionary}, got {marker_id}")
    size = t.number("size_mm", positive=True)
    position = t.number("position_mm", positive=True)
    tilt = t.number("tilt_deg", 30.0, min_value=-74.9, max_value=74.9)
    travel = t.number("max_travel_mm", 20.0, positive=True)
    return MarkerMount(dictionary, marker_id, size * 1e-3, position * 1e-3, tilt,
                       travel * 1e-3)


def _finger(t: _Table) -> FingerGeometry:
    # At most a metre, as the aperture: perception draws the finger in 5 mm pieces, and a
    # length of 1e308 mm is a typo, not a finger.
    length = t.number("length_mm", positive=True, max_value=MAX_APERTURE_MM)
    thickness = t.number("thickness_mm", positive=True)
    height = t.number("height_mm", positive=True)
    beams = t.numbers("beam_positions_mm", (11.0, 33.0, 55.0, 77.0, 99.0))
    if not beams:
        raise t.fail("beam_positions_mm", "needs at least one position")
    for x in beams:
        if not 0.0 <= x <= length:
            raise t.fail("beam_positions_mm", f"must lie on the finger (0..{length:g} mm), "
                                              f"got {x:g}")
    contact = t.number("contact_mm", min(80.0, length), positive=True, max_value=length)
    return FingerGeometry(length * 1e-3, thickness * 1e-3, height * 1e-3,
                          tuple(x * 1e-3 for x in beams), contact * 1e-3)


def _zero_pose(t: _Table) -> ZeroPoseSpec:
    x, y, z = t.numbers("position_mm", length=3)
    if not z > 0.0:
        raise t.fail("position_mm", f"must be in front of the RGB camera (z > 0), got {z:g}")
    rvec = t.numbers("rotation_deg", length=3)
    if math.hypot(*rvec) > 180.0 + 1e-9:
        raise t.fail("rotation_deg", "must be a rotation vector of at most 180 degrees")
    frames = t.integer("frames", min_value=1)
    spread = t.number("spread_mm", min_value=0.0)
    return ZeroPoseSpec((x * 1e-3, y * 1e-3, z * 1e-3),
                        tuple(math.radians(v) for v in rvec),  # type: ignore[arg-type]
                        frames, spread * 1e-3)


def _limits(t: _Table) -> LimitsSpec:
    return LimitsSpec(
        t.number("max_motor_speed_mm_s", 20.0, positive=True, max_value=1000.0),
        t.number("heater_duty_limit", 1.0, min_value=0.0, max_value=1.0),
        t.number("max_temp_c", 70.0, min_value=25.0, max_value=150.0),
    )


def parse_rig(data: dict[str, Any], where: str = "rig file") -> RigFile:
    """Validate the parsed TOML of a rig file.

    Parameters
    ----------
    data : dict
        What :func:`tomllib.loads` returned.
    where : str
        Name of the file, for messages.

    Returns
    -------
    RigFile

    Raises
    ------
    InputError
        One line naming the first bad field.
    """
    known = {"rig", "serial", "rgb", "ir", "marker", "finger", "limits", "emulator", "zero_pose"}
    for key in data:
        if key not in known:
            raise InputError(f"{where}: unknown table [{key}]")
    for key in ("serial", "rgb", "ir", "marker", "finger"):
        if key not in data:
            raise InputError(f"{where}: table [{key}] is missing")
    top = _Table(where, "rig", data.get("rig", {}))
    name = top.string("name", Path(where).stem)
    # At most a metre: the twin's gripper opens 150 mm (a 148 mm stroke); a larger figure is
    # a typo or a unit slip, not a bench gripper.
    aperture = top.number("open_aperture_mm", 150.0, positive=True, max_value=MAX_APERTURE_MM)
    marker_finger = top.integer("marker_finger", 0, max_value=1)
    top.done()

    ser = _Table(where, "serial", data["serial"])
    serial = SerialSpec(
        ser.string("port"),
        ser.integer("baud", 115_200, min_value=300, max_value=10_000_000),
        ser.number("reply_timeout_ms", 100.0, min_value=5.0, max_value=1000.0) * 1e-3,
        ser.number("boot_wait_ms", 2500.0, min_value=0.0, max_value=30_000.0) * 1e-3,
    )
    ser.done()
    tables = {key: _Table(where, key, data[key]) for key in ("rgb", "ir", "marker", "finger")}
    rgb = _rgb(tables["rgb"])
    ir = _ir(tables["ir"])
    marker = _marker(tables["marker"])
    finger = _finger(tables["finger"])
    limits_table = _Table(where, "limits", data.get("limits", {}))
    limits = _limits(limits_table)
    for table in (*tables.values(), limits_table):
        table.done()
    if marker.position_m > finger.length_m:
        raise InputError(f"{where}: [marker] position_mm {marker.position_m * 1e3:g} is beyond "
                         f"the finger's length_mm {finger.length_m * 1e3:g}")
    emulator = None
    uses_emulator = "emulator" in (rgb.source, ir.source)
    if "emulator" in data:
        emu = _Table(where, "emulator", data["emulator"])
        emulator = EmulatorSpec(emu.string("socket"), emu.integer("seed", 0))
        emu.done()
    elif uses_emulator:
        raise InputError(f"{where}: a camera source is 'emulator' but table [emulator] "
                         "(its socket) is missing")
    zero_pose = None
    if "zero_pose" in data:
        zero_table = _Table(where, "zero_pose", data["zero_pose"])
        zero_pose = _zero_pose(zero_table)
        zero_table.done()
    return RigFile(where, name, serial, rgb, ir, marker, finger, limits, aperture * 1e-3,
                   marker_finger, emulator, zero_pose)


def read_rig_text(path: str | Path) -> str:
    """A rig file's text, read with the checks :func:`load_rig` makes (not yet parsed).

    Raises
    ------
    InputError
        The file is missing, not a regular file (a FIFO, a device), larger
        than :data:`MAX_RIG_BYTES` or not UTF-8 text.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"rig file {p} not found")
    check_input_file(p, "rig file", InputError, max_bytes=MAX_RIG_BYTES)
    try:
        with open(p, "rb") as f:  # bounded: the file may have grown since the check
            raw = f.read(MAX_RIG_BYTES + 1)
    except FileNotFoundError:  # removed since the check
        raise InputError(f"rig file {p} not found") from None
    except OSError as exc:
        raise InputError(f"cannot read rig file {p}: {exc.strerror or one_line(exc)}") from None
    if len(raw) > MAX_RIG_BYTES:
        raise InputError(f"{p}: is over the {MAX_RIG_BYTES:,}-byte limit for a rig file")
    try:
        # Universal newlines, as a text-mode read gives: a file saved with CR line ends reads.
        return io.StringIO(raw.decode("utf-8"), newline=None).read()
    except UnicodeDecodeError as exc:
        raise InputError(f"rig file {p} is not UTF-8 text (byte {raw[exc.start]:#04x} at "
                         f"offset {exc.start})") from None


def load_rig(path: str | Path) -> RigFile:
    """Read and validate a rig file.

    Parameters
    ----------
    path : str or Path
        A TOML file.

    Returns
    -------
    RigFile

    Raises
    ------
    InputError
        The file is missing, not a regular file (a FIFO, a device), larger
        than :data:`MAX_RIG_BYTES`, not UTF-8 text, not TOML, or has a bad
        field (one line naming it).
    """
    text = read_rig_text(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"rig file {path} is not valid TOML: {exc}") from None
    return parse_rig(data, str(path))
