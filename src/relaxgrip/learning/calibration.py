"""The ``observer``'s calibration against a force reference: a few coefficients and a band.

Beyond the paper.  Eq. 10's estimate errs, run after run, by what the ICFN
misreads at the onset and what the RCFN misses of the relaxation.  Part of
that error is systematic for a gripper and its models, and a lab with a
force reference (a load cell in the object) can measure it in a few
regulated holds.  The calibration models the estimate's error as

``e(t) = c0 + c1 F_inst + c2 R(t)``,  ``R(t) = K (1 - exp(-t / tau))``

(Eq. 10's relaxation so far, which carries the temperature's effect): three
coefficients fitted by least squares to ``estimate - force_ref`` over the
hold frames of up to a dozen holds (:func:`fit_calibration`), and the
``observer`` takes ``e(t)`` off its estimate.

The 95 % band is split-conformal over holds.  Each hold's residuals are
computed with the coefficients fitted on the other holds (cross-fitting,
so every residual is out of sample, as a new hold's is), and the hold's score
is the :data:`COVERAGE` quantile of ``|residual| / (1 N + F_inst)`` over its
steady window.  With ``n`` holds exchangeable with a new one, the ``k``-th
smallest score, ``k = ceil((n + 1) / 2)``, covers a new hold's force for at
least :data:`COVERAGE` of its steady window with probability at least
``k / (n + 1) >= 1/2`` whatever the error's distribution (exactly for scores
computed alike; the new hold's coefficients are fitted on all ``n`` holds, not
``n - 1``).  The band is the median hold's 95 % band: twelve holds are too few
to promise 95 % of the holds their 95 % band, which takes 19 or more.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.errors import InputError

__all__ = [
    "BASIS",
    "CALIBRATION_VERSION",
    "COVERAGE",
    "MIN_HOLDS",
    "Calibration",
    "CalibrationHold",
    "error_basis",
    "fit_calibration",
]

FloatArray = NDArray[np.float64]

#: Written with every calibration; a calibration of another version is refused.
CALIBRATION_VERSION = "relaxgrip-calibration-v1"
#: The terms of the error model, in coefficient order.
BASIS = ("offset_n", "f_inst", "relaxed")
#: Share of a hold's steady window the band covers.
COVERAGE = 0.95
#: The band's half-width is ``band_rel (BAND_FLOOR_N + F_inst)``.
BAND_FLOOR_N = 1.0
#: Fewest holds a calibration takes: the coefficients fitted without each hold need a few
#: holds, and the band's median rank a few scores.
MIN_HOLDS = 4
#: Frames before this far into the hold are not fitted (s): the onset's own transient.
FIT_FROM_S = 5.0


def error_basis(f_onset_n: float, relaxed_n: ArrayLike) -> FloatArray:
    """The error model's terms (:data:`BASIS`) at each frame, shape ``(n, 3)``."""
    relaxed = np.atleast_1d(np.asarray(relaxed_n, dtype=np.float64))
    return np.column_stack([np.ones_like(relaxed), np.full_like(relaxed, f_onset_n), relaxed])


@dataclass(frozen=True)
class CalibrationHold:
    """One regulated hold's frames, as the calibration reads them.

    Attributes
    ----------
    name : str
        What the hold was (a seed and condition, or a recording's path).
    hold_s : ndarray
        Time since the hold onset of each frame (s).
    estimate_n : ndarray
        The uncalibrated estimate (N).
    f_onset_n : float
        The estimator's ``F_inst`` (N).
    relaxed_n : ndarray
        Eq. 10's relaxation so far, ``K (1 - exp(-t / tau))`` (N).
    force_ref_n : ndarray
        The force reference's reading (N; nan in frames without one).
    window_s : tuple of float
        The steady window the band is scored over (s since the onset).
    """

    name: str
    hold_s: FloatArray
    estimate_n: FloatArray
    f_onset_n: float
    relaxed_n: FloatArray
    force_ref_n: FloatArray
    window_s: tuple[float, float]

    def _usable(self) -> NDArray[np.bool_]:
        return (np.isfinite(self.estimate_n) & np.isfinite(self.force_ref_n)
                & np.isfinite(self.relaxed_n))

    def fit_rows(self) -> tuple[FloatArray, FloatArray]:
        """Basis and error of the frames the coefficients are fitted on."""
        keep = self._usable() & (self.hold_s >= FIT_FROM_S)
        return (error_basis(self.f_onset_n, self.relaxed_n[keep]),
                self.estimate_n[keep] - self.force_ref_n[keep])

    def score(self, coef: FloatArray) -> float:
        """The :data:`COVERAGE` quantile of the relative calibrated residual over the
        steady window (nan without a usable frame there)."""
        lo, hi = self.window_s
        keep = self._usable() & (self.hold_s >= lo) & (self.hold_s <= hi)
        if not keep.any():
            return math.nan
        basis = error_basis(self.f_onset_n, self.relaxed_n[keep])
        residual = self.estimate_n[keep] - basis @ coef - self.force_ref_n[keep]
        return float(np.quantile(np.abs(residual), COVERAGE)) / (BAND_FLOOR_N + self.f_onset_n)


@dataclass(frozen=True)
class Calibration:
    """Fitted error coefficients and the band's scale.

    Attributes
    ----------
    coef : tuple of float
        Coefficients of :data:`BASIS` (N, 1, 1).
    band_rel : float
        The band's half-width per ``BAND_FLOOR_N + F_inst`` (dimensionless).
    record : dict
        How it was measured: the holds, their scores, the command.
    """

    coef: tuple[float, ...]
    band_rel: float
    record: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if len(self.coef) != len(BASIS) or not all(math.isfinite(c) for c in self.coef):
            raise InputError(f"a calibration has {len(BASIS)} finite coefficients, "
                             f"got {list(self.coef)}")
        if not (math.isfinite(self.band_rel) and self.band_rel >= 0):
            raise InputError(f"a calibration's band scale must be finite and >= 0, "
                             f"got {self.band_rel}")

    def error_n(self, f_onset_n: float, relaxed_n: float) -> float:
        """The modelled error of the uncalibrated estimate now (N)."""
        c0, c1, c2 = self.coef
        return c0 + c1 * f_onset_n + c2 * relaxed_n

    def half_width_n(self, f_onset_n: float) -> float:
        """The 95 % band's half-width for a hold with this ``F_inst`` (N)."""
        return self.band_rel * (BAND_FLOOR_N + max(f_onset_n, 0.0))

    def to_dict(self) -> dict[str, Any]:
        """The manifest's ``calibration`` section."""
        return {"version": CALIBRATION_VERSION, "basis": list(BASIS),
                "coef": list(self.coef), "band_rel": self.band_rel, "record": self.record}

    @classmethod
    def from_dict(cls, section: Mapping[str, Any]) -> Calibration:
        """Rebuild from :meth:`to_dict`; InputError naming what is wrong."""
        if not isinstance(section, Mapping):
            raise InputError("the calibration section is not an object")
        version = section.get("version")
        if version != CALIBRATION_VERSION:
            raise InputError(f"calibration {version!r} is not {CALIBRATION_VERSION}: "
                             "recalibrate with relaxgrip calibrate")
        if section.get("basis") != list(BASIS):
            raise InputError(f"calibration basis {section.get('basis')!r} is not {list(BASIS)}")
        try:
            coef = tuple(float(c) for c in section["coef"])
            band = float(section["band_rel"])
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"calibration lacks numeric 'coef' or 'band_rel' ({exc})") from None
        record = section.get("record", {})
        return cls(coef, band, dict(record) if isinstance(record, Mapping) else {})


def _lstsq(rows: Sequence[tuple[FloatArray, FloatArray]]) -> FloatArray:
    basis = np.vstack([b for b, _ in rows])
    error = np.concatenate([e for _, e in rows])
    coef, *_ = np.linalg.lstsq(basis, error, rcond=None)
    result: FloatArray = coef
    return result


def fit_calibration(holds: Sequence[CalibrationHold],
                    record: Mapping[str, Any] | None = None) -> Calibration:
    """Fit the error coefficients on every hold and the band on cross-fitted residuals.

    Raises
    ------
    InputError
        Fewer than :data:`MIN_HOLDS` holds, or a hold without force reference
        readings to fit or score.
    """
    if len(holds) < MIN_HOLDS:
        raise InputError(f"{len(holds)} hold(s): a calibration needs at least {MIN_HOLDS}")
    rows = [hold.fit_rows() for hold in holds]
    for hold, (_, error) in zip(holds, rows, strict=True):
        if error.size < len(BASIS):
            raise InputError(f"{hold.name}: {error.size} frames with a force reference "
                             f"reading after {FIT_FROM_S:g} s of the hold: nothing to fit")
    coef = _lstsq(rows)
    scores = []
    for i, hold in enumerate(holds):
        score = hold.score(_lstsq(rows[:i] + rows[i + 1:]))
        if math.isnan(score):
            raise InputError(f"{hold.name}: no force reference reading in its steady window "
                             f"{hold.window_s[0]:g}-{hold.window_s[1]:g} s")
        scores.append(score)
    rank = math.ceil((len(holds) + 1) / 2)
    band = float(np.sort(scores)[rank - 1])
    out = {**(record or {}), "holds": [h.name for h in holds], "scores": scores,
           "band_rank": rank, "coverage": COVERAGE}
    return Calibration(tuple(float(c) for c in coef), band, out)
