"""The closed chain's own reading of the force during a hold, blended into Eq. 10's.

Beyond the paper.  The fingers and the object close one chain: the motor's
travel since a moment of the hold is taken up by the two fingers' contact
deflections and the object's compression, and the force changes by the
object's stiffness times that compression.  So

``F(t) = F(t_ref) + k_obj [(m(t) - m_ref) - (c0(t) - c0_ref) - (c1(t) - c1_ref)]``

with ``m`` the encoder, ``c0`` the contact deflection of the marker's finger
(the marker's deflection over the share of it the beam model gives at the
marker) and ``c1`` the other finger's.  Where the object was seen, ``c1`` is
read in the infrared frame (its top face's bend,
:mod:`relaxgrip.perception.face_bend`, fitted with the beam model at the
object's place) and the chain's weight is ``ChainParams.ir_weight``;
otherwise ``c1`` is taken equal to ``c0``, which nothing else sees.
``k_obj`` comes from the loading, where the ICFN rose by
``s = k_obj (1 - 2 rho / g)`` per millimetre of motor travel while the
marker moved ``rho`` (``g`` the marker's share).

How much of the marker's finger's contact deflection the marker shows
depends on where the object sits along the finger (0.622 ± 0.021 over the
twin's runs, whose contact scatters 1.9 mm): perception finds the object
before the hold (:class:`relaxgrip.control.GraspPlan`'s ``grasped``) and
:meth:`ClosedChain.start` takes the share from where it sits.

Eq. 10's error during a hold is mostly the relaxing share of the finger
without the marker (the RCFN reads the marker's finger); the chain's is the
difference of the two fingers' creep, and the object's position when it is
not seen.  The two are nearly independent, and
a weighted mean is better than either.  On the twin (``relax``, 5 N,
40 °C, the estimate's mean absolute error over 100-280 s, seeds 0-23, from
its logged frames): Eq. 10 alone 0.047 N, the chain alone 0.064 N, 0.8
Eq. 10 + 0.2 chain 0.041 N (0.040-0.044 N with the marker's share taken
anywhere in 0.58-0.65; the twin's runs read 0.56-0.63).  In closed loop
(MAE from the target, calibrated models) 5 N went from 0.0405 to 0.0373 N
over seeds 0-47, 8 N from 0.076 to 0.065 N and 5 N at 55 °C from 0.116 to
0.077 N (seeds 0-7).  Where the run's error is its onset reading, which
both readings share, the blend changes nothing: seeds 2000-2047, 0.0636
against 0.0642 N.  With the object's position seen, at weight 0.4, 5 N at
40 °C went from 0.054 to 0.0505 N over 180 holds on five sets of seeds;
across the grid of 1-8 N and 30-55 °C it was neither better nor worse (8
of 10 conditions worse on seeds 0-7, 8 of 10 better on seeds 8-15; 5 N at
55 °C +0.022 +- 0.014 N), so seeing it is not the default (sessions 35, 36).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from relaxgrip.physics.beam import FingerParams, deflection_share

__all__ = ["ChainParams", "ClosedChain", "marker_share"]

NAN = math.nan


def marker_share(marker_m: float, contact_m: float, temp_c: float,
                 finger: FingerParams) -> float:
    """The marker's deflection per unit of contact deflection, from the beam model.

    Parameters
    ----------
    marker_m, contact_m : float
        Positions of the marker and of the contact along the finger (m).
    temp_c : float
        The finger's temperature (°C), taken uniform.
    finger : FingerParams
        Finger constants.
    """
    return float(deflection_share(marker_m, contact_m, temp_c, finger))


#: The marker's share is computed anew when the finger's temperature has moved this far (K).
_SHARE_STEP_K = 0.5


@dataclass(frozen=True)
class ChainParams:
    """How the chain's reading is formed and blended.

    Attributes
    ----------
    weight : float
        The chain's share of the blended estimate, in [0, 1]; 0 is Eq. 10
        alone (the paper's).
    seen_weight : float
        Its share when perception saw where the object sits along the
        fingers (:meth:`ClosedChain.start`'s ``contact_m``): the marker's
        share of the contact deflection is then the run's, and the reading
        errs by the fingers' difference in creep alone.  0.4 was chosen at
        5 N, 40 °C; across the grid no weight per temperature stands out
        (the best scatters from 0 to 0.5 by condition and seed set).
    ref_s : float
        The chain counts from this hold time (s): before it the estimate is
        Eq. 10's, and at it the chain starts from Eq. 10's mean over the
        ``ref_window_s`` before.
    ref_window_s : float
        Length of that window (s).
    marker_m, contact_m : float
        Marker and contact positions along the finger (m) for the marker's
        share of the contact deflection; ``contact_m`` is the nominal one,
        taken when perception did not see the object.
    finger : FingerParams
        Finger constants for the beam model.
    min_compliant_share : float
        Below this share of the loading's travel left for the object
        (``1 - 2 rho / g``) the object's stiffness is not measurable (a
        rigid object): no chain reading.
    ir_weight : float
        The chain's share when the object was seen and the other finger is
        read in the infrared frame (1, the default: the reading replaces the
        marker's guess of the other finger's creep); 0 does not read it.  On
        twin v7 (its infrared pixels drawn by their area), the object
        located and the calibration measured so, 5 N, 40 °C held 0.0300 N
        on seeds 4000-4023 and 0.0375 N on 3000-3035 (v6, one marker:
        0.0445 and 0.0503 N), the estimate's spread over seeds 0.035 N.
        Drawn by pixel centre (twin v6) an outline moves only as it crosses
        a pixel centre, and the reading is too coarse
        (docs/hold-experiments.md, sessions 56 and 57).
    """

    weight: float = 0.2
    seen_weight: float = 0.4
    ref_s: float = 5.0
    ref_window_s: float = 1.0
    marker_m: float = 0.060
    contact_m: float = 0.080
    finger: FingerParams = field(default_factory=FingerParams)
    min_compliant_share: float = 0.1
    ir_weight: float = 1.0

    def __post_init__(self) -> None:
        for weight in (self.weight, self.seen_weight, self.ir_weight):
            if not 0.0 <= weight <= 1.0:
                raise ValueError(f"chain weight must be in [0, 1], got {weight}")
        if not (self.ref_s >= self.ref_window_s > 0):
            raise ValueError("the chain's reference window must be > 0 s and end at or after it, "
                             f"got {self.ref_window_s} s ending at {self.ref_s} s")
        if not 0.0 < self.marker_m < self.contact_m <= self.finger.length_m:
            raise ValueError(f"the marker ({self.marker_m} m) must sit between the root and the "
                             f"contact ({self.contact_m} m) on the finger")
        if not 0.0 < self.min_compliant_share < 1.0:
            raise ValueError(f"least compliant share must be in (0, 1), got "
                             f"{self.min_compliant_share}")


class ClosedChain:
    """One hold's chain reading, blended into the estimate it starts from.

    Call :meth:`start` at the hold onset with the loading's slopes, then
    :meth:`blend` every frame of the hold.
    """

    def __init__(self, params: ChainParams | None = None) -> None:
        self.params = params if params is not None else ChainParams()
        self.reset()

    def reset(self) -> None:
        """Forget the hold."""
        self.object_stiffness_n_per_mm = NAN
        self.share = NAN
        self.contact_m = NAN
        self.weight = NAN
        self.seen = False
        self._sums = [0.0, 0.0, 0.0]
        self._n = 0
        self._ref: tuple[float, float, float] | None = None
        self._share_temp_c = NAN
        self._deflection_m = NAN
        self._other_m = NAN
        self._other_ref_m = NAN
        self.reading_n = NAN

    @property
    def reads_other(self) -> bool:
        """Whether the other finger is read in the infrared frame (from the reference on)."""
        return math.isfinite(self._other_ref_m)

    def start(self, stiffness_n_per_mm: float, marker_per_mm_m: float, temp_c: float,
              contact_m: float = NAN) -> None:
        """The hold starts: the object's stiffness from the loading's slopes.

        Parameters
        ----------
        stiffness_n_per_mm : float
            The estimate's rise per millimetre of motor travel over the loading.
        marker_per_mm_m : float
            The marker's deflection per millimetre of motor travel (m/mm).
        temp_c : float
            The finger's temperature (°C) for the beam model; nan: no chain.
        contact_m : float
            Where perception saw the object along the fingers (m from the
            root); nan, or a place beyond the marker's reach, takes the
            nominal contact and weight.
        """
        self.reset()
        p = self.params
        seen = math.isfinite(contact_m) and p.marker_m < contact_m <= p.finger.length_m
        self.seen = seen
        self.contact_m = contact_m if seen else p.contact_m
        self.weight = p.seen_weight if seen else p.weight
        if self.weight == 0.0 or not math.isfinite(temp_c):
            return
        self.share = marker_share(p.marker_m, self.contact_m, temp_c, p.finger)
        self._share_temp_c = temp_c
        compliant = 1.0 - 2.0 * marker_per_mm_m * 1e3 / self.share
        if compliant >= p.min_compliant_share and stiffness_n_per_mm > 0:
            self.object_stiffness_n_per_mm = stiffness_n_per_mm / compliant

    def blend(self, hold_s: float, motor_mm: float, deflection_m: float | None,
              estimate_n: float, other_m: float | None = None,
              temp_c: float = NAN) -> float:
        """The estimate with the chain's reading blended in (N).

        Parameters
        ----------
        hold_s : float
            Time since the onset (s).
        motor_mm : float
            Encoder (mm).
        deflection_m : float or None
            The marker's deflection (m); None when the marker is not seen
            (the last one seen stands).
        estimate_n : float
            The estimate the chain starts from and is blended into (N).
        other_m : float or None
            The other finger's contact deflection read in an infrared frame
            just taken (m); None between frames (the last one stands).  Used
            when the object was seen and a reading stood when the chain
            started.
        temp_c : float
            The finger's temperature as now read (°C; nan: the last stands).
            The marker's share of the contact deflection follows it (0.625 at
            40 °C, 0.633 at 55 °C for a contact at 79.5 mm): through a ramp
            the finger's stiffness changes along it.

        ``reading_n`` keeps this frame's chain reading (N; nan if none).
        """
        if deflection_m is not None and math.isfinite(deflection_m):
            self._deflection_m = deflection_m
        if other_m is not None and math.isfinite(other_m):
            self._other_m = other_m
        p = self.params
        self.reading_n = NAN
        if (math.isfinite(temp_c) and math.isfinite(self.share)
                and abs(temp_c - self._share_temp_c) >= _SHARE_STEP_K):
            self.share = marker_share(p.marker_m, self.contact_m, temp_c, p.finger)
            self._share_temp_c = temp_c
        if not (math.isfinite(self.object_stiffness_n_per_mm) and math.isfinite(estimate_n)
                and math.isfinite(self._deflection_m)):
            return estimate_n
        if self._ref is None:
            if hold_s >= p.ref_s - p.ref_window_s:
                self._sums[0] += estimate_n
                self._sums[1] += motor_mm
                self._sums[2] += self._deflection_m
                self._n += 1
            if hold_s < p.ref_s or self._n == 0:
                return estimate_n
            f_ref, m_ref, x_ref = (s / self._n for s in self._sums)
            # The marker finger's contact deflection at the reference (mm).
            self._ref = (f_ref, m_ref, x_ref * 1e3 / self.share)
            if self.seen and math.isfinite(self._other_m) and p.ir_weight > 0:
                self._other_ref_m = self._other_m
                self.weight = p.ir_weight
        f_ref, m_ref, c_ref = self._ref
        marker_mm = self._deflection_m * 1e3 / self.share - c_ref
        if math.isfinite(self._other_ref_m):
            fingers_mm = marker_mm + (self._other_m - self._other_ref_m) * 1e3
        else:
            fingers_mm = 2.0 * marker_mm
        self.reading_n = f_ref + self.object_stiffness_n_per_mm * (motor_mm - m_ref - fingers_mm)
        return (1.0 - self.weight) * estimate_n + self.weight * self.reading_n
