"""The ICFN feature vector: a named, versioned schema and its builder.

The paper's instantaneous contact force network (ICFN, §IV-B) reads "the
ArUco-based pose, squared marker translation, beam temperatures, and
engineered thermal features such as temperature statistics and spatial
gradients".  :data:`ICFN_SCHEMA` names every entry with its unit; models
store the schema's version and refuse features of another version.

Units are SI (m, rad) except temperatures (°C, and K for spreads and
gradients), as everywhere in relaxgrip.  A beam temperature outside the
infrared camera's view (or missing, for a rig that reads fewer beams) is
filled with its finger's mean: the beams of one finger differ by a few
kelvin at most.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.perception.marker import MarkerState
from relaxgrip.perception.thermal import ThermalFeatures

FloatArray = NDArray[np.float64]

__all__ = [
    "ICFN_SCHEMA",
    "N_BEAMS",
    "RCFN_SCHEMA",
    "FeatureSchema",
    "RcfnFeatures",
    "build_icfn_features",
    "finger_temperature_c",
    "marker_pose",
]

#: Beam temperatures read per finger (regions of interest along it).
N_BEAMS = 5
#: Marker deflection that counts as contact: twenty times the tracking noise (m).
_CONTACT_DEFLECTION_M = 2e-5
#: How much of the loading before a hold onset the RCFN features keep (s).
LOADING_HISTORY_S = 10.0


@dataclass(frozen=True)
class FeatureSchema:
    """Names, units and version of a feature vector.

    Attributes
    ----------
    version : str
        Changes whenever the meaning, order or units of any entry change.
    names : tuple of str
        Entry names, in vector order.
    units : tuple of str
        Unit of each entry.
    """

    version: str
    names: tuple[str, ...]
    units: tuple[str, ...]

    def __post_init__(self) -> None:
        if len(self.names) != len(self.units):
            raise ValueError("one unit per feature name")
        if len(set(self.names)) != len(self.names):
            raise ValueError("feature names must be unique")

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Position of a named entry."""
        return self.names.index(name)

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form, stored with datasets and models."""
        return {"version": self.version, "names": list(self.names), "units": list(self.units)}


def _icfn_schema() -> FeatureSchema:
    names: list[str] = []
    units: list[str] = []

    def add(name: str, unit: str) -> None:
        names.append(name)
        units.append(unit)

    for axis in "xyz":
        add(f"marker_d{axis}_m", "m")
    for axis in "xyz":
        add(f"marker_r{axis}_rad", "rad")
    for axis in "xyz":
        add(f"marker_d{axis}2_m2", "m^2")
    for j in (0, 1):
        for i in range(N_BEAMS):
            add(f"f{j}_beam{i}_c", "degC")
    for j in (0, 1):
        add(f"f{j}_temp_mean_c", "degC")
        add(f"f{j}_temp_max_c", "degC")
        add(f"f{j}_temp_min_c", "degC")
        add(f"f{j}_temp_std_k", "K")
        add(f"f{j}_grad_k_per_m", "K/m")
    return FeatureSchema("relaxgrip-icfn-features-v1", tuple(names), tuple(units))


#: The ICFN input: marker pose from the zero pose (camera frame), its squares,
#: five beam temperatures per finger, per-finger statistics and gradient.
ICFN_SCHEMA = _icfn_schema()


def build_icfn_features(marker: MarkerState, thermal: ThermalFeatures) -> FloatArray | None:
    """Assemble the ICFN feature vector in :data:`ICFN_SCHEMA` order.

    Parameters
    ----------
    marker : MarkerState
        The tracker's state for the current RGB frame.
    thermal : ThermalFeatures
        The latest infrared features (held between 1 Hz frames).

    Returns
    -------
    ndarray, shape (len(ICFN_SCHEMA),), or None
        ``None`` when there is no relative pose (marker lost or still
        zeroing) or a finger has no temperature at all in view.
    """
    if marker.delta_t_m is None or marker.delta_r_rad is None:
        return None
    # Plain floats, one conversion at the end: 29 numbers are cheaper in Python than
    # in a dozen small NumPy calls, and this runs on every frame.
    dx, dy, dz = marker.delta_t_m.tolist()
    values = [dx, dy, dz, *marker.delta_r_rad.tolist(), dx * dx, dy * dy, dz * dz]
    stats: list[float] = []
    for finger in thermal.fingers:
        mean = finger.mean_c
        if not math.isfinite(mean):
            return None
        beams = [b if math.isfinite(b) else mean for b in finger.beam_temps_c[:N_BEAMS]]
        values += beams + [mean] * (N_BEAMS - len(beams))
        gradient = finger.gradient_k_per_m if math.isfinite(finger.gradient_k_per_m) else 0.0
        stats += [mean, finger.max_c, finger.min_c, finger.std_k, gradient]
    return np.array(values + stats)


def _rcfn_schema() -> FeatureSchema:
    pose = [("dx", "m"), ("dy", "m"), ("dz", "m"), ("rx", "rad"), ("ry", "rad"), ("rz", "rad")]
    names = ["temp_c"]
    units = ["degC"]
    for prefix, suffix in (("onset_", ""), ("", ""), ("v", "_s")):
        for axis, unit in pose:
            names.append(f"{prefix}{axis}_{unit}{suffix}")
            units.append(f"{unit}/s" if suffix else unit)
    names += ["closure_ratio", "hold_time_s"]
    units += ["", "s"]
    # v4: temp_c weighs the beams by the finger's bending (FingerGeometry.bending_weights).
    return FeatureSchema("relaxgrip-rcfn-features-v4", tuple(names), tuple(units))


#: The RCFN input: the paper's (§IV-B) current finger temperature, marker pose at
#: contact onset, current marker pose and its velocity over the last second; and two
#: more.  ``closure_ratio``, the motor's closure per unit of marker deflection over
#: the last second of loading, tells a soft object from a stiff one (the fingers and
#: the object share the closure in inverse proportion to their stiffness): for a
#: soft object the marker's drift during the hold is then a calibrated measure of
#: the relaxation.  ``hold_time_s``, the time since the onset, tells how much of it
#: has happened yet.
RCFN_SCHEMA = _rcfn_schema()


def marker_pose(marker: MarkerState) -> FloatArray | None:
    """The relative pose as six numbers ``(dx, dy, dz, rx, ry, rz)`` (m, rad), if tracked."""
    if marker.delta_t_m is None or marker.delta_r_rad is None:
        return None
    return np.concatenate([marker.delta_t_m, marker.delta_r_rad])


def finger_temperature_c(thermal: ThermalFeatures) -> float:
    """Mean temperature of both fingers over the beams no object covers (°C); nan if none in view.

    See :func:`relaxgrip.perception.thermal.uncovered_mean_c`: the faces' mean
    read a 55 °C finger holding the room-temperature ball at 52.1 °C in a
    closed-loop hold and at 53.6 °C on average over the datasets' contact
    positions, a difference the relaxation models, steep near Tg, took for
    1.5 K of temperature.  Each beam weighs as the rig's finger bends there
    (``thermal.beam_weights``): the five beams alike read 0.8 K below the
    weighted mean 50 s into a 40 -> 55 °C ramp (the tip trails the heaters),
    against 0.1 K above it at rest, and the observer missed 0.14 N of the
    softening (docs/hold-experiments.md, session 45).
    """
    return thermal.finger_temperature_c


class RcfnFeatures:
    """Build RCFN features from a stream of poses and encoder readings.

    Keeps the onset pose, the loading that led to it and a short history.

    Parameters
    ----------
    velocity_window_s : float
        Pose velocity is the change over this window, divided by it (s).
    """

    def __init__(self, velocity_window_s: float = 1.0) -> None:
        if not velocity_window_s > 0:
            raise ValueError(f"velocity window must be > 0 s, got {velocity_window_s}")
        self.velocity_window_s = velocity_window_s
        self._history: deque[tuple[float, FloatArray, float]] = deque()
        self.onset_pose: FloatArray | None = None
        self.onset_t_s: float | None = None
        self.closure_ratio = math.nan

    def observe(self, t_s: float, pose: FloatArray, motor_position_mm: float) -> None:
        """Record a pose and the encoder (before or after the onset)."""
        if self._history and t_s <= self._history[-1][0]:
            return
        self._history.append((t_s, np.asarray(pose, dtype=np.float64), motor_position_mm))
        # Before the onset the loading is kept long enough for the closure ratio of a slow
        # approach; in the hold, two velocity windows suffice.
        keep_s = 2.0 * self.velocity_window_s if self.onset_t_s is not None else max(
            2.0 * self.velocity_window_s, LOADING_HISTORY_S)
        horizon = t_s - keep_s
        while len(self._history) > 2 and self._history[1][0] <= horizon:
            self._history.popleft()

    @property
    def last_pose(self) -> FloatArray | None:
        """The latest pose observed, if any."""
        return self._history[-1][1] if self._history else None

    def start(self, t_s: float, pose: FloatArray, motor_position_mm: float) -> None:
        """Mark the hold onset; the loading history before it gives the closure ratio."""
        self.observe(t_s, pose, motor_position_mm)
        self.onset_pose = np.asarray(pose, dtype=np.float64)
        self.onset_t_s = t_s
        self.closure_ratio = self._closure_ratio()

    def _closure_ratio(self) -> float:
        """Motor closure per marker deflection over the loading's last window.

        The span is the last velocity window (its earliest usable sample).  A
        loading that crept in at the end (a stiff object approached slowly)
        may bend the marker too little within it; the span then reaches back
        to the latest sample the marker has measurably bent since, within
        :data:`LOADING_HISTORY_S`.
        """
        t_now, now, motor_now = self._history[-1]
        ratio = math.nan  # no loading seen (a hold started from rest): unknown
        for t, pose, motor in itertools.islice(reversed(self._history), 1, None):
            if t < t_now - self.velocity_window_s and math.isfinite(ratio):
                break
            bent = now[0] - pose[0]
            in_contact = pose[0] > _CONTACT_DEFLECTION_M  # closure before contact would count
            if in_contact and bent > _CONTACT_DEFLECTION_M and motor_now > motor:
                ratio = (motor_now - motor) * 1e-3 / bent  # the earliest in the window wins
                if t < t_now - self.velocity_window_s:
                    break  # beyond the window: the first measurable bend is the span
        return ratio

    def velocity(self) -> FloatArray:
        """Pose change over the last window, per second (over what history there is)."""
        if len(self._history) < 2:
            return np.zeros(6)
        t_now, now, _ = self._history[-1]
        target = t_now - self.velocity_window_s
        t_then, then, _ = self._history[0]
        for t, pose, _ in itertools.islice(reversed(self._history), 1, None):
            if t <= target:
                t_then, then = t, pose
                break
        out: FloatArray = (now - then) / (t_now - t_then)
        return out

    def build(self, temp_c: float) -> FloatArray | None:
        """The feature vector in :data:`RCFN_SCHEMA` order; ``None`` before the onset."""
        if self.onset_pose is None or self.onset_t_s is None or not self._history:
            return None
        if not (math.isfinite(temp_c) and math.isfinite(self.closure_ratio)):
            return None
        t_now, pose, _ = self._history[-1]
        return np.concatenate([[temp_c], self.onset_pose, pose, self.velocity(),
                               [self.closure_ratio, t_now - self.onset_t_s]])
