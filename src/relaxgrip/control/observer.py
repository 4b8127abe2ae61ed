"""The ``observer`` force estimator: Maxwell branches driven by the measured deflection.

Beyond the paper.  Eq. 10 predicts the force of a hold at a fixed aperture
and one temperature; closed-loop corrections move the finger and a demo may
change the temperature while holding.  The observer instead integrates the
generalized Maxwell model of the marker's finger (Eqs. 1–2) along whatever
happens: every frame, the branch forces advance by the exact recursion
(:func:`relaxgrip.physics.viscoelastic.branch_update`) under the marker's
deflection change and the infrared temperature, with temperature-dependent
stiffnesses and relaxation times in reduced time
(:class:`relaxgrip.learning.observer.ObserverModel`).

Its state starts at **contact** (branches at rest, the marker's deflection
from zero): the loading that leads to the hold is part of the history the
branches relax from, and a state started at the hold onset would have to
guess it.  Its **scale** (N per metre of deflection) comes from the ICFN over
the first ``onset_window_s`` of the hold: the ICFN is accurate where the
force has not yet relaxed away from the loading it was trained on, and one
ratio is all the linear model needs.  (``relax`` also averages the loading's
last second into ``F_inst``; here that measured no better, mean MAE 0.126
against 0.121 N on the standard hold, seeds 0-5: the observer's error is the
run's relaxing share, not its onset.)
Before the hold the estimate is the smoothed ICFN, as for ``icfn`` and
``relax``, so the closing is the same for all three.

The band: 95 % half-width ``band_rel(t) F_onset`` from the model's held-out
residuals (ICFN onset error included), the ICFN's onset error before.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from relaxgrip.control.estimators import ForceEstimate, IcfnEstimator
from relaxgrip.learning.icfn import ICFN
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.perception.features import finger_temperature_c, marker_pose
from relaxgrip.perception.pipeline import Percept
from relaxgrip.physics.viscoelastic import branch_update

__all__ = ["ObserverEstimator"]

NAN = math.nan
FloatArray = NDArray[np.float64]
#: Marker deflection that starts the branch states (m): the controller's contact threshold.
CONTACT_DEFLECTION_M = 3e-5


class ObserverEstimator:
    """ICFN before the hold; the viscoelastic observer, scaled by the ICFN at the onset, during it.

    Parameters
    ----------
    icfn : ICFN
        Fitted instantaneous contact force network.
    model : ObserverModel
        Fitted observer parameters.
    onset_window_s : float
        The scale averages the ICFN over this much of the hold's start (s).
    smoothing_s : float
        Low-pass time constant of the ICFN estimate before the hold (s).
    """

    name = "observer"
    regulates_hold = True

    def __init__(self, icfn: ICFN, model: ObserverModel, onset_window_s: float = 0.6,
                 smoothing_s: float = 0.2) -> None:
        self.icfn = IcfnEstimator(icfn, smoothing_s)
        self.model = model
        self.onset_window_s = onset_window_s
        self.reset()

    def reset(self) -> None:
        """Forget the grasp."""
        self.icfn.reset()
        self.branches_m: FloatArray | None = None  # per unit reference stiffness
        self.deflection_m = NAN
        self.temp_c = NAN
        self._t: float | None = None
        self._onset_t: float | None = None
        self._sum_f = self._sum_u = 0.0
        self.scale_n_per_m = NAN
        self.f_onset_n = NAN

    def unit_force_m(self) -> float:
        """The model's force per unit reference stiffness now (m); nan before contact."""
        if self.branches_m is None:
            return NAN
        k_e, _, _ = self.model.parameters(self.temp_c)
        return k_e * self.deflection_m + float(self.branches_m.sum())

    def advance(self, t_s: float, deflection_m: float, temp_c: float) -> None:
        """Step the branches to ``t_s`` (deflection linear, temperature constant over the step).

        Parameters
        ----------
        t_s : float
            Time of the new measurement (s).
        deflection_m : float
            Marker deflection (m).
        temp_c : float
            Finger temperature over the step (°C).
        """
        if self.branches_m is None:
            if deflection_m <= CONTACT_DEFLECTION_M:
                return
            _, k_i, tau = self.model.parameters(temp_c)
            # Contact: the deflection so far arrived within the last frame.
            self.branches_m, _ = branch_update(np.zeros(k_i.size), deflection_m, 0.0, k_i, tau)
        elif self._t is not None and t_s > self._t:
            _, k_i, tau = self.model.parameters(temp_c)
            self.branches_m, _ = branch_update(self.branches_m, deflection_m - self.deflection_m,
                                               t_s - self._t, k_i, tau)
        self.deflection_m, self.temp_c, self._t = deflection_m, temp_c, t_s

    def update(self, percept: Percept, motor_position_mm: float) -> ForceEstimate:
        """Advance the observer: the estimate is the ICFN before the hold, the observer in it."""
        raw = self.icfn.instantaneous(percept)
        f = self.icfn.smoothed(raw, percept.t_s)
        t = percept.t_s
        if percept.thermal is not None:
            temp = finger_temperature_c(percept.thermal)
            if math.isfinite(temp):
                self.temp_c = temp
        pose = marker_pose(percept.marker)
        if pose is not None and math.isfinite(self.temp_c):
            self.advance(t, float(pose[0]), self.temp_c)
        u = self.unit_force_m()
        if self._onset_t is None:
            half = self.model.onset_rel_ * self.model.band_scale * f
            return ForceEstimate(f, raw, band_lo_n=f - half, band_hi_n=f + half)
        hold = t - self._onset_t
        if hold <= self.onset_window_s and math.isfinite(raw) and u > 0:
            self._sum_f += raw
            self._sum_u += u
            self.scale_n_per_m = self._sum_f / self._sum_u
            self.f_onset_n = self.scale_n_per_m * u
        if not (math.isfinite(self.scale_n_per_m) and math.isfinite(u)):
            return ForceEstimate(NAN, raw, hold_s=hold)
        est = self.scale_n_per_m * u
        half = self.model.band_rel(hold) * self.f_onset_n
        return ForceEstimate(est, raw, self.f_onset_n, hold_s=hold,
                             band_lo_n=est - half, band_hi_n=est + half)

    def start_hold(self, t_s: float, motor_position_mm: float) -> None:
        """The hold starts: the scale averages the ICFN over the next ``onset_window_s``."""
        self._onset_t = t_s
        self._sum_f = self._sum_u = 0.0
        self.scale_n_per_m = self.f_onset_n = NAN
