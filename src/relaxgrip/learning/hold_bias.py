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

What is left from run to run is mostly the marker finger's own relaxing
share, which the twin draws per run and Eq. 10 does not see; the per-frame
ICFN reads it, as its drift since the hold's first seconds (on twin v7,
5 N: correlation 0.98 at 40 °C and 0.92 at 55 °C with that share over seeds
0-23; ``relaxgrip budget``).  :class:`IcfnDrift` is the line the calibration
holds fit through their steady-state error against that drift, per onset
force and temperature: read once, at the steady state's start
(:func:`drift_windows`), and taken off from then on, it is causal.
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

__all__ = ["DRIFT_EARLY_S", "DRIFT_LATE_S", "MIN_DRIFT_WINDOW_S", "HoldBias", "IcfnDrift",
           "drift_windows"]

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


def _bilinear(values: list[list[float]], forces: tuple[float, ...], temps: tuple[float, ...],
              force_n: float, temp_c: float) -> float:
    """``values`` on the force × temperature knots at one point, faded beyond them."""
    fade = _inside(forces, force_n) * _inside(temps, temp_c)
    if fade == 0.0:
        return 0.0
    fi = _weights(forces, force_n)
    ti = _weights(temps, temp_c)
    total = 0.0
    for a, wa in ((fi[0], 1.0 - fi[2]), (fi[1], fi[2])):
        for b, wb in ((ti[0], 1.0 - ti[2]), (ti[1], ti[2])):
            if wa * wb:
                total += wa * wb * values[a][b]
    return fade * total


#: The ICFN's drift, in a hold of 280 s or longer: its per-frame mean over the
#: :data:`DRIFT_LATE_S` before the read time less its mean over :data:`DRIFT_EARLY_S`
#: after the onset (s).  A shorter hold's windows shrink with it, to no less than
#: :data:`MIN_DRIFT_WINDOW_S` (three frames at the camera's 30 Hz).
DRIFT_EARLY_S = (1.0, 4.0)
DRIFT_LATE_S = 5.0
MIN_DRIFT_WINDOW_S = 0.1

#: The largest drift slope a table may hold (N of error per N of drift): the
#: marker finger is one of two, so a run's error is about half its extra drift.
MAX_DRIFT_SLOPE = 2.0


def drift_windows(read_s: float, scale: float = 1.0
                  ) -> tuple[tuple[float, float], tuple[float, float]]:
    """The early and late windows of the ICFN's drift read at ``read_s`` (s since the onset).

    ``scale`` is the hold's length over 280 s (at most 1): a 14 s hold
    (scale 0.05, read at 5 s) takes 0.05-0.2 s and 4.75-5 s.
    """
    early_lo = DRIFT_EARLY_S[0] * scale
    early = (early_lo, max(DRIFT_EARLY_S[1] * scale, early_lo + MIN_DRIFT_WINDOW_S))
    late = (read_s - max(DRIFT_LATE_S * scale, MIN_DRIFT_WINDOW_S), read_s)
    return early, late


@dataclass(frozen=True, eq=False)
class IcfnDrift:
    """A line in the ICFN's drift for what the calibration's mean leaves (N per N).

    From the end of :attr:`late_s` on, the estimator takes off
    ``slope · (drift − mean_n)`` at its onset force and temperature, the
    drift being its own per-frame ICFN's mean over :attr:`late_s` less that
    over :attr:`early_s`: a run whose marker finger relaxes more than the
    calibration holds' did reads a larger drift, and Eq. 10 under-reads it.

    Attributes
    ----------
    forces_n, temps_c : ndarray
        The grid, as :class:`HoldBias`'s (N, °C).
    early_s, late_s : tuple of float
        The drift's windows since the onset (s); the correction starts at
        the end of ``late_s``.
    mean_n : ndarray, shape (forces, temps)
        The calibration holds' mean drift (N).
    slope : ndarray, shape (forces, temps)
        The steady state's mean estimate error per N of drift above that mean.
    """

    forces_n: FloatArray
    temps_c: FloatArray
    early_s: tuple[float, float]
    late_s: tuple[float, float]
    mean_n: FloatArray
    slope: FloatArray
    _knots: tuple[tuple[float, ...], tuple[float, ...]] = field(
        init=False, repr=False, compare=False)
    _tables: tuple[list[list[float]], list[list[float]]] = field(
        init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        forces = _axis(self.forces_n, "icfn_drift forces_n")
        temps = _axis(self.temps_c, "icfn_drift temps_c")
        windows = []
        for name, window in (("early_s", self.early_s), ("late_s", self.late_s)):
            try:
                lo, hi = (float(v) for v in window)
            except (TypeError, ValueError):
                raise InputError(f"hold bias: icfn_drift {name} must be two numbers") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
                raise InputError(f"hold bias: icfn_drift {name} must be a window 0 <= from < "
                                 f"to (s), got {[lo, hi]}")
            windows.append((lo, hi))
        if windows[1][0] < windows[0][1]:
            raise InputError(f"hold bias: icfn_drift's late window {list(windows[1])} starts "
                             f"before its early one {list(windows[0])} ends")
        tables = []
        for name in ("mean_n", "slope"):
            table = np.asarray(getattr(self, name), dtype=np.float64)
            if table.shape != (forces.size, temps.size):
                raise InputError(f"hold bias: icfn_drift {name} must have shape "
                                 f"{(forces.size, temps.size)}, got {table.shape}")
            if not np.all(np.isfinite(table)):
                raise InputError(f"hold bias: icfn_drift {name} has a value that is not finite")
            object.__setattr__(self, name, table)
            tables.append(table.tolist())
        if np.abs(self.slope).max() > MAX_DRIFT_SLOPE:
            raise InputError(f"hold bias: icfn_drift slope has {np.abs(self.slope).max():g}, "
                             f"beyond ±{MAX_DRIFT_SLOPE:g} N per N of drift")
        object.__setattr__(self, "forces_n", forces)
        object.__setattr__(self, "temps_c", temps)
        object.__setattr__(self, "early_s", windows[0])
        object.__setattr__(self, "late_s", windows[1])
        object.__setattr__(self, "_knots", (tuple(forces.tolist()), tuple(temps.tolist())))
        object.__setattr__(self, "_tables", (tables[0], tables[1]))

    def at(self, force_n: float, temp_c: float, drift_n: float) -> float:
        """The correction for a run that read ``drift_n`` at this onset force and temperature (N).

        Linear between knots, fading beyond them as :meth:`HoldBias.at`; 0
        when an argument is not finite.
        """
        if not (math.isfinite(force_n) and math.isfinite(temp_c) and math.isfinite(drift_n)):
            return 0.0
        forces, temps = self._knots
        mean_table, slope_table = self._tables
        slope = _bilinear(slope_table, forces, temps, force_n, temp_c)
        if slope == 0.0:
            return 0.0
        # The mean unfaded: beyond the grid the slope fades, the drift's reference does not.
        mean = _bilinear(mean_table, forces, temps, min(max(force_n, forces[0]), forces[-1]),
                         min(max(temp_c, temps[0]), temps[-1]))
        return slope * (drift_n - mean)

    def to_dict(self) -> dict[str, Any]:
        """The manifest's form (plain lists)."""
        return {"forces_n": self.forces_n.tolist(), "temps_c": self.temps_c.tolist(),
                "early_s": list(self.early_s), "late_s": list(self.late_s),
                "mean_n": self.mean_n.tolist(), "slope": self.slope.tolist()}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any]) -> IcfnDrift:
        """Read :meth:`to_dict`'s form.

        Raises
        ------
        InputError
            A key missing, or values that are not numbers of the right shapes.
        """
        keys = ("forces_n", "temps_c", "early_s", "late_s", "mean_n", "slope")
        if not isinstance(entry, Mapping):
            raise InputError("hold bias: icfn_drift must be an object")
        missing = [k for k in keys if k not in entry]
        if missing:
            raise InputError(f"hold bias: icfn_drift lacks {', '.join(missing)}")
        try:
            arrays = {k: np.asarray(entry[k], dtype=np.float64) for k in keys}
        except (TypeError, ValueError):
            raise InputError("hold bias: icfn_drift's values must be numbers") from None
        for name in ("early_s", "late_s"):
            if arrays[name].shape != (2,):
                raise InputError(f"hold bias: icfn_drift {name} must be two numbers")
        early = (float(arrays["early_s"][0]), float(arrays["early_s"][1]))
        late = (float(arrays["late_s"][0]), float(arrays["late_s"][1]))
        return cls(arrays["forces_n"], arrays["temps_c"], early, late, arrays["mean_n"],
                   arrays["slope"])


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
    drift : IcfnDrift, optional
        What is left of each run's error, read from its ICFN's drift; None
        when the calibration did not measure it (one before it did, or one
        on holds without the per-frame ICFN).
    """

    forces_n: FloatArray
    temps_c: FloatArray
    times_s: FloatArray
    values_n: FloatArray
    drift: IcfnDrift | None = None
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
        out: dict[str, Any] = {
            "forces_n": self.forces_n.tolist(), "temps_c": self.temps_c.tolist(),
            "times_s": self.times_s.tolist(), "values_n": self.values_n.tolist()}
        if self.drift is not None:
            out["icfn_drift"] = self.drift.to_dict()
        return out

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any]) -> HoldBias:
        """Read :meth:`to_dict`'s form (``icfn_drift`` optional).

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
        drift = entry.get("icfn_drift")
        return cls(axes[0], axes[1], axes[2], values,
                   None if drift is None else IcfnDrift.from_dict(drift))
