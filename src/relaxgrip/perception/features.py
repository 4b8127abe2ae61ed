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

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.perception.marker import MarkerState
from relaxgrip.perception.thermal import ThermalFeatures

FloatArray = NDArray[np.float64]

__all__ = ["ICFN_SCHEMA", "N_BEAMS", "FeatureSchema", "build_icfn_features"]

#: Beam temperatures read per finger (regions of interest along it).
N_BEAMS = 5


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
