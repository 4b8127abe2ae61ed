"""An estimator's closed-loop error, calibrated on holds against the force ball.

The ICFN and the RCFN are trained frame by frame and on holds at a fixed
aperture; in a closed-loop hold, ``relax``'s estimate carries an error of
its own: the ICFN's reading at the onset, Eq. 10's relaxation after the
controller's loading, and the closure the controller adds (``relaxgrip
budget`` splits it).  Most of it is the same from run to run at a given
force and temperature, and it changes with both irregularly (on the twin,
5 N: −0.02 N at 30 °C, +0.05 N at 40 °C, −0.02 N at 48 °C; 40 °C: +0.02,
−0.05, +0.05 and −0.20 N at 1, 3, 5 and 8 N), so it is measured where it
is used, not modelled.

:class:`HoldBias` is that measurement: the mean of estimate − true force
over calibration holds on a grid of onset forces, finger temperatures and
times since the onset (smoothed over force and temperature by
:func:`relaxgrip.experiments.hold_calibration.smooth_bias`), interpolated
linearly between the grid's knots (time on a log scale), fading to none
beyond its forces and temperatures.  The estimator takes
it off its estimate (:class:`relaxgrip.control.estimators.RelaxEstimator`),
so the controller holds the force the calibration holds measured, not the
force the estimate read.  ``relaxgrip calibrate-hold`` measures it
(:mod:`relaxgrip.experiments.hold_calibration`) and stores it in the model
directory's manifest (:func:`relaxgrip.learning.store.set_hold_bias`).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError

__all__ = ["HoldBias"]

FloatArray = NDArray[np.float64]


# The knots as tuples of floats: the estimator looks the table up every frame, and
# numpy's per-call cost is most of a lookup this small.


def _weights(knots: tuple[float, ...], x: float) -> tuple[int, int, float]:
    """The two knots around ``x`` and the second one's weight, held at the ends."""
    if len(knots) == 1 or x <= knots[0]:
        return 0, 0, 0.0
    if x >= knots[-1]:
        last = len(knots) - 1
        return last, last, 0.0
    hi = bisect.bisect_right(knots, x)
    lo = hi - 1
    return lo, hi, (x - knots[lo]) / (knots[hi] - knots[lo])


def _inside(knots: tuple[float, ...], x: float) -> float:
    """1 within the knots, falling linearly to 0 one end spacing beyond them.

    Nothing was measured there: the calibration fades to none rather than
    carrying its edge on (a single knot is a constant everywhere).
    """
    if len(knots) == 1:
        return 1.0
    if x < knots[0]:
        return max(0.0, 1.0 - (knots[0] - x) / (knots[1] - knots[0]))
    if x > knots[-1]:
        return max(0.0, 1.0 - (x - knots[-1]) / (knots[-1] - knots[-2]))
    return 1.0


def _axis(values: Sequence[float] | FloatArray, name: str) -> FloatArray:
    out = np.asarray(values, dtype=np.float64)
    if out.ndim != 1 or out.size == 0:
        raise InputError(f"hold bias: {name} must be a non-empty list of numbers")
    if not np.all(np.isfinite(out)):
        raise InputError(f"hold bias: {name} has a value that is not finite")
    if np.any(np.diff(out) <= 0):
        raise InputError(f"hold bias: {name} must be strictly increasing, got {out.tolist()}")
    return out


@dataclass(frozen=True, eq=False)
class HoldBias:
    """Mean estimate − true force (N) of closed-loop holds on a grid.

    Attributes
    ----------
    forces_n : ndarray
        Onset forces of the grid (N): the estimator's ``F_inst``, strictly increasing.
    temps_c : ndarray
        Finger temperatures of the grid (°C): the estimator's own reading
        (the mean of both fingers' uncovered beams), strictly increasing.
    times_s : ndarray
        Times since the hold onset (s), strictly increasing and positive;
        interpolated on ``log(1 + t)``.
    values_n : ndarray, shape (forces, temps, times)
        The mean estimate error at each knot (N).
    """

    forces_n: FloatArray
    temps_c: FloatArray
    times_s: FloatArray
    values_n: FloatArray
    _knots: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]] = field(
        init=False, repr=False, compare=False)
    _values: list[list[list[float]]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        forces = _axis(self.forces_n, "forces_n")
        temps = _axis(self.temps_c, "temps_c")
        times = _axis(self.times_s, "times_s")
        if times[0] < 0:
            raise InputError(f"hold bias: times_s must be >= 0 s, got {times.tolist()}")
        values = np.asarray(self.values_n, dtype=np.float64)
        shape = (forces.size, temps.size, times.size)
        if values.shape != shape:
            raise InputError(f"hold bias: values_n must have shape {shape}, got {values.shape}")
        if not np.all(np.isfinite(values)):
            raise InputError("hold bias: values_n has a value that is not finite")
        largest, strongest = float(np.abs(values).max()), float(np.abs(forces).max())
        if largest > strongest:  # a correction is a share of the force
            raise InputError(f"hold bias: values_n has {largest:g} N, more than any force of "
                             f"the grid ({strongest:g} N)")
        object.__setattr__(self, "forces_n", forces)
        object.__setattr__(self, "temps_c", temps)
        object.__setattr__(self, "times_s", times)
        object.__setattr__(self, "values_n", values)
        object.__setattr__(self, "_knots", (tuple(forces.tolist()), tuple(temps.tolist()),
                                            tuple(np.log1p(times).tolist())))
        object.__setattr__(self, "_values", values.tolist())

    def at(self, force_n: float, temp_c: float, hold_s: float) -> float:
        """The calibrated error at this onset force, temperature and hold time (N).

        Linear between knots.  Beyond the grid's forces and temperatures it
        falls linearly to 0 over one end spacing (none was measured there);
        before the first and after the last time it is held.  0 when an
        argument is not finite (no onset force yet, no temperature seen).
        """
        if not (math.isfinite(force_n) and math.isfinite(temp_c) and math.isfinite(hold_s)):
            return 0.0
        forces, temps, log_times = self._knots
        fade = _inside(forces, force_n) * _inside(temps, temp_c)
        if fade == 0.0:
            return 0.0
        fi = _weights(forces, force_n)
        ti = _weights(temps, temp_c)
        hi = _weights(log_times, math.log1p(max(hold_s, 0.0)))
        total = 0.0
        for a, wa in ((fi[0], 1.0 - fi[2]), (fi[1], fi[2])):
            for b, wb in ((ti[0], 1.0 - ti[2]), (ti[1], ti[2])):
                for c, wc in ((hi[0], 1.0 - hi[2]), (hi[1], hi[2])):
                    w = wa * wb * wc
                    if w:
                        total += w * self._values[a][b][c]
        return fade * total

    def to_dict(self) -> dict[str, Any]:
        """The manifest's form (plain lists)."""
        return {"forces_n": self.forces_n.tolist(), "temps_c": self.temps_c.tolist(),
                "times_s": self.times_s.tolist(), "values_n": self.values_n.tolist()}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any]) -> HoldBias:
        """Read :meth:`to_dict`'s form.

        Raises
        ------
        InputError
            A key missing, or values that are not a grid of finite numbers.
        """
        missing = [k for k in ("forces_n", "temps_c", "times_s", "values_n") if k not in entry]
        if missing:
            raise InputError(f"hold bias: missing {', '.join(missing)}")
        try:
            values = np.asarray(entry["values_n"], dtype=np.float64)
            axes = [np.asarray(entry[k], dtype=np.float64)
                    for k in ("forces_n", "temps_c", "times_s")]
        except (TypeError, ValueError):
            raise InputError("hold bias: the grid and its values must be numbers") from None
        return cls(axes[0], axes[1], axes[2], values)
