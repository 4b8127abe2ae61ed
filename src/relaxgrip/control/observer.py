"""The ``observer`` force estimator: Eq. 10 with the parts an ablation keeps.

Beyond the paper.  The ``observer`` is ``relax`` (Eq. 10,
:class:`~relaxgrip.control.estimators.RelaxEstimator`) with these parts, each
of which can be switched off (:data:`PARTS`) and each kept only because the
ablation (``relaxgrip ablation``, :mod:`relaxgrip.experiments.ablation`) shows
it lowers the MAE by more than the 95 % interval of the difference on fresh
seeds (docs/method.md):

* ``tare``: the ICFN's reading at rest, measured over the second before
  contact, is taken off every later reading when it is clearly off zero
  (:class:`~relaxgrip.control.estimators.IcfnEstimator`).
* ``loading``: ``F_inst`` averages the ICFN over the last second of the
  loading as well as the hold's first moments, each loading reading carried to
  the onset's motor position along the closure stiffness (the ICFN's rise per
  millimetre of motor travel over the upper half of the loading).
* ``closure``: the RCFN was trained on holds at a fixed aperture, so Eq. 10
  predicts the force had the motor stayed at the onset; the closure the
  controller adds since adds force through the stiffness of the closed chain
  (finger - object - finger), ``s_close (m(t) - m_onset)`` (the onset step of
  Eq. 6 and the controller's later steps superposed), and the RCFN is shown
  the pose the fixed-aperture hold would have had (the pose change per
  millimetre of closure, measured on the loading, taken out).
* ``calibration``: the model directory's calibration against a force
  reference (:mod:`relaxgrip.learning.calibration`, ``relaxgrip calibrate``)
  is taken off the estimate, and gives the 95 % band.

So ``F(t) = F_inst - K (1 - exp(-t / tau)) + s_close (m(t) - m_onset) - e(t)``.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.control.estimators import ForceEstimate, IcfnEstimator
from relaxgrip.learning.calibration import Calibration
from relaxgrip.learning.icfn import ICFN
from relaxgrip.learning.rcfn import RCFN
from relaxgrip.perception.features import RcfnFeatures, finger_temperature_c, marker_pose
from relaxgrip.perception.pipeline import Percept

__all__ = ["PARTS", "ObserverEstimator", "travel_slope"]

NAN = math.nan
FloatArray = NDArray[np.float64]
#: The parts of the observer beyond Eq. 10, each of which the ablation removes in turn.
PARTS = ("tare", "loading", "closure", "calibration")
#: How long the ICFN's reading at rest is measured before contact (s).
TARE_WINDOW_S = 1.0
#: The closure slopes are measured where the loading estimate is above this share of its end.
SLOPE_FORCE_SHARE = 0.5


class ObserverEstimator:
    """Eq. 10 with a tare, the loading's onset force, the added closure and a calibration.

    Parameters
    ----------
    icfn, rcfn : ICFN, RCFN
        The fitted networks, as for ``relax``.
    calibration : Calibration, optional
        The model directory's calibration (the ``calibration`` part; without
        it the estimate is uncalibrated and has no band).
    without : iterable of str
        Parts of :data:`PARTS` to leave out (the ablation's variants).
    onset_window_s, onset_before_s : float
        ``F_inst`` averages the ICFN over this much of the hold's start and,
        with ``loading``, of the loading before it (s).
    stiffness_window_s : float
        Loading window over which the closure slopes are measured (s).
    smoothing_s : float
        Low-pass time constant of the ICFN estimate before the hold (s).
    """

    name = "observer"
    regulates_hold = True

    def __init__(self, icfn: ICFN, rcfn: RCFN, calibration: Calibration | None = None,
                 without: Iterable[str] = (), onset_window_s: float = 0.6,
                 onset_before_s: float = 1.0, stiffness_window_s: float = 4.0,
                 smoothing_s: float = 0.2) -> None:
        left_out = frozenset(without)
        unknown = left_out - set(PARTS)
        if unknown:
            raise ValueError(f"unknown observer part(s) {sorted(unknown)}; parts: {PARTS}")
        if not (onset_window_s > 0 and onset_before_s >= 0 and stiffness_window_s > 0):
            raise ValueError("the onset window and the stiffness window must be > 0 s and the "
                             f"loading window >= 0 s, got {onset_window_s}, "
                             f"{stiffness_window_s} and {onset_before_s} s")
        self.parts = tuple(p for p in PARTS if p not in left_out)
        self.icfn = IcfnEstimator(icfn, smoothing_s,
                                  TARE_WINDOW_S if "tare" in self.parts else 0.0)
        self.rcfn = rcfn
        self.calibration = calibration if "calibration" in self.parts else None
        self.onset_window_s = onset_window_s
        self.onset_before_s = onset_before_s if "loading" in self.parts else 0.0
        self.stiffness_window_s = stiffness_window_s
        self.provenance: dict[str, Any] = {}
        self.reset()

    def reset(self) -> None:
        """Forget the grasp."""
        self.icfn.reset()
        self.features = RcfnFeatures()
        self._loading: deque[tuple[float, float, float, FloatArray]] = deque()
        self._pose_per_mm: FloatArray = np.zeros(6)
        self.closure_stiffness_n_per_mm = 0.0
        self._onset_t: float | None = None
        self._onset_motor = NAN
        self._onset_sum, self._onset_n = 0.0, 0
        self.f_onset_n = NAN
        self._k = self._tau = NAN

    def update(self, percept: Percept, motor_position_mm: float) -> ForceEstimate:
        """The smoothed ICFN before the hold; Eq. 10 with the observer's parts during it."""
        raw = self.icfn.instantaneous(percept)
        f = self.icfn.smoothed(raw, percept.t_s)
        t = percept.t_s
        pose = marker_pose(percept.marker)
        if self._onset_t is None:
            if pose is not None:
                self.features.observe(t, pose)
                if math.isfinite(raw):
                    self._loading.append((t, motor_position_mm, raw, pose))
                    while self._loading[0][0] < t - self.stiffness_window_s:
                        self._loading.popleft()
            return ForceEstimate(f, raw)
        closure_mm = motor_position_mm - self._onset_motor
        if pose is not None:
            self.features.observe(t, pose - self._pose_per_mm * closure_mm)
        hold = t - self._onset_t
        added = self.closure_stiffness_n_per_mm * closure_mm
        if hold <= self.onset_window_s and math.isfinite(raw):
            self._onset_sum += raw - added
            self._onset_n += 1
            self.f_onset_n = self._onset_sum / self._onset_n
        if not math.isfinite(self.f_onset_n):
            return ForceEstimate(NAN, raw, hold_s=hold)
        if percept.thermal is not None:
            x = self.features.build(finger_temperature_c(percept.thermal))
            if x is not None:
                self._k, self._tau = self.rcfn.relaxation(x)
        if not math.isfinite(self._k):
            return ForceEstimate(NAN, raw, self.f_onset_n, hold_s=hold)
        relaxed = self._k * -math.expm1(-hold / self._tau)
        force = self.f_onset_n - relaxed + added  # Eq. 10 and the added closure
        if self.calibration is None:
            return ForceEstimate(force, raw, self.f_onset_n, self._k, self._tau, hold)
        error = self.calibration.error_n(self.f_onset_n, relaxed)
        force -= error
        half = self.calibration.half_width_n(self.f_onset_n)
        return ForceEstimate(force, raw, self.f_onset_n, self._k, self._tau, hold,
                             force - half, force + half, error)

    def contact(self, t_s: float) -> float:
        """Tare the ICFN on the free-space frames before the contact (returns the tare, N)."""
        return self.icfn.contact(t_s)

    def start_hold(self, t_s: float, motor_position_mm: float, contact_m: float = NAN) -> None:
        """Fix the onset, its pose and the closure slopes; start ``F_inst`` on the loading."""
        self._onset_t = t_s
        self._onset_motor = motor_position_mm
        self._k = self._tau = NAN
        stiffness, pose_per_mm = _closure_slopes(self._loading)
        if "closure" in self.parts:
            self.closure_stiffness_n_per_mm, self._pose_per_mm = stiffness, pose_per_mm
        before = [raw - stiffness * (m - motor_position_mm)
                  for t, m, raw, _ in self._loading if t >= t_s - self.onset_before_s]
        if self.onset_before_s == 0:
            before = []
        self._onset_sum, self._onset_n = float(sum(before)), len(before)
        self.f_onset_n = self._onset_sum / self._onset_n if before else NAN
        pose = self.features.last_pose
        if pose is not None:
            self.features.start(t_s, pose)

    def end_hold(self, t_s: float) -> None:
        """The fingers open: Eq. 10 and the added closure no longer apply; the ICFN reads."""
        tare = self.icfn.tare_n
        self.reset()
        self.icfn.tare_n = tare
        self.icfn.end_hold(t_s)


def _closure_slopes(
    loading: deque[tuple[float, float, float, FloatArray]],
) -> tuple[float, FloatArray]:
    """Least-squares slopes over motor travel of the ICFN (N/mm) and of the pose (per mm).

    Taken where the estimate is above half its latest value: the contact
    stiffens with force, so the hold needs the chain's tangent near the hold
    force, and at low targets the window would otherwise include travel before
    contact.  Zero if the motor did not move (a hold started from rest).
    """
    if len(loading) < 3:
        return 0.0, np.zeros(6)
    m = np.array([row[1] for row in loading])
    f = np.array([row[2] for row in loading])
    poses = np.array([row[3] for row in loading])
    upper = f >= SLOPE_FORCE_SHARE * float(np.median(f[-5:]))
    if np.count_nonzero(upper) >= 3:
        m, f, poses = m[upper], f[upper], poses[upper]
    stiffness = travel_slope(m, f)
    if stiffness is None:
        return 0.0, np.zeros(6)
    pose_slope = travel_slope(m, poses)
    assert pose_slope is not None  # the same travel
    return max(0.0, float(stiffness)), np.asarray(pose_slope)


def travel_slope(motor_mm: FloatArray, values: FloatArray) -> FloatArray | float | None:
    """Least-squares slope of ``values`` (one row per frame) over motor travel (per mm).

    A float for one value per frame, an array for several; None under 1 µm
    of travel, where there is no slope to measure.
    """
    spread = motor_mm - motor_mm.mean()
    denom = float(spread @ spread)
    if denom < 1e-6:
        return None
    slope: FloatArray | float = spread @ (values - values.mean(axis=0)) / denom
    return slope
