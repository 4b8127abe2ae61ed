"""The zero pose: where the finger's marker is, in the RGB camera's frame, with the gripper at rest.

Perception reads a grasp as the marker's motion from where it sits on the
unloaded finger.  :func:`measure_zero_pose` measures that place on a gripper
(any :class:`relaxgrip.backend.Gripper`: the serial rig, the emulator, the
twin) and refuses unless the gripper is at rest throughout:

* the **heaters off** (the duty read back is 0) and the fingers cool (the
  infrared frame's finger temperature at most ``max_temp_c``): a warm SMP
  beam is soft and the finger's rest shape not yet its cold one;
* **nothing on the fingers**: the force reference reads at most
  ``max_force_n`` (a rig without one must say so, ``require_force_ref``
  off, after making sure the fingers are empty);
* the **marker found** on nearly every frame, the one of the rig's
  dictionary and id nearest where the mounts put it;
* its pose **still** over the frames: no frame further than ``max_spread_mm``
  and ``max_spread_deg`` from their mean (a finger still creeping back
  after a grasp, a camera on a vibrating bench).

The motor is held still and the heaters off while it measures.  The result
is written to the rig file's ``[zero_pose]`` (``relaxgrip zero-pose
--write``), where :attr:`relaxgrip.rig.RigGeometry.marker_zero_m` gives it to
perception as the marker's home; the offset reported is from where the
mounts put the marker.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Command, Gripper, Observation
from relaxgrip.clock import Clock
from relaxgrip.errors import InputError
from relaxgrip.perception.marker import (
    MarkerPose,
    PoseSolver,
    detect_markers,
    detection_pose,
    make_detector,
    mean_rotation,
    rotation_angle,
    to_gray,
)
from relaxgrip.perception.thermal import ThermalPerception
from relaxgrip.rig import RigGeometry

FloatArray = NDArray[np.float64]

__all__ = ["GripperNotAtRestError", "ZeroPose", "ZeroPoseLimits", "measure_zero_pose"]


class GripperNotAtRestError(InputError):
    """The gripper was not at rest while the zero pose was measured; the message says how."""


@dataclass(frozen=True)
class ZeroPoseLimits:
    """What "at rest" means.

    Attributes
    ----------
    frames : int
        RGB frames the pose is averaged over.
    max_force_n : float
        Largest force-reference reading taken (N, either sign).
    max_temp_c : float
        Warmest finger taken (°C, as the infrared camera reads it).
    max_spread_mm : float
        Farthest a frame's marker position may lie from the mean (mm).
    max_spread_deg : float
        Farthest a frame's marker rotation may lie from the mean (degrees).
    min_found : float
        Least share of the frames the marker must be found on.
    """

    frames: int = 30
    max_force_n: float = 0.1
    max_temp_c: float = 35.0
    max_spread_mm: float = 0.1
    max_spread_deg: float = 0.3
    min_found: float = 0.9

    def __post_init__(self) -> None:
        if not 5 <= self.frames <= 10_000:
            raise InputError(f"--frames must be 5 to 10000, got {self.frames}")
        for name in ("max_force_n", "max_spread_mm", "max_spread_deg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be > 0 and finite, got {value}")
        if not (math.isfinite(self.max_temp_c) and -20.0 <= self.max_temp_c <= 100.0):
            raise InputError(f"max_temp_c must be -20 to 100 °C, got {self.max_temp_c}")
        if not 0.0 < self.min_found <= 1.0:
            raise InputError(f"min_found must be within (0, 1], got {self.min_found}")


@dataclass(frozen=True)
class ZeroPose:
    """The marker's pose at rest, and how still and unloaded the gripper was.

    Attributes
    ----------
    position_m : tuple of float
        Marker centre in the RGB camera frame (m), mean over the frames.
    rotation_rvec : tuple of float
        Marker rotation in the camera frame, a rotation vector (rad): the
        chordal mean over the frames.
    frames : int
        Frames the marker was found on and averaged.
    frames_seen : int
        RGB frames looked at.
    spread_m : float
        Farthest a frame's position lay from the mean (m).
    spread_rad : float
        Farthest a frame's rotation lay from the mean (rad).
    max_force_n : float or None
        Largest force-reference reading (N); None without a force reference.
    finger_temp_c : float
        Warmest finger temperature read (°C); nan without an infrared frame.
    offset_m : float
        Distance from where the rig's mounts put the marker (m).
    """

    position_m: tuple[float, float, float]
    rotation_rvec: tuple[float, float, float]
    frames: int
    frames_seen: int
    spread_m: float
    spread_rad: float
    max_force_n: float | None
    finger_temp_c: float
    offset_m: float

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form (``--json``), in the rig file's units."""
        return {
            "position_mm": [v * 1e3 for v in self.position_m],
            "rotation_deg": [math.degrees(v) for v in self.rotation_rvec],
            "frames": self.frames, "frames_seen": self.frames_seen,
            "spread_mm": self.spread_m * 1e3, "spread_deg": math.degrees(self.spread_rad),
            "max_force_n": self.max_force_n,
            "finger_temp_c": None if math.isnan(self.finger_temp_c) else self.finger_temp_c,
            "offset_from_mounts_mm": self.offset_m * 1e3,
        }


def measure_zero_pose(gripper: Gripper, clock: Clock, rig: RigGeometry,
                      limits: ZeroPoseLimits | None = None, *, require_force_ref: bool = True,
                      period_s: float = 0.02, timeout_s: float | None = None) -> ZeroPose:
    """Measure the marker's pose at rest on a started gripper.

    Parameters
    ----------
    gripper : Gripper
        The gripper, reset (its cameras streaming).  It is sent stop
        commands (motor still, heaters off) throughout.
    clock : Clock
        The gripper's clock.
    rig : RigGeometry
        Camera intrinsics and the marker (dictionary, id, size, mounts).
    limits : ZeroPoseLimits, optional
        What "at rest" means (the defaults otherwise).
    require_force_ref : bool
        Refuse when no force-reference reading arrives.
    period_s : float
        Time between observations (s).
    timeout_s : float, optional
        Longest wait for the frames (s); default three times their duration
        at the camera's rate, plus 2 s.

    Returns
    -------
    ZeroPose

    Raises
    ------
    GripperNotAtRestError
        Heaters on, fingers warm, a load on the fingers, no force reference
        (with ``require_force_ref``), the marker not found, or its pose not
        still: the message says which, with the figures.
    InputError
        Bad limits or settings.
    """
    lim = limits if limits is not None else ZeroPoseLimits()
    if not (math.isfinite(period_s) and 0.0 < period_s <= 1.0):
        raise InputError(f"period_s must be within (0, 1] s, got {period_s}")
    rate_hz = rig.rgb.rate_hz
    wait_s = timeout_s if timeout_s is not None else 3.0 * lim.frames / rate_hz + 2.0
    first = gripper.observe()
    _check_heaters(first)
    solver = PoseSolver(rig.marker.size_m, rig.rgb.intrinsics)
    detector = make_detector(rig.marker.aruco_dictionary)
    thermal = ThermalPerception(rig)
    home_m = rig.marker2cam()[:3, 3]  # where the mounts put it
    home_px = rig.rgb.intrinsics.project(np.asarray(rig.marker_home_m)[None, :])[0]
    poses: list[MarkerPose] = []
    forces: list[float] = []
    temps: list[float] = []
    seen_rgb: set[int] = set()
    seen_ir: set[int] = set()
    others: set[int] = set()
    start = clock.now()
    obs = first
    while True:
        _check_heaters(obs)
        if obs.force_ref is not None and obs.force_ref.force_n.size:
            forces.extend(np.abs(obs.force_ref.force_n).tolist())
        if obs.ir is not None and obs.ir.seq not in seen_ir:
            seen_ir.add(obs.ir.seq)
            features = thermal.extract(obs.ir, obs.motor_position_mm)
            temps.extend(f.max_c for f in features.fingers if math.isfinite(f.max_c))
        if obs.rgb is not None and obs.rgb.seq not in seen_rgb:
            seen_rgb.add(obs.rgb.seq)
            pose, ids = _marker_pose(obs, detector, solver, rig.marker.marker_id, home_px)
            others |= ids
            if pose is not None:
                poses.append(pose)
        if len(seen_rgb) >= lim.frames:
            break
        if clock.now() - start > wait_s:
            raise GripperNotAtRestError(
                f"the RGB camera gave {len(seen_rgb)} frames in {wait_s:.1f} s, "
                f"{lim.frames} needed")
        gripper.act(Command())
        clock.sleep_until(clock.now() + period_s)
        obs = gripper.observe()
    gripper.act(Command())
    return _judge(poses, len(seen_rgb), forces, temps, others, home_m, rig, lim,
                  require_force_ref)


def _check_heaters(obs: Observation) -> None:
    duty = max(obs.heater_duty)
    if duty > 0.0:
        raise GripperNotAtRestError(
            f"heaters on (duty {obs.heater_duty[0]:.2f}, {obs.heater_duty[1]:.2f}): switch them "
            "off and let the fingers cool before the zero pose")


def _marker_pose(obs: Observation, detector: cv2.aruco.ArucoDetector, solver: PoseSolver,
                 marker_id: int, home_px: FloatArray) -> tuple[MarkerPose | None, set[int]]:
    """The rig's marker in one frame (of several of its id, the nearest the mounts' place),
    and the other ids seen."""
    assert obs.rgb is not None
    gray = to_gray(np.asarray(obs.rgb.image, dtype=np.uint8))
    found = detect_markers(gray, detector)
    mine = [d for d in found if d.marker_id == marker_id]
    others = {d.marker_id for d in found} - {marker_id}
    if not mine:
        return None, others
    det = min(mine, key=lambda d: float(np.linalg.norm(d.corners_px.mean(axis=0) - home_px)))
    pose = detection_pose(gray, det, solver)
    return (pose if pose.valid else None), others


def _judge(poses: list[MarkerPose], n_frames: int, forces: list[float], temps: list[float],
           others: set[int], home_m: FloatArray, rig: RigGeometry, lim: ZeroPoseLimits,
           require_force_ref: bool) -> ZeroPose:
    """The zero pose from the frames, or why the gripper was not at rest."""
    warmest = max(temps) if temps else math.nan
    if temps and warmest > lim.max_temp_c:
        raise GripperNotAtRestError(
            f"fingers at {warmest:.1f} °C, warmer than {lim.max_temp_c:g} °C: let them cool "
            "with the heaters off before the zero pose")
    max_force = max(forces) if forces else None
    if max_force is None and require_force_ref:
        raise GripperNotAtRestError(
            "no force-reference reading arrived, so an unloaded finger cannot be checked: "
            "make sure nothing touches the fingers and pass --no-force-ref")
    if max_force is not None and max_force > lim.max_force_n:
        raise GripperNotAtRestError(
            f"the force reference reads {max_force:.3f} N, over {lim.max_force_n:g} N: open the "
            "gripper and take the object out (or tare the force reference)")
    marker = rig.marker
    if len(poses) < lim.min_found * n_frames:
        seen = f" (the frames show id {', '.join(map(str, sorted(others)))})" if others else ""
        raise GripperNotAtRestError(
            f"marker DICT_{marker.dictionary} id {marker.marker_id} found on {len(poses)} of "
            f"{n_frames} frames{seen}: check the light, the camera's view and [marker] in the "
            "rig file")
    positions = np.array([p.tvec_m for p in poses])
    mean_t = positions.mean(axis=0)
    rot0 = mean_rotation([p.rotation for p in poses])
    spread_m = float(np.linalg.norm(positions - mean_t, axis=1).max())
    spread_rad = max(rotation_angle(p.rotation @ rot0.T) for p in poses)
    if spread_m * 1e3 > lim.max_spread_mm or math.degrees(spread_rad) > lim.max_spread_deg:
        raise GripperNotAtRestError(
            f"marker pose unstable over {len(poses)} frames: {spread_m * 1e3:.3f} mm and "
            f"{math.degrees(spread_rad):.3f}° from its mean (at most {lim.max_spread_mm:g} mm, "
            f"{lim.max_spread_deg:g}°): wait for the finger to settle, keep the bench still")
    rvec = np.asarray(cv2.Rodrigues(rot0)[0], dtype=np.float64).ravel()
    return ZeroPose(
        (float(mean_t[0]), float(mean_t[1]), float(mean_t[2])),
        (float(rvec[0]), float(rvec[1]), float(rvec[2])),
        len(poses), n_frames, spread_m, spread_rad, max_force, warmest,
        float(np.linalg.norm(mean_t - home_m)),
    )
