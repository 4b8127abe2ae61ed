"""Force estimators behind one interface: the paper's ``fixed``, ``icfn`` and ``relax``.

Every estimator reads percepts (features of rendered or real frames) and the
motor encoder, never ground truth.  Each frame it reports a
:class:`ForceEstimate`; the grasp controller tells it when it sees contact
(:meth:`ForceEstimator.contact`), when the hold starts
(:meth:`ForceEstimator.start_hold`, ``t = 0`` of Eqs. 6-10) and when the
fingers open (:meth:`ForceEstimator.end_hold`).

* ``icfn``: the instantaneous contact force network on the current frame
  (§IV-B).  Regulating it holds the finger's *deflection*, and the finger
  relaxes at constant deflection: the estimate stays on target while the true
  force decays (the paper's "without relaxation compensation").
* ``fixed``: the same estimate, but the controller stops the motor at the hold
  onset and never regulates again (:attr:`ForceEstimator.regulates_hold` is
  false): the aperture is held and the force decays ("without holding
  control").
* ``relax``: the paper's method, Eq. 10.  The ICFN at the contact onset gives
  ``F_inst``; during the hold the RCFN predicts ``(K, tau)`` from the current
  temperature, the onset pose, the current pose and the pose velocity, and the
  controller is handed ``F(t) = F_inst - K (1 - exp(-t / tau))``.

The beyond-paper ``observer`` (:mod:`relaxgrip.control.observer`) builds on
``relax``.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from relaxgrip.learning.calibration import Calibration
from relaxgrip.learning.icfn import ICFN
from relaxgrip.learning.rcfn import RCFN
from relaxgrip.learning.store import ModelBundle
from relaxgrip.perception.features import RcfnFeatures, finger_temperature_c, marker_pose
from relaxgrip.perception.pipeline import Percept

__all__ = [
    "EstimatorKind",
    "FixedEstimator",
    "ForceEstimate",
    "ForceEstimator",
    "IcfnEstimator",
    "RelaxEstimator",
    "bundle_estimator",
    "estimator_provenance",
    "make_estimator",
]

NAN = math.nan


class EstimatorKind(enum.StrEnum):
    """The estimators ``relaxgrip hold --estimator`` offers."""

    FIXED = "fixed"
    ICFN = "icfn"
    RELAX = "relax"
    OBSERVER = "observer"


@dataclass(frozen=True)
class ForceEstimate:
    """One frame's force estimate.

    Attributes
    ----------
    force_n : float
        The estimate the controller regulates (N); nan when there is none
        (marker lost, no thermal features yet).
    f_icfn_n : float
        The ICFN's instantaneous estimate on this frame (N; nan if none).
    f_onset_n : float
        ``F_inst`` at the hold onset (N; nan before it).
    k_n, tau_s : float
        Relaxation magnitude (N) and time (s) of Eq. 10 (nan unless ``relax``
        or ``observer`` is holding).
    hold_s : float
        Time since the hold onset (s; nan before it).
    band_lo_n, band_hi_n : float
        The estimate's 95 % band (N; nan when the estimator gives none).
    calibration_n : float
        The calibrated error taken off ``force_n`` (N; ``observer`` with a
        calibration only, :mod:`relaxgrip.learning.calibration`).
    """

    force_n: float
    f_icfn_n: float
    f_onset_n: float = NAN
    k_n: float = NAN
    tau_s: float = NAN
    hold_s: float = NAN
    band_lo_n: float = NAN
    band_hi_n: float = NAN
    calibration_n: float = NAN

    @property
    def valid(self) -> bool:
        """Whether there is an estimate to act on."""
        return math.isfinite(self.force_n)


class ForceEstimator(Protocol):
    """What the grasp controller needs of a force estimator."""

    name: str
    regulates_hold: bool
    #: The models it runs, as a recording names them (:func:`bundle_estimator` sets it;
    #: empty for an estimator built on bare models).
    provenance: dict[str, Any]

    def reset(self) -> None:
        """Forget everything (a new grasp)."""
        ...

    def update(self, percept: Percept, motor_position_mm: float) -> ForceEstimate:
        """Estimate the force from this frame's percept and the encoder."""
        ...

    def contact(self, t_s: float) -> float:
        """The controller saw contact now; returns the tare taken off later readings (N)."""
        ...

    def start_hold(self, t_s: float, motor_position_mm: float, contact_m: float = NAN) -> None:
        """The hold starts now (``t = 0`` of Eq. 10); ``contact_m`` is where perception saw
        the object along the fingers (m from the root; nan if unseen)."""
        ...

    def end_hold(self, t_s: float) -> None:
        """The fingers open now: the hold is over, estimate as before it."""
        ...


class IcfnEstimator:
    """The instantaneous estimate alone (the paper's instantaneous-only baseline).

    Parameters
    ----------
    icfn : ICFN
        A fitted instantaneous contact force network.
    smoothing_s : float
        Low-pass time constant of the estimate (s): a frame's estimate carries
        the marker pose's noise (about 0.1 N), and the force changes far
        slower than the camera rate.
    tare_window_s, tare_margin_s, tare_min_n : float
        At contact (:meth:`contact`) the network's reading at rest is its
        median over ``tare_window_s`` of frames ending ``tare_margin_s``
        before the contact, when the fingers were free; if it is at least
        ``tare_min_n`` off zero it is taken off every later reading, as a load
        cell is zeroed before a grasp.  ``tare_window_s = 0`` (the paper's
        estimators) never tares; the ``observer`` may.
    """

    name = "icfn"
    regulates_hold = True

    def __init__(self, icfn: ICFN, smoothing_s: float = 0.2, tare_window_s: float = 0.0,
                 tare_margin_s: float = 0.25, tare_min_n: float = 0.15) -> None:
        if not smoothing_s >= 0:
            raise ValueError(f"smoothing time must be >= 0 s, got {smoothing_s}")
        if not (tare_window_s >= 0 and tare_margin_s >= 0 and tare_min_n >= 0):
            raise ValueError(f"tare window, margin and least tare must be >= 0, got "
                             f"{tare_window_s} s, {tare_margin_s} s and {tare_min_n} N")
        self.icfn = icfn
        self.smoothing_s = smoothing_s
        self.tare_window_s = tare_window_s
        self.tare_margin_s = tare_margin_s
        self.tare_min_n = tare_min_n
        self.provenance: dict[str, Any] = {}
        self.reset()

    def reset(self) -> None:
        """Forget the tare, the hold onset and the filter's state."""
        self._onset_t: float | None = None
        self._onset_f = self._last = NAN
        self._smooth = NAN
        self._t: float | None = None
        self._recent: deque[tuple[float, float]] = deque()
        self.rest_n = NAN
        self.tare_n = 0.0

    def instantaneous(self, percept: Percept) -> float:
        """The force read on this frame (N, never negative); nan without finite features."""
        x = percept.features
        if x is None or not np.isfinite(x).all():
            return NAN
        reading = self.icfn.predict_one(x)
        if self.tare_window_s > 0:
            self._recent.append((percept.t_s, reading))
            while self._recent[0][0] < percept.t_s - self.tare_window_s - self.tare_margin_s:
                self._recent.popleft()
        return max(0.0, reading - self.tare_n)

    def contact(self, t_s: float) -> float:
        """Measure the reading at rest before ``t_s`` and tare it if it is off (returns the
        tare, N; 0 for none).  ``rest_n`` keeps the measurement (nan without frames)."""
        if self.tare_window_s == 0:
            return 0.0
        start = t_s - self.tare_window_s - self.tare_margin_s
        free = [f for t, f in self._recent if start <= t <= t_s - self.tare_margin_s]
        self.rest_n = float(np.median(free)) if free else NAN
        if abs(self.rest_n) >= self.tare_min_n:
            self.tare_n = self.rest_n
        return self.tare_n

    def smoothed(self, f: float, t_s: float) -> float:
        """First-order low-pass of the per-frame estimate; a missing one restarts it."""
        if not math.isfinite(f):
            self._smooth, self._t = NAN, None
            return NAN
        if self._t is None or not math.isfinite(self._smooth) or self.smoothing_s == 0:
            self._smooth = f
        elif t_s > self._t:
            alpha = -math.expm1(-(t_s - self._t) / self.smoothing_s)
            self._smooth += alpha * (f - self._smooth)
        self._t = t_s
        return self._smooth

    def update(self, percept: Percept, motor_position_mm: float) -> ForceEstimate:
        """The (smoothed) ICFN estimate is the force."""
        raw = self.instantaneous(percept)
        f = self.smoothed(raw, percept.t_s)
        self._last = f
        hold = NAN if self._onset_t is None else percept.t_s - self._onset_t
        return ForceEstimate(f, raw, self._onset_f, hold_s=hold)

    def start_hold(self, t_s: float, motor_position_mm: float, contact_m: float = NAN) -> None:
        """Remember the onset (for the record only)."""
        self._onset_t = t_s
        self._onset_f = self._last

    def end_hold(self, t_s: float) -> None:
        """Forget the onset."""
        self._onset_t = None
        self._onset_f = NAN


class FixedEstimator(IcfnEstimator):
    """The ICFN estimate, for a controller that holds the aperture once the target is reached."""

    name = "fixed"
    regulates_hold = False


class RelaxEstimator:
    """ICFN at the hold onset, RCFN during the hold: the paper's Eq. 10 in closed loop.

    Before the hold the estimate is the smoothed ICFN (as ``icfn``'s).  From the
    onset on it is

    ``F(t) = F_inst - K (1 - exp(-t / tau))``   (Eq. 10)

    with ``F_inst`` the mean ICFN estimate over the hold's first
    ``onset_window_s`` (one frame's ICFN is 0.1-0.2 N off, and ``F_inst``
    carries into every later estimate) and ``(K, tau)`` the RCFN's prediction
    on the latest infrared frame (:data:`relaxgrip.perception.features.RCFN_SCHEMA`).

    Parameters
    ----------
    icfn : ICFN
        Fitted instantaneous contact force network.
    rcfn : RCFN
        Fitted relaxation compensation force network.
    onset_window_s : float
        ``F_inst`` averages the ICFN over this much of the hold's start (s).
    smoothing_s : float
        Low-pass time constant of the ICFN estimate before the hold (s).
    """

    name = "relax"
    regulates_hold = True

    def __init__(self, icfn: ICFN, rcfn: RCFN, onset_window_s: float = 0.6,
                 smoothing_s: float = 0.2) -> None:
        if not onset_window_s > 0:
            raise ValueError(f"onset window must be > 0 s, got {onset_window_s}")
        self.icfn = IcfnEstimator(icfn, smoothing_s)
        self.rcfn = rcfn
        self.onset_window_s = onset_window_s
        self.provenance: dict[str, Any] = {}
        self.reset()

    def reset(self) -> None:
        """Forget the grasp."""
        self.icfn.reset()
        self.features = RcfnFeatures()
        self._onset_t: float | None = None
        self._onset_sum, self._onset_n = 0.0, 0
        self.f_onset_n = NAN
        self._k = self._tau = NAN

    def update(self, percept: Percept, motor_position_mm: float) -> ForceEstimate:
        """The smoothed ICFN before the hold; Eq. 10 during it."""
        raw = self.icfn.instantaneous(percept)
        f = self.icfn.smoothed(raw, percept.t_s)
        t = percept.t_s
        pose = marker_pose(percept.marker)
        if pose is not None:
            self.features.observe(t, pose)
        if self._onset_t is None:
            return ForceEstimate(f, raw)
        hold = t - self._onset_t
        if hold <= self.onset_window_s and math.isfinite(raw):
            self._onset_sum += raw
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
        force = self.f_onset_n - self._k * -math.expm1(-hold / self._tau)  # Eq. 10
        return ForceEstimate(force, raw, self.f_onset_n, self._k, self._tau, hold)

    def contact(self, t_s: float) -> float:
        """Nothing to do at contact: the paper's ICFN reads as it is (no tare)."""
        return self.icfn.contact(t_s)

    def start_hold(self, t_s: float, motor_position_mm: float, contact_m: float = NAN) -> None:
        """Fix the onset and its pose; ``F_inst`` averages the ICFN from now on."""
        self._onset_t = t_s
        self._onset_sum, self._onset_n = 0.0, 0
        self.f_onset_n = NAN
        self._k = self._tau = NAN
        pose = self.features.last_pose
        if pose is not None:
            self.features.start(t_s, pose)

    def end_hold(self, t_s: float) -> None:
        """The fingers open: Eq. 10 no longer applies; the ICFN reads."""
        self._onset_t = None
        self.f_onset_n = NAN
        self._k = self._tau = NAN
        self.features = RcfnFeatures()
        self.icfn.end_hold(t_s)


def make_estimator(kind: EstimatorKind | str, icfn: ICFN, rcfn: RCFN,
                   calibration: Calibration | None = None,
                   without: tuple[str, ...] = ()) -> ForceEstimator:
    """The estimator named ``kind`` on the given models (``calibration``: the observer's;
    ``without``: observer parts to leave out, the ablation's variants)."""
    kind = EstimatorKind(kind)
    if kind is EstimatorKind.OBSERVER:
        from relaxgrip.control.observer import ObserverEstimator

        return ObserverEstimator(icfn, rcfn, calibration, without)
    if without:
        raise ValueError(f"only the observer has parts to leave out, not {kind.value}")
    if kind is EstimatorKind.FIXED:
        return FixedEstimator(icfn)
    if kind is EstimatorKind.ICFN:
        return IcfnEstimator(icfn)
    return RelaxEstimator(icfn, rcfn)


def bundle_estimator(kind: EstimatorKind | str, bundle: ModelBundle,
                     without: tuple[str, ...] = ()) -> ForceEstimator:
    """The estimator named ``kind`` on a model directory's models (the ``observer`` with
    its calibration, less the parts ``without``); its :attr:`~ForceEstimator.provenance`
    names them for a recording."""
    est = make_estimator(kind, bundle.icfn, bundle.rcfn, bundle.calibration, without)
    est.provenance = estimator_provenance(kind, bundle)
    return est


def estimator_provenance(kind: EstimatorKind | str, bundle: ModelBundle) -> dict[str, Any]:
    """What a recording names of the models :func:`bundle_estimator` runs ``kind`` on
    (:meth:`ModelBundle.provenance`)."""
    return bundle.provenance()
