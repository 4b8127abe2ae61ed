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

**The run's relaxing share.**  The parameters are the population's, and a run
whose finger relaxes 18 % less than the population's drifts 0.37 N off by the
end of a 280 s hold.  With the RCFN at hand (the default), a ``relax``
estimator runs alongside: its ``F_inst`` starts the observer, and while the
hold is the one Eq. 10 describes (temperature within 1 K of its mean since the onset, the
motor never faster than 0.3 mm/s, which a new target or a push breaks, and from 5 s
on the marker's deflection, averaged over 0.2 s, never changing by more than 2 % (and
10 µm) in a second, which a push breaks even where the controller, reading Eq. 10,
barely moves the motor) one
factor on every branch's stiffness is fitted so that the observer relaxes as
Eq. 10 says, the RCFN having read the run's relaxation from its pose
features.  The factor then holds through whatever temperature path and
displacement follow, where Eq. 10 no longer applies.  On the twin (280 s,
5 N, 40 °C) this took the observer from 0.121 to 0.054 N mean MAE over seeds
0-5 (0.0429 over seeds 0-11, ``relax`` 0.0430), the 40 -> 55 °C ramp from
0.128 to 0.096 N and the 5 -> 3 N step from 0.093 to 0.055 N (seeds 0-2).
While the fit runs, Eq. 10 itself is the estimate, and when it ends the
observer continues from Eq. 10's value (it adds Eq. 10's mean offset from
it over the seconds before): where Eq. 10 holds the observer cannot do
better than the model its share is fitted to, and it no longer jumps when
it takes over.  On the twin (uncovered-beam temperature, seeds 0-5) the
step went from 0.058 to 0.053 N mean MAE, the ramp from 0.113 to 0.105 N;
the standard hold is ``relax``'s.  That estimate is ``relax``'s whole,
the closed chain's reading blended in (:mod:`relaxgrip.control.chain`);
the share is fitted to Eq. 10 without it.  What the observer carries from
Eq. 10 (that offset and the calibration of the fit's last frame) it carries
in proportion to its own force, as the linear model it is: after a 5 -> 3 N
step a constant offset had left the estimate 0.04 N higher than before the
step on average, in proportion 0.006 N (seeds 3000-3011, whose MAE went from
0.066 to 0.061 N; with the controller's feed-forward on a new target, 0.050 N).
A chain of the observer's own,
counted from the fit's end and blended in at 0.3, held the ramp worse
(0.085 against 0.072 N, seeds 2000-2023) and was not kept.

The band: 95 % half-width ``band_floor_n + band_rel(t, T) F_onset``, a floor in
newtons and a share of the onset force from the model's held-out residuals
(ICFN onset error included) times a factor at the finger's temperature ``T``
(``band_factor``: 1 where the band was calibrated, wider where it is hot), the
floor and the ICFN's onset error before; once
the share fit has ended, plus the run-to-run spread of the relaxing share
times what the branches have relaxed since (``band_drift_rel``): a
temperature ramp relaxes the finger by a share the fit at the old
temperature did not see.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.control.estimators import (
    TARE_WINDOW_S,
    ForceEstimate,
    IcfnEstimator,
    RelaxEstimator,
)
from relaxgrip.learning.history import CONTACT_DEFLECTION_M, LoadingHistory, UnrelaxedIcfn
from relaxgrip.learning.hold_bias import HoldBias
from relaxgrip.learning.icfn import ICFN
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.rcfn import RCFN
from relaxgrip.perception.features import finger_temperature_c, marker_pose
from relaxgrip.perception.pipeline import Percept

__all__ = ["ObserverEstimator"]

NAN = math.nan
FloatArray = NDArray[np.float64]
#: The marker's deflection is averaged over this long at each end of the second the
#: share fit watches it over (s).
_MOTION_AVERAGE_S = 0.2


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
    rcfn : RCFN, optional
        With it, the observer identifies the run's relaxing share online: a
        ``relax`` estimator runs alongside, its ``F_inst`` starts the observer,
        and while the hold is the one Eq. 10 describes (the temperature within
        ``share_fit_temp_k`` of its mean since the onset, the motor never faster than
        ``share_fit_motor_mm_s`` over a second, the marker's deflection, from
        ``share_fit_settle_s`` on, never changing by more than
        ``share_fit_deflection_rel`` of itself (or ``share_fit_deflection_floor_m``)
        over a second, the first ``share_fit_s``: a new target or a push ends
        it) the branches' share is
        scaled by the factor that best matches Eq. 10's relaxation since the
        onset.  The factor then holds for whatever temperature path and
        displacement follow.  The deflection's limit: on the twin the marker
        creeps up to 2.2 % in a second over the hold's first 5 s and 0.7 % after
        (seed 2014, 5 N, 40 °C); a 2 N push moved it 7 % in a second while the
        motor moved under 0.3 mm, and that hold's MAE went from 0.400 to 0.101 N.
        Single frames carry the marker's noise, about 2 % of a 0.25 mm deflection
        at 0.5 N: averaged over 0.2 s at each end, with the floor, the largest
        change before the end of a 40 s hold at 0.5 N was 0.30 of the limit
        (seeds 2000-2001), at 1 N 0.46.
    share_bounds : tuple of float
        Bounds of that factor.
    anchor_window_s : tuple of float
        While the fit runs, Eq. 10 is the estimate (the observer cannot
        beat the model it is fitted to where that model holds); when it ends,
        the observer continues from Eq. 10's last value: its own estimate plus
        Eq. 10's mean offset from it between ``anchor_window_s[0]`` and
        ``anchor_window_s[1]`` seconds before the end, scaled from then on by
        its own force over its force at the end.
    unrelaxed : UnrelaxedIcfn, optional
        Read the force from the loading history, as ``relax`` does
        (:class:`relaxgrip.control.estimators.IcfnEstimator`).
    chain_weight : float
        After the share fit, where ``relax``'s closed chain reads the other
        finger in the infrared frame (the object located), the estimate is
        this share of ``relax``'s (the chain's reading: the motor's travel
        less both fingers' measured deflections, which holds through any
        temperature path and displacement) and the rest the observer's.
    hold_bias : HoldBias, optional
        ``relax``'s calibrated closed-loop error (at ``F_inst``, the
        temperature as read and the hold time), taken off the observer's
        estimate: while Eq. 10 is the estimate it is calibrated ``relax``'s;
        after the share fit, the value of the fit's last frame stays, scaled
        with the observer's force as the offset is.  The
        table was measured on holds at one temperature from their onset, so
        after a ramp its entry at the new temperature says what such a hold
        is off by, not the observer (seeds 4000-4035, 40 -> 55 °C from
        150 s: 0.105 N looked up as read, 0.088 N kept; the 5 -> 3 N step
        0.063 and 0.065 N).  The share is fitted to Eq. 10 without it.
    """

    name = "observer"
    regulates_hold = True

    def __init__(self, icfn: ICFN, model: ObserverModel, onset_window_s: float = 0.6,
                 smoothing_s: float = 0.2, rcfn: RCFN | None = None,
                 share_fit_s: float = 280.0, share_fit_temp_k: float = 1.0,
                 share_fit_motor_mm_s: float = 0.3, share_fit_deflection_rel: float = 0.02,
                 share_fit_deflection_floor_m: float = 10e-6, share_fit_settle_s: float = 5.0,
                 share_bounds: tuple[float, float] = (0.5, 1.5),
                 anchor_window_s: tuple[float, float] = (10.0, 2.0),
                 unrelaxed: UnrelaxedIcfn | None = None,
                 hold_bias: HoldBias | None = None, chain_weight: float = 1.0) -> None:
        if not (share_fit_s >= 0 and share_fit_temp_k > 0 and share_fit_motor_mm_s > 0
                and share_fit_deflection_rel > 0 and share_fit_deflection_floor_m >= 0
                and share_fit_settle_s >= 0):
            raise ValueError("the share fit needs a window >= 0 s, temperature, motor and "
                             "deflection limits > 0, a deflection floor >= 0 and a settling "
                             f"time >= 0, got {share_fit_s} s, {share_fit_temp_k} K, "
                             f"{share_fit_motor_mm_s} mm/s, {share_fit_deflection_rel}, "
                             f"{share_fit_deflection_floor_m} m, {share_fit_settle_s} s")
        if not 0 < share_bounds[0] <= 1.0 <= share_bounds[1]:
            raise ValueError(f"share bounds must enclose 1 and be > 0, got {share_bounds}")
        if not anchor_window_s[0] > anchor_window_s[1] >= 0:
            raise ValueError("the share fit's anchor window must start before it ends, got "
                             f"{anchor_window_s[0]} s to {anchor_window_s[1]} s before")
        if not 0.0 <= chain_weight <= 1.0:
            raise ValueError(f"the chain's weight must be in [0, 1], got {chain_weight}")
        self.chain_weight = chain_weight
        self.model = model
        self.provenance: dict[str, Any] = {}
        self.history = LoadingHistory(model, CONTACT_DEFLECTION_M)
        self.onset_window_s = onset_window_s
        self.relax = None if rcfn is None else RelaxEstimator(
            icfn, rcfn, smoothing_s=smoothing_s, unrelaxed=unrelaxed, bias=hold_bias)
        # With relax alongside, its reading is the observer's: one ICFN pass per frame.
        self.icfn = (IcfnEstimator(icfn, smoothing_s, unrelaxed, TARE_WINDOW_S)
                     if self.relax is None else self.relax.icfn)
        self.share_fit_s = share_fit_s
        self.share_fit_temp_k = share_fit_temp_k
        self.share_fit_motor_mm_s = share_fit_motor_mm_s
        self.share_fit_deflection_rel = share_fit_deflection_rel
        self.share_fit_deflection_floor_m = share_fit_deflection_floor_m
        self.share_fit_settle_s = share_fit_settle_s
        self.share_bounds = share_bounds
        self.anchor_window_s = anchor_window_s
        self.reset()

    def reset(self) -> None:
        """Forget the grasp."""
        self.icfn.reset()
        self.history.reset()
        self.temp_c = NAN
        self._onset_t: float | None = None
        self._sum_f = self._sum_u = 0.0
        self.scale_n_per_m = NAN
        self.f_onset_n = NAN
        if self.relax is not None:
            self.relax.reset()
        self._reset_hold()

    def _reset_hold(self) -> None:
        """Forget the hold: the share fit and its windows start again (the branches go on)."""
        self.share = 1.0
        self._fitting = True
        self._fit_ab = self._fit_aa = 0.0
        self._u_on = self._r_on = NAN
        self._temp_sum, self._temp_n = 0.0, 0
        self._motor: deque[tuple[float, float]] = deque()
        self._deflection: deque[tuple[float, float]] = deque()
        self._offsets: deque[tuple[float, float]] = deque()
        self._offset_n = self._r_end = self._est_end = NAN
        self._calibration_n = 0.0

    def _anchor_offset(self, hold: float) -> float:
        """Eq. 10 less the observer, averaged over the anchor window before ``hold`` (N).

        The frames just before the fit ends are already off Eq. 10's
        assumptions (the temperature has moved a kelvin, the motor
        for a second), so the window ends ``anchor_window_s[1]`` before;
        a fit that ended sooner uses what there is.
        """
        if not self._offsets:
            return 0.0
        oldest, lag = hold - self.anchor_window_s[0], hold - self.anchor_window_s[1]
        kept = [o for h, o in self._offsets if oldest <= h <= lag]
        return float(np.mean(kept if kept else [o for _, o in self._offsets]))

    def _marker_moved(self, hold: float) -> bool:
        """Has the marker's deflection moved faster than creep over the last second?

        The mean of the last ``_MOTION_AVERAGE_S`` against the mean of the
        same span a second before (single frames carry the marker's noise,
        which at 0.5 N is 2 % of the deflection), beyond
        ``share_fit_deflection_rel`` of it or ``share_fit_deflection_floor_m``,
        whichever is larger; only from ``share_fit_settle_s`` into the hold on.
        """
        if hold <= self.share_fit_settle_s or not self._deflection:
            return False
        start = self._deflection[0][0]
        if hold - start < 1.0 - _MOTION_AVERAGE_S:
            return False  # less than a second seen
        first = [d for h, d in self._deflection if h <= start + _MOTION_AVERAGE_S]
        last = [d for h, d in self._deflection if h >= hold - _MOTION_AVERAGE_S]
        now = sum(last) / len(last)
        change = abs(now - sum(first) / len(first))
        return change > max(self.share_fit_deflection_rel * abs(now),
                            self.share_fit_deflection_floor_m)

    def unit_force_m(self) -> float:
        """The model's force per unit reference stiffness now (m); nan before contact."""
        return self.history.unit_force_m()

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
        self.history.advance(t_s, deflection_m, temp_c)
        self.temp_c = temp_c

    def relaxed_m(self) -> float:
        """What the branches have relaxed of the instantaneous response now (m, per unit)."""
        return self.history.relaxed_m()

    def update(self, percept: Percept, motor_position_mm: float) -> ForceEstimate:
        """Advance the observer: the estimate is the ICFN before the hold, the observer in it."""
        relax = None if self.relax is None else self.relax.update(percept, motor_position_mm)
        raw = self.icfn.instantaneous(percept) if relax is None else relax.f_icfn_n
        # Shared with relax, the filter has taken this frame already; it keeps it.
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
            half = self.model.closing_half_n(f, self.temp_c)
            return ForceEstimate(f, raw, band_lo_n=f - half, band_hi_n=f + half,
                                 band_drift_n=0.0)
        hold = t - self._onset_t
        if relax is not None:
            return self._with_share(relax, raw, hold, u, motor_position_mm,
                                    NAN if pose is None else float(pose[0]))
        if hold <= self.onset_window_s and math.isfinite(raw) and u > 0:
            self._sum_f += raw
            self._sum_u += u
            self.scale_n_per_m = self._sum_f / self._sum_u
            self.f_onset_n = self.scale_n_per_m * u
        if not (math.isfinite(self.scale_n_per_m) and math.isfinite(u)):
            return ForceEstimate(NAN, raw, hold_s=hold)
        est = self.scale_n_per_m * u
        half = self.model.band_half_n(hold, self.f_onset_n, self.temp_c)
        return ForceEstimate(est, raw, self.f_onset_n, hold_s=hold,
                             band_lo_n=est - half, band_hi_n=est + half, band_drift_n=0.0)

    def _with_share(self, relax: ForceEstimate, raw: float, hold: float, u: float,
                    motor_mm: float, deflection_m: float) -> ForceEstimate:
        """The observer started from ``relax``'s ``F_inst``, its branch share fitted to Eq. 10.

        Scaling every branch stiffness by ``share`` (the instantaneous
        stiffness kept) scales the branch states by it along any history, so
        the force per unit stiffness is ``u - (share - 1) R``, ``R`` what the
        branches have relaxed, and the estimate
        ``F_inst (u - (share - 1) R) / (u_onset - (share - 1) R_onset)``.
        Equating it to Eq. 10's and clearing the denominator is linear in
        ``share``: a running least-squares fit over the frames where Eq. 10 holds.
        """
        assert self.relax is not None
        f_on = self.relax.f_onset_n
        r = self.relaxed_m()
        if not math.isfinite(self._u_on) and math.isfinite(u) and u > 0:
            self._u_on, self._r_on = u, r
        if not (math.isfinite(f_on) and math.isfinite(self._u_on) and math.isfinite(u)):
            return ForceEstimate(NAN, raw, hold_s=hold)
        self._motor.append((hold, motor_mm))
        while hold - self._motor[0][0] > 1.0:
            self._motor.popleft()
        if math.isfinite(deflection_m):
            self._deflection.append((hold, deflection_m))
        while self._deflection and hold - self._deflection[0][0] > 1.0:
            self._deflection.popleft()
        if self._fitting:
            # Steady: the temperature near its mean since the onset (the first reading
            # can be off while the contact settles the infrared pattern), the motor
            # still, and the marker only creeping: a push on the object moves the
            # marker's finger by several per cent in a second while the controller,
            # reading Eq. 10, may barely move the motor.
            self._temp_sum += self.temp_c
            self._temp_n += 1
            steady_c = self._temp_sum / self._temp_n
            if (hold > self.share_fit_s
                    or abs(self.temp_c - steady_c) > self.share_fit_temp_k
                    or abs(motor_mm - self._motor[0][1]) > self.share_fit_motor_mm_s
                    or self._marker_moved(hold)):
                self._fitting = False
        # Eq. 10 itself, the calibration put back and the closed chain's reading taken
        # out: the share is fitted to the model's relaxation, and the calibration is
        # taken off the observer's estimate below.
        calibration = relax.calibration_n if math.isfinite(relax.calibration_n) else 0.0
        chain = relax.chain_n if math.isfinite(relax.chain_n) else 0.0
        blended = relax.force_n + calibration
        eq10 = blended - chain
        if self._fitting and hold > self.onset_window_s and math.isfinite(eq10):
            # F_inst (u - x R) = F_eq10 (u_onset - x R_onset), x = share - 1
            a = f_on * r - eq10 * self._r_on
            b = f_on * u - eq10 * self._u_on
            self._fit_ab += a * b
            self._fit_aa += a * a
            if self._fit_aa > 0:
                lo, hi = self.share_bounds
                self.share = min(max(1.0 + self._fit_ab / self._fit_aa, lo), hi)
        excess = self.share - 1.0
        self.f_onset_n = f_on
        self.scale_n_per_m = f_on / (self._u_on - excess * self._r_on)
        est = self.scale_n_per_m * (u - excess * r)
        fitting = self._fitting and math.isfinite(blended)
        if fitting:
            # Eq. 10 holds: it is the estimate (with the chain's reading blended in, as
            # relax's); the observer carries its offset from it.
            self._offsets.append((hold, blended - est))
            while hold - self._offsets[0][0] > self.anchor_window_s[0]:
                self._offsets.popleft()
            est = blended
            self._calibration_n = calibration
        else:
            if math.isnan(self._offset_n):
                self._offset_n = self._anchor_offset(hold)
                self._r_end = r
                self._est_end = est
            # The offset from Eq. 10 and the calibration when the observer took over,
            # carried in proportion to the force: the observer is linear, and the
            # table's later times and other temperatures describe Eq. 10's holds,
            # not the observer's.
            ratio = est / self._est_end if self._est_end > 0 else 1.0
            est += self._offset_n * ratio
            calibration = self._calibration_n * ratio
        est -= calibration
        follows = (not fitting and self.chain_weight > 0.0 and self.relax.chain.reads_other
                   and math.isfinite(relax.force_n))
        if follows:
            # Both fingers measured: the chain's reading needs no relaxation model.
            est += self.chain_weight * (relax.force_n - est)
        drift = 0.0
        if math.isfinite(self._r_end):
            # What the branches relax after the fit carries the run's share spread.
            unseen = self.scale_n_per_m * self.share * abs(r - self._r_end)
            drift = self.model.band_drift_rel(self.temp_c) * unseen
        half = self.model.band_half_n(hold, f_on, self.temp_c) + drift
        return ForceEstimate(est, raw, f_on, relax.k_n, relax.tau_s, hold,
                             band_lo_n=est - half, band_hi_n=est + half, band_drift_n=drift,
                             calibration_n=(calibration if math.isfinite(relax.calibration_n)
                                            else NAN),
                             chain_n=relax.chain_n if fitting or follows else NAN)

    def contact(self, t_s: float) -> float:
        """Tare the ICFN on the free-space frames before the contact (returns the tare, N)."""
        return self.icfn.contact(t_s)

    def end_hold(self, t_s: float) -> None:
        """The fingers open: the estimate is the ICFN again, until a new hold."""
        self._onset_t = None
        if self.relax is not None:
            self.relax.end_hold(t_s)
        else:
            self.icfn.end_hold(t_s)

    def start_hold(self, t_s: float, motor_position_mm: float, contact_m: float = NAN) -> None:
        """The hold starts: the scale averages the ICFN over the next ``onset_window_s``.

        ``contact_m`` (where the object was seen) goes to ``relax``'s closed chain.
        """
        self._onset_t = t_s
        self._sum_f = self._sum_u = 0.0
        self.scale_n_per_m = self.f_onset_n = NAN
        self._reset_hold()
        if self.relax is not None:
            self.relax.start_hold(t_s, motor_position_mm, contact_m)
