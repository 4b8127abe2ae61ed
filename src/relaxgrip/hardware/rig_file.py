"""Rig files: one TOML file describes a gripper, real or emulated, and its twin.

A rig file names the serial port of the MCU and the two cameras (where their
frames come from, how to open them, their intrinsics and mounts), and
describes the gripper: the marker, the finger (outline, stiffness, heat model,
material), the motor, the heaters, the force reference sensor, the
calibration object (the force ball) and the safety limits.  :func:`load_rig`
validates it into frozen dataclasses; :attr:`RigFile.geometry` maps it onto
:class:`relaxgrip.rig.RigGeometry`, the description perception and the twin
share, and :func:`relaxgrip.hardware.rig_twin.twin_config_for_rig` onto the
twin of that gripper.  Every bad field gives one line naming the file, the
table and the key.

A real rig (a camera whose source is a device) gives every property of its
gripper: a missing one is an error naming it and its unit, never a code
default.  An emulator rig (both cameras' source ``emulator``) runs the twin,
and what it leaves out is the twin's own.  Files carry ``[rig] schema``
(:data:`RIG_SCHEMA`); a file without it is schema 1, which described the
geometry only: an emulator rig of schema 1 reads as schema 2 with the twin's
values for the rest, a real one is refused with what to add.

Lengths in the file are in millimetres (``*_mm``), as a lab measures them;
inside they become metres.  A length far outside what a gripper has (a finger
of 0.11 mm) is refused with the unit it was probably written in.  The keys,
their units and meanings: ``docs/rig-file.md``; examples: ``docs/rigs/``
(real rigs) and ``docs/rig-emulator.toml`` (the MCU emulator).
"""

from __future__ import annotations

import io
import math
import tomllib
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from relaxgrip.errors import InputError
from relaxgrip.fileio import check_input_file, one_line
from relaxgrip.limits import OUR_LIMITS, LimitsSpec
from relaxgrip.physics.beam import (
    FingerParams,
    beam_grid,
    contact_deflection_m,
    finger_from_k80,
    unit_profile_m_per_n,
)
from relaxgrip.physics.smp import SMPParams
from relaxgrip.physics.thermal import HeatParams
from relaxgrip.physics.viscoelastic import RelaxationParams
from relaxgrip.rig import (
    ARUCO_DICTIONARIES,
    CameraIntrinsics,
    FingerGeometry,
    IrCameraMount,
    MarkerMount,
    RgbCameraMount,
    RigGeometry,
)
from relaxgrip.twin.config import MotorParams, TwinConfig
from relaxgrip.twin.objects import ObjectSpec
from relaxgrip.twin.sensors import ForceSensorConfig

__all__ = [
    "FORCE_REF_SOURCES",
    "IR_SOURCES",
    "MAX_RIG_BYTES",
    "RGB_SOURCES",
    "RIG_SCHEMA",
    "RIG_SCHEMAS",
    "VIEW_FORCE_N",
    "VIEW_TEMP_C",
    "EmulatorSpec",
    "ForceRefSpec",
    "IrCameraSpec",
    "LimitsSpec",
    "RgbCameraSpec",
    "RigFile",
    "SerialSpec",
    "ZeroPoseSpec",
    "check_marker_in_view",
    "load_rig",
    "parse_rig",
    "read_rig_text",
]

#: The rig-file schema this relaxgrip writes and reads in full (``[rig] schema``).
RIG_SCHEMA = 2
#: Every schema it reads: 1 (geometry only, no ``schema`` key) and 2.
RIG_SCHEMAS = (1, 2)
#: Where RGB frames can come from: an OpenCV ``VideoCapture`` or the MCU emulator.
RGB_SOURCES = ("opencv", "emulator")
#: Where infrared frames can come from: a UVC radiometric (Y16) camera or the MCU emulator.
IR_SOURCES = ("uvc", "emulator")
#: Where the reference force comes from: the MCU's load cell (HX711), an external force
#: gauge on its own serial port, or the twin's force ball (an emulator rig only).
FORCE_REF_SOURCES = ("mcu", "serial", "twin")
#: The widest ``open_aperture_mm`` taken (mm).
MAX_APERTURE_MM = 1000.0
#: The largest rig file read (bytes): one is a few KiB of TOML.
MAX_RIG_BYTES = 1 << 20
#: The marker must stay in the RGB camera's view under this load at the finger's tip (N):
#: the force loop's limit (``ForceControlConfig.max_force_n``) ...
VIEW_FORCE_N = 12.0
#: ... on a finger this hot (°C): the temperature loop's highest setpoint
#: (``ThermalLimits.max_setpoint_c``).
VIEW_TEMP_C = 65.0
#: Fewest pixels the marker's side may span for the detector to find it.
MIN_MARKER_PX = 8.0

#: Units of keys by the ending of their names, longest ending first (for messages).
_UNITS: tuple[tuple[str, str], ...] = (
    ("_n_per_mm", "N/mm"), ("_mm_per_count", "mm per encoder count"), ("_n_m2", "N m^2"),
    ("_j_per_k", "J/K"), ("_w_per_k", "W/K"), ("_per_k", "1/K"), ("_mm_s", "mm/s"),
    ("_mpa", "MPa"), ("_ohm", "ohm"), ("_deg", "degrees"), ("_px", "px"), ("_mm", "mm"),
    ("_ms", "ms"), ("_hz", "Hz"), ("_s", "s"), ("_c", "°C"), ("_k", "K"), ("_n", "N"),
    ("_v", "V"), ("_g", "g"),
)
#: Units (or kinds) of the keys whose names carry none.
_KINDS: dict[str, str] = {
    "schema": "an integer, 2", "name": "text", "marker_finger": "0 or 1", "port": "a path",
    "baud": "bit/s", "source": "text", "device": "an index or a path", "dist": "OpenCV "
    "coefficients, [] for none", "scale": "°C per count", "dictionary": "e.g. 4X4_50",
    "id": "an integer", "frames": "a count", "skeleton_taper": "a share, 0..1",
    "smp_ratio_base": "a ratio",
    "smp_ratio_tip": "a ratio", "stiffening": "no unit", "heater_share": "shares, one a node",
    "friction": "no unit", "wlf_c1": "no unit", "relax_fraction_glassy": "a share, 0..1",
    "relax_fraction_rubbery": "a share, 0..1", "branch_weights": "shares",
}


def _unit(key: str) -> str:
    """What a key is measured in, for a message naming it."""
    if key in _KINDS:
        return _KINDS[key]
    return next((unit for end, unit in _UNITS if key.endswith(end)), "no unit")


@cache
def _twin() -> TwinConfig:
    """The twin's own gripper: what an emulator rig leaves out."""
    return TwinConfig()


class _Table:
    """One TOML table being read: every key taken is checked, leftovers are errors.

    ``strict`` (a real rig): a key read with ``gripper=True`` is a property of
    the gripper and must be given, whatever default the twin has.
    """

    def __init__(self, where: str, name: str, data: Any, strict: bool = False) -> None:
        self.where = where
        self.name = name
        self.strict = strict
        if not isinstance(data, dict):
            raise InputError(f"{where}: [{name}] must be a table")
        self.data: dict[str, Any] = dict(data)
        self.taken: set[str] = set()

    def _field(self, key: str) -> str:
        return f"{self.where}: [{self.name}] {key}"

    def fail(self, key: str, what: str) -> InputError:
        """A one-line error naming the field."""
        return InputError(f"{self._field(key)} {what}")

    def lacks(self, key: str, hint: str = "") -> InputError:
        """A one-line error: the key is missing (with its unit)."""
        return InputError(f"{self.where}: [{self.name}] lacks {key} ({_unit(key)}){hint}")

    def has(self, key: str) -> bool:
        """Whether the key is present."""
        return key in self.data

    def raw(self, key: str, default: Any = None, required: bool = True,
            gripper: bool = False) -> Any:
        """The value of ``key``, or ``default`` if absent and not required."""
        self.taken.add(key)
        if key not in self.data:
            if required or (gripper and self.strict):
                raise self.lacks(key)
            return default
        return self.data[key]

    def number(self, key: str, default: float | None = None, *, positive: bool = False,
               min_value: float | None = None, max_value: float | None = None,
               gripper: bool = False) -> float:
        """A finite number, optionally bounded."""
        value = self.raw(key, default, required=default is None, gripper=gripper)
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

    def length(self, key: str, default: float | None, lo: float, hi: float, what: str, *,
               gripper: bool = True, unit: str = "mm") -> float:
        """A length (in ``unit``, mm by default) that ``what`` can have: ``lo`` to ``hi``.

        One far outside it but inside once read in metres, centimetres or
        micrometres is refused with that unit named: 0.11 for a finger is
        110 mm written in metres.
        """
        value = self.number(key, default, gripper=gripper)
        if lo <= value <= hi:
            return value
        for factor, name in ((1000.0, "metres"), (10.0, "centimetres"), (1e-3, "micrometres")):
            if lo <= value * factor <= hi:
                raise self.fail(key, f"is {value:g} {unit}, not a length {what} has "
                                     f"({lo:g} to {hi:g} {unit}): written in {name}? "
                                     f"{value:g} {name} is {value * factor:g} {unit}")
        raise self.fail(key, f"must be {lo:g} to {hi:g} {unit} for {what}, got {value:g}")

    def integer(self, key: str, default: int | None = None, *, min_value: int = 0,
                max_value: int | None = None, gripper: bool = False) -> int:
        """An integer within bounds."""
        value = self.raw(key, default, required=default is None, gripper=gripper)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"must be an integer, got {value!r}")
        if max_value is None and value < min_value:
            raise self.fail(key, f"must be >= {min_value}, got {value}")
        if max_value is not None and not min_value <= value <= max_value:
            raise self.fail(key, f"must be in {min_value}..{max_value}, got {value}")
        return int(value)

    def string(self, key: str, default: str | None = None,
               choices: tuple[str, ...] | None = None, gripper: bool = False) -> str:
        """A non-empty string, optionally one of ``choices``."""
        value = self.raw(key, default, required=default is None, gripper=gripper)
        if not isinstance(value, str) or not value:
            raise self.fail(key, f"must be a non-empty string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.fail(key, f"must be one of {', '.join(choices)}, got {value!r}")
        return value

    def numbers(self, key: str, default: tuple[float, ...] | None = None,
                length: int | None = None, gripper: bool = False) -> tuple[float, ...]:
        """A list of finite numbers (of a given length)."""
        value = self.raw(key, default, required=default is None, gripper=gripper)
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

    def sub(self, key: str) -> _Table | None:
        """The sub-table ``[name.key]``, if given."""
        self.taken.add(key)
        if key not in self.data:
            return None
        return _Table(self.where, f"{self.name}.{key}", self.data[key], self.strict)

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
    watchdog_s : float or None
        The MCU watchdog's period the host sets before enabling the outputs
        (s, 0.02-2): a host silent this long stops the motor and heaters.
        None: the firmware's own (200 ms).
    """

    port: str
    baud: int = 115_200
    reply_timeout_s: float = 0.1
    boot_wait_s: float = 2.5
    watchdog_s: float | None = None


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
class ForceRefSpec:
    """The force reference sensor: what calibrations and datasets of a real rig read.

    Attributes
    ----------
    source : str
        ``mcu`` (the MCU's load cell, read by its HX711-class ADC), ``serial``
        (an external force gauge on its own serial port) or ``twin`` (the
        twin's force ball, through the emulator; an emulator rig only).
    rate_hz : float
        Readings per second (Hz).
    noise_n : float
        Standard deviation of a reading at rest (N): the twin's force ball
        reads with this noise.
    scale : float
        Conversion ``force_n = reading * scale + offset_n`` (N per reading
        unit; ``mcu``: per ADC count).
    offset_n : float
        Offset of that conversion (N).
    port : str or None
        The gauge's serial port (``serial`` only).
    baud : int or None
        Its line speed (bit/s; ``serial`` only).
    """

    source: str
    rate_hz: float
    noise_n: float
    scale: float = 1.0
    offset_n: float = 0.0
    port: str | None = None
    baud: int | None = None

    @property
    def sensor(self) -> ForceSensorConfig:
        """The twin's force-ball sensor that reads like this one."""
        return ForceSensorConfig(rate_hz=self.rate_hz, noise_n=self.noise_n)

    def force_n(self, reading: Any) -> Any:
        """Convert a raw reading (array or number) to newtons."""
        return reading * self.scale + self.offset_n


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
        The finger's outline and where its beams and its usual contact are.
    limits : LimitsSpec
    open_aperture_m : float
        Gap between the contact faces at motor position 0 (m).
    marker_finger : int
        Finger carrying the marker and the RGB camera.
    stiffness : FingerParams
        The finger's bending stiffness model, with its SMP.
    relax : RelaxationParams
        The SMP's Maxwell branches.
    heat : HeatParams
        The finger's heat model, with its heater film.
    motor : MotorParams
        The closing motor: stroke, top speed, encoder, lag.
    force_ref : ForceRefSpec
        The force reference sensor.
    force_ball : ObjectSpec
        The calibration object (a ball around a force sensor).
    emulator : EmulatorSpec or None
        Present when a camera's source is ``emulator``.
    zero_pose : ZeroPoseSpec or None
        The marker's measured pose at rest (table ``[zero_pose]``), if measured.
    schema : int
        The file's schema version (:data:`RIG_SCHEMAS`).
    from_twin : tuple of str
        What the file leaves to the twin's own values (``"material"`` until a
        rig names its SMP; an emulator rig's omitted tables and keys).
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
    stiffness: FingerParams
    relax: RelaxationParams
    heat: HeatParams
    motor: MotorParams
    force_ref: ForceRefSpec
    force_ball: ObjectSpec
    emulator: EmulatorSpec | None = None
    zero_pose: ZeroPoseSpec | None = None
    schema: int = RIG_SCHEMA
    from_twin: tuple[str, ...] = ()

    @property
    def emulated(self) -> bool:
        """Whether both cameras come from the MCU emulator (the twin runs the gripper)."""
        return self.rgb.source == "emulator" and self.ir.source == "emulator"

    @property
    def geometry(self) -> RigGeometry:
        """The rig as perception and the twin describe it."""
        return RigGeometry(finger=self.finger, marker=self.marker, rgb=self.rgb.mount,
                           ir=self.ir.mount, open_aperture_m=self.open_aperture_m,
                           marker_finger=self.marker_finger,
                           ir_follow_bend=self.ir.follow_bend,
                           marker_zero_m=(None if self.zero_pose is None
                                          else self.zero_pose.position_m))


def _m(t: _Table, key: str, twin_m: float, lo_mm: float, hi_mm: float, what: str) -> float:
    """A gripper length in mm, in metres; the twin's ``twin_m`` where an emulator rig has none."""
    if not t.has(key) and not t.strict:
        t.taken.add(key)
        return twin_m
    return t.length(key, None, lo_mm, hi_mm, what) * 1e-3


def _position_m(t: _Table, twin_m: tuple[float, float, float]) -> tuple[float, float, float]:
    """A camera's ``position_mm`` in metres (the twin's on an emulator rig without one)."""
    if not t.has("position_mm") and not t.strict:
        t.taken.add("position_mm")
        return twin_m
    pos = t.numbers("position_mm", None, length=3)
    biggest = max(abs(p) for p in pos)
    if biggest > MAX_APERTURE_MM:
        raise t.fail("position_mm", f"must be within ±{MAX_APERTURE_MM:g} mm, got {biggest:g}")
    if 0.0 < biggest < 1.0:  # a camera within a millimetre of its origin on every axis
        raise t.fail("position_mm", f"is within 1 mm of the origin on every axis "
                                    f"({', '.join(f'{p:g}' for p in pos)}): written in metres? "
                                    f"in mm it is {', '.join(f'{p * 1e3:g}' for p in pos)}")
    return (pos[0] * 1e-3, pos[1] * 1e-3, pos[2] * 1e-3)


def _intrinsics(t: _Table, twin: CameraIntrinsics) -> CameraIntrinsics:
    width = t.integer("width_px", twin.width_px, min_value=1, max_value=16384, gripper=True)
    height = t.integer("height_px", twin.height_px, min_value=1, max_value=16384, gripper=True)
    fx = t.number("fx_px", twin.fx_px, positive=True, gripper=True)
    fy = t.number("fy_px", twin.fy_px, positive=True, gripper=True)
    same = (width, height) == (twin.width_px, twin.height_px)
    cx = t.number("cx_px", twin.cx_px if same else (width - 1) / 2.0, gripper=True)
    cy = t.number("cy_px", twin.cy_px if same else (height - 1) / 2.0, gripper=True)
    dist = t.numbers("dist", twin.dist, gripper=True)
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
    twin = _twin().rig.rgb
    source = t.string("source", choices=RGB_SOURCES)
    device = _device(t, source, "opencv")
    fps = t.number("fps", 30.0, positive=True, max_value=1000.0)
    exposure = t.number("exposure") if t.has("exposure") else None
    t.taken.add("exposure")
    intr = _intrinsics(t, twin.intrinsics)
    pos = _position_m(t, twin.position_m)
    toe = t.number("toe_in_deg", twin.toe_in_deg, min_value=-45.0, max_value=45.0,
                   gripper=True)
    stall = _stall_s(t, fps, 200.0)
    return RgbCameraSpec(source, device, fps, exposure, stall, RgbCameraMount(intr, fps, pos, toe))


def _ir(t: _Table) -> IrCameraSpec:
    twin = _twin().rig.ir
    source = t.string("source", choices=IR_SOURCES)
    device = _device(t, source, "uvc")
    fps = t.number("fps", 1.0, positive=True, max_value=1000.0)
    scale = t.number("scale", 0.01, gripper=True)
    if scale == 0.0:
        raise t.fail("scale", "must not be 0")
    offset = t.number("offset_c", -273.15, gripper=True)
    intr = _intrinsics(t, twin.intrinsics)
    pos = _position_m(t, twin.position_m)
    pitch = t.number("pitch_down_deg", twin.pitch_down_deg, min_value=-90.0, max_value=90.0,
                     gripper=True)
    stall = _stall_s(t, fps, 2500.0)
    follow = t.raw("follow_bend", True, required=False)
    if not isinstance(follow, bool):
        raise t.fail("follow_bend", f"must be true or false, got {follow!r}")
    return IrCameraSpec(source, device, fps, scale, offset, stall,
                        IrCameraMount(intr, fps, pos, pitch), follow)


def _marker(t: _Table) -> MarkerMount:
    twin = _twin().rig.marker
    dictionary = t.string("dictionary", twin.dictionary, gripper=True)
    if dictionary not in ARUCO_DICTIONARIES:
        raise t.fail("dictionary", f"is not an OpenCV ArUco dictionary: {dictionary!r} "
                                   "(e.g. 4X4_50, 5X5_100)")
    marker_id = t.integer("id", twin.marker_id, gripper=True)
    n_ids = int(MarkerMount(dictionary=dictionary).aruco_dictionary.bytesList.shape[0])
    if marker_id >= n_ids:
        raise t.fail("id", f"must be below {n_ids} for dictionary {dictionary}, got {marker_id}")
    size = _m(t, "size_mm", twin.size_m, 2.0, 200.0, "a marker's side")
    position = _m(t, "position_mm", twin.position_m, 1.0, MAX_APERTURE_MM,
                  "a marker's place on a finger")
    tilt = t.number("tilt_deg", twin.tilt_deg, min_value=-74.9, max_value=74.9, gripper=True)
    travel = t.number("max_travel_mm", twin.max_travel_m * 1e3, positive=True)
    return MarkerMount(dictionary, marker_id, size, position, tilt, travel * 1e-3)


def _finger(t: _Table) -> FingerGeometry:
    twin = _twin().rig.finger
    # At most a metre, as the aperture: perception draws the finger in 5 mm pieces, and a
    # length of 1e308 mm is a typo, not a finger.
    length_m = _m(t, "length_mm", twin.length_m, 20.0, MAX_APERTURE_MM, "a finger")
    thickness_m = _m(t, "thickness_mm", twin.thickness_m, 1.0, 100.0, "a finger's thickness")
    height_m = _m(t, "height_mm", twin.height_m, 2.0, 200.0, "a finger's height")
    length = length_m * 1e3
    if not t.has("beam_positions_mm") and not t.strict and length_m == twin.length_m:
        t.taken.add("beam_positions_mm")
        beams_m = twin.beam_positions_m
    else:
        beams = t.numbers("beam_positions_mm", gripper=True)
        if not beams:
            raise t.fail("beam_positions_mm", "needs at least one position")
        for x in beams:
            if not 0.0 <= x <= length:
                raise t.fail("beam_positions_mm", f"must lie on the finger (0..{length:g} "
                                                  f"mm), got {x:g}")
        if max(beams) < 1.0:
            in_mm = ", ".join(f"{x * 1e3:g}" for x in beams)
            raise t.fail("beam_positions_mm", f"all lie within 1 mm of the root of a "
                                              f"{length:g} mm finger: written in metres? in mm "
                                              f"they are {in_mm}")
        beams_m = tuple(x * 1e-3 for x in beams)
    if t.has("contact_mm"):
        contact = t.number("contact_mm", positive=True, max_value=length)
        if contact < 1.0:
            raise t.fail("contact_mm", f"is {contact:g} mm from the root: written in metres? "
                                       f"{contact:g} m is {contact * 1e3:g} mm")
        contact_m = contact * 1e-3
    else:  # where a hold usually grasps: a setting, the twin's where the finger reaches
        t.taken.add("contact_mm")
        contact_m = min(twin.contact_m, length_m)
    return FingerGeometry(length_m, thickness_m, height_m, beams_m, contact_m)


#: The keys of a measured stiffness (``k80`` at two temperatures), instead of its parts.
_K80_KEYS = ("k80_n_per_mm", "k80_temps_c", "k80_force_n")
#: The keys of the stiffness's two parts that a measured ``k80`` replaces.
_PART_KEYS = ("ei_skeleton_base_n_m2", "smp_ratio_base")


def _stiffness(t: _Table, length_m: float, smp: SMPParams) -> tuple[FingerParams, bool]:
    """The finger's stiffness model and whether the file left it to the twin."""
    twin = replace(_twin().finger, length_m=length_m, smp=smp)
    given = [k for k in (*_K80_KEYS, *_PART_KEYS) if t.has(k)]
    model = replace(
        twin,
        skeleton_taper=t.number("skeleton_taper", twin.skeleton_taper, min_value=0.0,
                                max_value=0.99, gripper=True),
        skeleton_temp_coeff_per_k=t.number(
            "skeleton_temp_coeff_per_k", twin.skeleton_temp_coeff_per_k, min_value=0.0,
            max_value=0.02, gripper=True),
        smp_ratio_tip=t.number("smp_ratio_tip", twin.smp_ratio_tip, min_value=0.0,
                               max_value=1000.0, gripper=True),
        stiffening=t.number("stiffening", twin.stiffening, min_value=0.0, max_value=100.0,
                            gripper=True),
        ref_temp_c=t.number("ref_temp_c", twin.ref_temp_c, min_value=0.0, max_value=60.0,
                            gripper=True),
    )
    measured = [k for k in _K80_KEYS if k in given]
    if measured and any(k in given for k in _PART_KEYS):
        raise t.fail(measured[0], "and ei_skeleton_base_n_m2 / smp_ratio_base describe the "
                                  "same stiffness: give one of them")
    if measured:
        for key in _K80_KEYS:
            if not t.has(key):
                raise t.lacks(key, f" beside {measured[0]}")
        k80 = t.numbers("k80_n_per_mm", length=2)
        temps = t.numbers("k80_temps_c", length=2)
        force = t.number("k80_force_n", positive=True, max_value=100.0)
        if min(k80) <= 0.0:
            raise t.fail("k80_n_per_mm", f"must be > 0, got {k80[0]:g}, {k80[1]:g}")
        if length_m < 0.080:
            raise t.fail("k80_n_per_mm", f"is the stiffness 80 mm from the root, beyond this "
                                         f"{length_m * 1e3:g} mm finger: give "
                                         "ei_skeleton_base_n_m2 and smp_ratio_base")
        try:
            return finger_from_k80(model, (k80[0] * 1e3, k80[1] * 1e3), (temps[0], temps[1]),
                                   force), False
        except ValueError as exc:
            raise t.fail("k80_n_per_mm", str(exc)) from None
    if not given and not t.strict:
        t.taken.update(_PART_KEYS)
        return model, True
    for key in _PART_KEYS:
        if not t.has(key):
            raise t.lacks(key, "; or give the measured k80_n_per_mm, k80_temps_c and "
                               "k80_force_n")
    ei = t.number("ei_skeleton_base_n_m2", positive=True, max_value=1000.0)
    ratio = t.number("smp_ratio_base", min_value=0.0, max_value=1000.0)
    return replace(model, ei_skeleton_base_n_m2=ei, smp_ratio_base=ratio), False


#: ``[finger.smp]``: the SMP's constants (SMPParams; moduli in MPa) and its Maxwell branches.
_SMP_KEYS = ("tg_c", "e_glassy_mpa", "e_rubbery_mpa", "transition_width_k", "wlf_c1",
             "wlf_c2_k", "relax_fraction_glassy", "relax_fraction_rubbery", "relax_onset_c",
             "relax_onset_width_k", "branch_weights", "tau_ref_s")


def _material(finger: _Table) -> tuple[SMPParams, RelaxationParams, bool]:
    """The finger's SMP and its relaxation, and whether the file left them to the twin.

    ``material = "FILE.json"`` in ``[finger]`` (relative to the rig file) is a
    material file of ``relaxgrip fit-material``; it excludes ``[finger.smp]``.
    """
    if finger.has("material"):
        from relaxgrip.hardware.material_file import load_material_file
        from relaxgrip.twin import TwinConfig

        name = finger.string("material")
        if "smp" in finger.data:
            raise finger.fail("material", "and [finger.smp] both describe the SMP; keep one")
        finger.taken.add("smp")
        cfg = TwinConfig().with_material(
            load_material_file(Path(finger.where).parent / name))
        return cfg.finger.smp, cfg.relax, False
    t = finger.sub("smp")
    if t is None:  # the twin's SMP, until a rig names its material
        twin = _twin()
        return twin.finger.smp, twin.relax, True
    values = {k: t.number(k) for k in _SMP_KEYS if k not in ("branch_weights", "tau_ref_s")}
    weights = t.numbers("branch_weights")
    taus = t.numbers("tau_ref_s")
    t.done()
    if not values["e_glassy_mpa"] > values["e_rubbery_mpa"] > 0.0:
        raise t.fail("e_glassy_mpa", f"{values['e_glassy_mpa']:g} must exceed e_rubbery_mpa "
                                     f"{values['e_rubbery_mpa']:g}, and both be > 0")
    try:
        smp = SMPParams(
            tg_c=values["tg_c"], e_glassy_pa=values["e_glassy_mpa"] * 1e6,
            e_rubbery_pa=values["e_rubbery_mpa"] * 1e6,
            transition_width_k=values["transition_width_k"], wlf_c1=values["wlf_c1"],
            wlf_c2_k=values["wlf_c2_k"], relax_fraction_glassy=values["relax_fraction_glassy"],
            relax_fraction_rubbery=values["relax_fraction_rubbery"],
            relax_onset_c=values["relax_onset_c"],
            relax_onset_width_k=values["relax_onset_width_k"])
        relax = RelaxationParams(branch_weights=weights, tau_ref_s=taus)
    except ValueError as exc:
        raise InputError(f"{t.where}: [{t.name}] {exc}") from None
    return smp, relax, False


def _thermal(finger: _Table, heaters: _Table | None, length_m: float
             ) -> tuple[HeatParams, list[str]]:
    """The finger's heat model (``[finger.thermal]`` and ``[heaters]``) and what came
    from the twin."""
    twin = replace(_twin().heat, length_m=length_m)
    left: list[str] = []
    t = finger.sub("thermal")
    if t is None:
        if finger.strict:
            raise InputError(f"{finger.where}: table [finger.thermal] is missing (the finger's "
                             "heat model: capacity_j_per_k, conductance_w_per_k, "
                             "convection_w_per_k, base_conductance_w_per_k, heater_share)")
        left.append("finger.thermal")
        model = twin
    else:
        share = t.numbers("heater_share")
        if not share:
            raise t.fail("heater_share", "needs one share a node, got none")
        try:
            model = replace(
                twin, n_nodes=len(share), heater_share=share,
                capacity_j_per_k=t.number("capacity_j_per_k", positive=True, max_value=1e4),
                conductance_w_per_k=t.number("conductance_w_per_k", min_value=0.0,
                                             max_value=1e3),
                convection_w_per_k=t.number("convection_w_per_k", positive=True,
                                            max_value=1e3),
                base_conductance_w_per_k=t.number("base_conductance_w_per_k", min_value=0.0,
                                                  max_value=1e3))
        except ValueError as exc:
            raise InputError(f"{t.where}: [{t.name}] {exc}") from None
        t.done()
    if heaters is None:
        left.append("heaters")
        return model, left
    out = replace(model,
                  heater_resistance_ohm=heaters.number("resistance_ohm", positive=True,
                                                       max_value=1e6),
                  heater_voltage_v=heaters.number("supply_v", positive=True, max_value=1000.0))
    heaters.done()
    return out, left


def _motor(t: _Table, aperture_m: float) -> MotorParams:
    stroke = t.length("stroke_mm", None, 1.0, MAX_APERTURE_MM, "a gripper's stroke")
    if stroke * 1e-3 > aperture_m:
        raise t.fail("stroke_mm", f"{stroke:g} exceeds [rig] open_aperture_mm "
                                  f"{aperture_m * 1e3:g}: the fingers would cross")
    return MotorParams(
        max_velocity_mm_s=t.length("max_speed_mm_s", None, 0.1, 1000.0, "a motor's top speed",
                                   unit="mm/s"),
        lag_s=t.number("lag_ms", positive=True, max_value=10_000.0) * 1e-3,
        stroke_mm=stroke,
        encoder_resolution_mm=t.length("encoder_mm_per_count", None, 1e-5, 1.0,
                                       "an encoder count"),
    )


def _force_ref(t: _Table, emulated: bool) -> ForceRefSpec:
    twin = _twin().force_sensor
    assert twin is not None
    source = t.string("source", choices=FORCE_REF_SOURCES)
    if source == "twin" and not emulated:
        raise t.fail("source", "'twin' reads the twin's force ball: only an emulator rig (both "
                               "cameras' source = 'emulator') has one; a real rig reads 'mcu' "
                               "or 'serial'")
    rate = t.number("rate_hz", twin.rate_hz, positive=True, max_value=10_000.0,
                    gripper=source != "twin")
    noise = t.number("noise_n", twin.noise_n, min_value=0.0, max_value=10.0,
                     gripper=source != "twin")
    if source == "twin":
        return ForceRefSpec(source, rate, noise)
    scale = t.number("scale")
    if scale == 0.0:
        raise t.fail("scale", "must not be 0")
    offset = t.number("offset_n")
    port = baud = None
    if source == "serial":
        port = t.string("port")
        baud = t.integer("baud", min_value=300, max_value=10_000_000)
    else:
        for key in ("port", "baud"):
            if t.has(key):
                raise t.fail(key, "is only used with source = 'serial'")
    return ForceRefSpec(source, rate, noise, scale, offset, port, baud)


def _force_ball(t: _Table) -> ObjectSpec:
    return replace(
        _twin().force_ball,
        width_m=t.length("diameter_mm", None, 5.0, 500.0, "a force ball") * 1e-3,
        stiffness_n_per_m=t.number("stiffness_n_per_mm", positive=True, max_value=1e4) * 1e3,
        mass_kg=t.number("mass_g", positive=True, max_value=1e5) * 1e-3,
        friction_coeff=t.number("friction", positive=True, max_value=5.0),
    )


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


def _limits(t: _Table, motor: MotorParams) -> LimitsSpec:
    """``[limits]``: each key absent is our gripper's (:data:`relaxgrip.limits.OUR_LIMITS`),
    except the motor's: the speed limit is at most the rig's motor's top speed, and the travel
    its stroke (neither may exceed them)."""
    ours = OUR_LIMITS
    values = {
        "max_target_n": t.number("max_target_n", ours.max_target_n, positive=True,
                                 max_value=1000.0),
        "max_force_n": t.number("max_force_n", ours.max_force_n, positive=True,
                                max_value=1000.0),
        "min_setpoint_c": t.number("min_setpoint_c", ours.min_setpoint_c, min_value=-50.0,
                                   max_value=150.0),
        "max_setpoint_c": t.number("max_setpoint_c", ours.max_setpoint_c, min_value=-50.0,
                                   max_value=150.0),
        "max_temp_c": t.number("max_temp_c", ours.max_temp_c, min_value=25.0, max_value=150.0),
        "heater_duty_limit": t.number("heater_duty_limit", ours.heater_duty_limit,
                                      min_value=0.0, max_value=1.0),
        "max_motor_speed_mm_s": t.number(
            "max_motor_speed_mm_s", min(ours.max_motor_speed_mm_s, motor.max_velocity_mm_s),
            positive=True, max_value=motor.max_velocity_mm_s),
        "stroke_mm": t.number("stroke_mm", motor.stroke_mm, positive=True,
                              max_value=motor.stroke_mm),
    }
    try:
        return LimitsSpec(**values)
    except InputError as exc:  # limits that contradict each other: say where they were set
        raise InputError(f"{t.where}: [limits] {str(exc).removeprefix('limits: ')}") from None


#: Tables a rig file may have.
_TABLES = ("rig", "serial", "rgb", "ir", "marker", "finger", "motor", "heaters", "force_ref",
           "force_ball", "limits", "emulator", "zero_pose")
#: What each of the gripper's tables holds, for a real rig that lacks one.
_GRIPPER_TABLES = {
    "motor": "stroke_mm, max_speed_mm_s, encoder_mm_per_count, lag_ms",
    "heaters": "resistance_ohm, supply_v",
    "force_ref": "source, rate_hz, noise_n, scale, offset_n",
    "force_ball": "diameter_mm, stiffness_n_per_mm, mass_g, friction",
}


def _schema(where: str, top: _Table, emulated: bool) -> int:
    """The file's schema version; a real rig of schema 1 is refused with what to add."""
    if not top.has("schema"):
        top.taken.add("schema")
        if not emulated:
            raise InputError(
                f"{where}: a schema 1 rig file (no [rig] schema) describes the geometry only: "
                f"add schema = {RIG_SCHEMA} to [rig], the tables "
                f"{', '.join(f'[{k}]' for k in _GRIPPER_TABLES)} and [finger.thermal], and the "
                "finger's stiffness to [finger] (docs/rig-file.md)")
        return 1
    schema = top.integer("schema", min_value=0, max_value=10**6)
    if schema not in RIG_SCHEMAS:
        raise top.fail("schema", f"{schema} is not a version this relaxgrip reads "
                                 f"({' or '.join(map(str, RIG_SCHEMAS))}): a newer relaxgrip "
                                 "wrote it, or it is a typo")
    return schema


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
        One line naming the first bad field: missing (with its unit), mistyped,
        out of range, a length in the wrong unit, a marker the RGB camera does
        not see (:func:`check_marker_in_view`), an unknown schema.
    """
    for key in data:
        if key not in _TABLES:
            raise InputError(f"{where}: unknown table [{key}]")
    for key in ("serial", "rgb", "ir"):
        if key not in data:
            raise InputError(f"{where}: table [{key}] is missing")
    sources = [data[k].get("source") if isinstance(data[k], dict) else None
               for k in ("rgb", "ir")]
    emulated = sources == ["emulator", "emulator"]
    strict = not emulated  # a real rig: every property of the gripper given
    for key in ("marker", "finger"):
        if key not in data and strict:
            raise InputError(f"{where}: table [{key}] is missing")
    twin = _twin()
    top = _Table(where, "rig", data.get("rig", {}), strict)
    schema = _schema(where, top, emulated)
    name = top.string("name", Path(where).stem)
    # At most a metre: the twin's gripper opens 150 mm (a 148 mm stroke); a larger figure is
    # a typo or a unit slip, not a bench gripper.
    aperture = _m(top, "open_aperture_mm", twin.rig.open_aperture_m, 5.0, MAX_APERTURE_MM,
                  "a gripper's opening")
    marker_finger = top.integer("marker_finger", twin.rig.marker_finger, max_value=1,
                                gripper=True)
    top.done()

    ser = _Table(where, "serial", data["serial"])
    serial = SerialSpec(
        ser.string("port"),
        ser.integer("baud", 115_200, min_value=300, max_value=10_000_000),
        ser.number("reply_timeout_ms", 100.0, min_value=5.0, max_value=1000.0) * 1e-3,
        ser.number("boot_wait_ms", 2500.0, min_value=0.0, max_value=30_000.0) * 1e-3,
        (ser.number("watchdog_ms", min_value=20.0, max_value=2000.0) * 1e-3
         if ser.has("watchdog_ms") else None),
    )
    ser.done()
    tables = {key: _Table(where, key, data.get(key, {}), strict)
              for key in ("rgb", "ir", "marker", "finger")}
    rgb = _rgb(tables["rgb"])
    ir = _ir(tables["ir"])
    marker = _marker(tables["marker"])
    finger = _finger(tables["finger"])
    if marker.position_m > finger.length_m:
        raise InputError(f"{where}: [marker] position_mm {marker.position_m * 1e3:g} is beyond "
                         f"the finger's length_mm {finger.length_m * 1e3:g}")
    left: list[str] = []
    smp, relax, twin_smp = _material(tables["finger"])
    stiffness, twin_stiffness = _stiffness(tables["finger"], finger.length_m, smp)
    if twin_smp:
        left.append("material")
    if twin_stiffness:
        left.append("finger stiffness")
    gripper: dict[str, _Table | None] = {}
    for key, holds in _GRIPPER_TABLES.items():
        if key in data:
            gripper[key] = _Table(where, key, data[key], strict)
        elif strict:
            raise InputError(f"{where}: table [{key}] is missing ({holds})")
        else:
            gripper[key] = None
            if key != "heaters":  # said with the heat model's
                left.append(key)
    heat, thermal_left = _thermal(tables["finger"], gripper["heaters"], finger.length_m)
    left += thermal_left
    motor_t, ref_t, ball_t = gripper["motor"], gripper["force_ref"], gripper["force_ball"]
    motor = twin.motor if motor_t is None else _motor(motor_t, aperture)
    if motor_t is None and motor.stroke_mm * 1e-3 > aperture:
        raise InputError(f"{where}: [rig] open_aperture_mm {aperture * 1e3:g} is less than the "
                         f"twin's stroke of {motor.stroke_mm:g} mm: give the rig's [motor]")
    force_ref = (ForceRefSpec("twin", *_twin_sensor()) if ref_t is None
                 else _force_ref(ref_t, emulated))
    force_ball = twin.force_ball if ball_t is None else _force_ball(ball_t)
    limits_table = _Table(where, "limits", data.get("limits", {}))
    limits = _limits(limits_table, motor)
    for table in (*tables.values(), limits_table, *(t for t in gripper.values() if t)):
        table.done()
    emulator = None
    if "emulator" in data:
        emu = _Table(where, "emulator", data["emulator"])
        emulator = EmulatorSpec(emu.string("socket"), emu.integer("seed", 0))
        emu.done()
    elif "emulator" in (rgb.source, ir.source):
        raise InputError(f"{where}: a camera source is 'emulator' but table [emulator] "
                         "(its socket) is missing")
    zero_pose = None
    if "zero_pose" in data:
        zero_table = _Table(where, "zero_pose", data["zero_pose"])
        zero_pose = _zero_pose(zero_table)
        zero_table.done()
    rig = RigFile(path=where, name=name, serial=serial, rgb=rgb, ir=ir, marker=marker,
                  finger=finger, limits=limits, open_aperture_m=aperture,
                  marker_finger=marker_finger, stiffness=stiffness, relax=relax, heat=heat,
                  motor=motor, force_ref=force_ref, force_ball=force_ball, emulator=emulator,
                  zero_pose=zero_pose, schema=schema,
                  from_twin=tuple(left))
    check_marker_in_view(rig)
    return rig


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


def _twin_sensor() -> tuple[float, float]:
    """The twin's force-ball sensor: rate (Hz) and noise (N)."""
    sensor = _twin().force_sensor
    assert sensor is not None
    return sensor.rate_hz, sensor.noise_n


def check_marker_in_view(rig: RigFile) -> None:
    """Refuse a rig whose RGB camera does not see the whole marker, unbent and bent.

    The marker is projected through the rig's camera at rest and with the
    finger bent by :data:`VIEW_FORCE_N` at its tip at :data:`VIEW_TEMP_C`
    (the most the force and temperature loops allow, on the rig's own beam
    model); each of its corners must fall in front of the camera and inside
    the image, and its side span at least :data:`MIN_MARKER_PX` pixels.

    Raises
    ------
    InputError
        One line saying where the marker falls, and what in the file sets it.
    """
    geometry = rig.geometry
    beam = rig.stiffness
    z_unit, slope_unit = unit_profile_m_per_n(beam.length_m, VIEW_TEMP_C, beam)
    x = beam_grid(beam)
    tip = float(z_unit[-1])
    scale = float(contact_deflection_m(VIEW_FORCE_N, tip, beam)) / tip
    at = rig.marker.position_m
    bent = (float(np.interp(at, x, z_unit)) * scale, float(np.interp(at, x, slope_unit)) * scale)
    intr = rig.rgb.mount.intrinsics
    for deflection_m, slope_rad in ((0.0, 0.0), bent):
        pose = geometry.marker2cam(deflection_m, slope_rad)
        corners = rig.marker.object_points_m @ pose[:3, :3].T + pose[:3, 3]
        state = ("at rest" if deflection_m == 0.0 else
                 f"bent {deflection_m * 1e3:.1f} mm by {VIEW_FORCE_N:g} N at the tip at "
                 f"{VIEW_TEMP_C:g} °C")
        fix = ("check [marker] position_mm and tilt_deg, [rgb] position_mm, toe_in_deg "
               "and intrinsics")
        if float(corners[:, 2].min()) <= 1e-3:
            raise InputError(f"{rig.path}: [marker] is behind the RGB camera {state}: {fix}")
        px = intr.project(corners)
        outside = [(u, v) for u, v in px
                   if not (0.0 <= u <= intr.width_px - 1 and 0.0 <= v <= intr.height_px - 1)]
        if outside:
            u, v = outside[0]
            raise InputError(f"{rig.path}: [marker] is outside the RGB camera's view {state}: "
                             f"a corner falls at ({u:.0f}, {v:.0f}) px of a "
                             f"{intr.width_px}x{intr.height_px} image; {fix}")
        side = float(np.linalg.norm(np.roll(px, 1, axis=0) - px, axis=1).min())
        if side < MIN_MARKER_PX:
            raise InputError(f"{rig.path}: [marker] spans {side:.1f} px on the RGB image "
                             f"{state}, too few to detect (at least {MIN_MARKER_PX:g}): {fix}")


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
