"""Temperature-dependent stiffness characterization of the finger (paper Fig. "deform").

The paper clamps the finger, indents it with a UR5e at 2–8 N and 27–60 °C,
and measures the deformation profile ``z(x)``; from it the local stiffness
``k80 = F / z(80 mm)``, the global deformation ``A_z = int z dx`` and the local
stiffness at 8 N over contact position.  Here the same quantities come from
the twin's finger (uniform temperature, nominal material).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.physics.beam import (
    FingerParams,
    beam_grid,
    deflection_area_m2,
    deflection_profile_m,
    local_stiffness_n_per_m,
)
from relaxgrip.twin.config import TWIN_VERSION
from relaxgrip.validate import check_positive, check_temp_c

FloatArray = NDArray[np.float64]

__all__ = ["Characterization", "characterize"]

#: The paper's loads (N) and its temperature span (°C).
PAPER_LOADS_N = (2.0, 4.0, 6.0, 8.0)
PAPER_TEMPS_C = (27.0, 35.0, 40.0, 45.0, 50.0, 55.0, 60.0)


def _key(value: float) -> str:
    return f"{value:g}"


@dataclass(frozen=True)
class Characterization:
    """Deformation of the finger over load, temperature and contact position.

    Attributes
    ----------
    loads_n : ndarray, shape (L,)
        Normal loads (N).
    temps_c : ndarray, shape (T,)
        Uniform finger temperatures (°C); the first and last are the
        comparison pair (27 and 60 °C in the paper).
    x_m : ndarray, shape (X,)
        Positions along the finger (m).
    profiles_m : ndarray, shape (L, T, X)
        Deformation profiles ``z(x)`` with the load at ``contact_m`` (m).
    k80_n_per_m : ndarray, shape (L, T)
        ``F / z(80 mm)`` (N/m).
    z80_m : ndarray, shape (L, T)
        Deformation at 80 mm (m).
    area_m2 : ndarray, shape (L, T)
        ``A_z`` (m^2).
    positions_m : ndarray, shape (P,)
        Contact positions of the position sweep (m).
    local_stiffness_n_per_m : ndarray, shape (P, T)
        ``F / z(a)`` at ``position_load_n`` for a load at position ``a`` (N/m).
    contact_m, position_load_n : float
        Load position of the profiles (m) and load of the position sweep (N).
    twin_version : str
        Version of the twin.
    """

    loads_n: FloatArray
    temps_c: FloatArray
    x_m: FloatArray
    profiles_m: FloatArray
    k80_n_per_m: FloatArray
    z80_m: FloatArray
    area_m2: FloatArray
    positions_m: FloatArray
    local_stiffness_n_per_m: FloatArray
    contact_m: float
    position_load_n: float
    twin_version: str = TWIN_VERSION
    material: dict[str, Any] | None = None

    @property
    def k80_drop_pct(self) -> FloatArray:
        """Drop of ``k80`` from the first to the last temperature, per load (%)."""
        return 100.0 * (1.0 - self.k80_n_per_m[:, -1] / self.k80_n_per_m[:, 0])

    @property
    def z80_ratio(self) -> FloatArray:
        """``z80`` at the last over the first temperature, per load."""
        return self.z80_m[:, -1] / self.z80_m[:, 0]

    def area_at_mm2(self, load_n: float) -> FloatArray:
        """``A_z`` over temperature at one of the characterized loads (mm^2)."""
        idx = int(np.argmin(np.abs(self.loads_n - load_n)))
        if not np.isclose(self.loads_n[idx], load_n):
            raise ValueError(f"load {load_n} N was not characterized")
        out: FloatArray = self.area_m2[idx] * 1e6
        return out

    def to_dict(self) -> dict[str, Any]:
        """Summary as plain Python (the ``--json`` output of ``relaxgrip characterize``)."""
        loads = [_key(f) for f in self.loads_n]
        temps = [_key(t) for t in self.temps_c]
        biggest = float(self.loads_n[-1])
        area = self.area_at_mm2(biggest)
        return {
            "twin_version": self.twin_version,
            "material": self.material,
            "contact_mm": self.contact_m * 1e3,
            "temps_c": [float(t) for t in self.temps_c],
            "k80_drop_pct": dict(zip(loads, self.k80_drop_pct.tolist(), strict=True)),
            "z80_ratio": dict(zip(loads, self.z80_ratio.tolist(), strict=True)),
            f"area_{_key(biggest)}n_mm2": {temps[0]: float(area[0]), temps[-1]: float(area[-1])},
            "k80_n_per_mm": {
                load: dict(zip(temps, (row / 1e3).tolist(), strict=True))
                for load, row in zip(loads, self.k80_n_per_m, strict=True)
            },
            "z80_mm": {
                load: dict(zip(temps, (row * 1e3).tolist(), strict=True))
                for load, row in zip(loads, self.z80_m, strict=True)
            },
            "area_mm2": {
                load: dict(zip(temps, (row * 1e6).tolist(), strict=True))
                for load, row in zip(loads, self.area_m2, strict=True)
            },
        }


def characterize(
    finger: FingerParams | None = None,
    loads_n: tuple[float, ...] = PAPER_LOADS_N,
    temps_c: tuple[float, ...] = PAPER_TEMPS_C,
    contact_m: float = 0.080,
    positions_m: tuple[float, ...] | None = None,
    position_load_n: float = 8.0,
) -> Characterization:
    """Run the stiffness characterization on a finger.

    Parameters
    ----------
    finger : FingerParams, optional
        The finger (default: our gripper's; a rig's is its ``TwinConfig.finger``).
    loads_n : tuple of float
        Loads (N), > 0.
    temps_c : tuple of float
        Uniform temperatures (°C); drops and ratios compare the last to the first.
    contact_m : float
        Where the load acts for the profiles (m).
    positions_m : tuple of float, optional
        Contact positions of the local-stiffness sweep (m; default: 15 from
        40 mm to the tip).
    position_load_n : float
        Load of the position sweep (N).

    Returns
    -------
    Characterization
        Profiles, ``k80``, ``z80``, ``A_z`` and the position sweep.
    """
    finger = finger if finger is not None else FingerParams()
    if len(temps_c) < 2 or not loads_n:
        raise ValueError("need at least one load and two temperatures")
    for f in (*loads_n, position_load_n):
        check_positive(f, "load")
    for t in temps_c:
        check_temp_c(t, "characterization temperature")
    x = beam_grid(finger)
    loads = np.asarray(loads_n, dtype=np.float64)
    temps = np.asarray(temps_c, dtype=np.float64)
    profiles = np.array(
        [[deflection_profile_m(f, contact_m, t, finger) for t in temps] for f in loads]
    )
    z80 = np.array([[np.interp(0.080, x, p) for p in row] for row in profiles])
    area = np.array([[deflection_area_m2(f, t, finger, contact_m) for t in temps] for f in loads])
    positions = (np.linspace(0.04, finger.length_m, 15) if positions_m is None
                 else np.asarray(positions_m, dtype=np.float64))
    local = np.array(
        [
            [
                local_stiffness_n_per_m(position_load_n, t, finger, contact_m=a, at_m=a)
                for t in temps
            ]
            for a in positions
        ]
    )
    return Characterization(
        loads_n=loads,
        temps_c=temps,
        x_m=x,
        profiles_m=profiles,
        k80_n_per_m=loads[:, None] / z80,
        z80_m=z80,
        area_m2=area,
        positions_m=positions,
        local_stiffness_n_per_m=local,
        contact_m=contact_m,
        position_load_n=position_load_n,
        material=None if finger.smp.material is None else finger.smp.material.material.provenance,
    )
