"""The temperature loop: infrared beam temperatures in, heater duty (the L298N's PWM) out.

One PID per finger on what the infrared camera reads of it (the finger's mean
over its top face, or the tip beams for the adhesive pads), with a
feed-forward duty from the heat model; the stiffness modes of the paper are
named setpoints.  Three guards come before any control:

* **over-temperature**: a finger whose hottest reading passes
  :attr:`ThermalLimits.max_temp_c` gets no power until it has cooled
  :attr:`ThermalLimits.hysteresis_k` below the limit;
* **stale infrared**: with no infrared frame for more than
  :attr:`ThermalLimits.stale_after_s`, every heater is off (a loop that cannot
  see the temperature must not heat); a frame stamped in the future or not
  at all counts as none;
* **heater fault** (thermal runaway protection, as 3D printers have it): a
  heater driven at :attr:`ThermalLimits.fault_duty` or more for
  :attr:`ThermalLimits.fault_window_s` whose finger's reading has not risen
  :attr:`ThermalLimits.fault_min_rise_k` is taken as a broken heater, a
  frozen camera or a camera that sees something else, and every heater
  stays off until a setpoint is given again.  At full duty a finger at
  ambient warms about 25 K in that time (:class:`ThermalLimits`).

The PID runs when a new infrared frame arrives (1 Hz) and its duty is held
between frames.

**Occlusion.** A grasped object stands between the camera and the finger's
distal beams: a room-temperature ball makes them read 26-30 °C while the rest
of a 55 °C finger reads 55-57 °C, and a loop regulating the face's mean would
heat the finger 4 K above its setpoint to make up for it.  A beam that reads
closer to the background than to the finger's warmest beam is taken as
covered (:func:`covered_beams`); while any is, the reading is the last
uncovered mean moved by the median change of the other beams since (a beam
the object only half covers drops too, and the median passes over it).
"""

from __future__ import annotations

import enum
import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

from relaxgrip.control.pid import PID, PIDGains
from relaxgrip.errors import InputError
from relaxgrip.limits import OUR_LIMITS, LimitsSpec
from relaxgrip.perception.thermal import FingerThermal, ThermalFeatures, covered_beams
from relaxgrip.physics.thermal import HeatParams, duty_for_mean_temp

__all__ = [
    "MODE_SETPOINTS_C",
    "StiffnessMode",
    "TemperatureLoop",
    "TemperatureStatus",
    "ThermalLimits",
    "fresh",
]


class StiffnessMode(enum.StrEnum):
    """The paper's stiffness modes (§III, Fig. "modes")."""

    COMPLIANT = "compliant"
    MEDIUM = "medium"
    STIFF = "stiff"
    ADHESIVE = "adhesive"


#: Setpoint of each mode (°C; ``None``: heaters off, the fingers cool to ambient).
#: Compliant and medium sit either side of Tg ≈ 48 °C; the adhesive mode heats
#: the pads at the fingertips well past their activation.
MODE_SETPOINTS_C: dict[StiffnessMode, float | None] = {
    StiffnessMode.COMPLIANT: 58.0,
    StiffnessMode.MEDIUM: 40.0,
    StiffnessMode.STIFF: None,
    StiffnessMode.ADHESIVE: 58.0,
}


class TemperatureStatus(enum.StrEnum):
    """Why the heaters have the duty they have."""

    OFF = "off"
    """No setpoint (stiff mode, or stopped)."""
    REGULATING = "regulating"
    """The PID drives both heaters."""
    OVER_TEMPERATURE = "over_temperature"
    """At least one finger is cut off above the limit."""
    STALE = "stale"
    """No recent infrared frame: all heaters off."""
    HEATER_FAULT = "heater_fault"
    """A heater drove hard and its finger did not warm: all heaters off until a new setpoint."""
    HELD_OFF = "held_off"
    """The controller holds the heaters off while it cannot read the force (marker lost)."""


@dataclass(frozen=True)
class ThermalLimits:
    """Safety limits of the temperature loop.

    Attributes
    ----------
    max_temp_c : float
        Hottest reading allowed on a finger (°C); above it the heater is off
        (the rig's :class:`~relaxgrip.limits.LimitsSpec`, see :meth:`for_rig`).
    hysteresis_k : float
        How far below the limit a finger must cool before heating again (K).
    stale_after_s : float
        Infrared age beyond which every heater is off (s).
    min_setpoint_c, max_setpoint_c : float
        Setpoints accepted (°C).
    fault_duty, fault_window_s, fault_min_rise_k : float
        Heater fault: a duty at or above ``fault_duty`` held for
        ``fault_window_s`` with the finger's reading risen less than
        ``fault_min_rise_k`` (defaults: 0.8, 60 s, 2 K; the default heat model
        warms a finger at ambient by about 25 K in 60 s at duty 1).
    """

    max_temp_c: float = OUR_LIMITS.max_temp_c
    hysteresis_k: float = 2.0
    stale_after_s: float = 3.0
    min_setpoint_c: float = OUR_LIMITS.min_setpoint_c
    max_setpoint_c: float = OUR_LIMITS.max_setpoint_c
    fault_duty: float = 0.8
    fault_window_s: float = 60.0
    fault_min_rise_k: float = 2.0

    def __post_init__(self) -> None:
        if not self.min_setpoint_c < self.max_setpoint_c < self.max_temp_c:
            raise InputError("temperature limits must satisfy min setpoint < max setpoint < "
                             f"cut-off, got {self.min_setpoint_c}, {self.max_setpoint_c}, "
                             f"{self.max_temp_c}")
        if not (self.hysteresis_k >= 0 and self.stale_after_s > 0):
            raise InputError("hysteresis must be >= 0 K and the stale age > 0 s")
        if not (0 < self.fault_duty <= 1 and self.fault_window_s > 0
                and self.fault_min_rise_k > 0):
            raise InputError("the heater fault needs a duty in (0, 1], a window > 0 s and a "
                             "rise > 0 K")

    @classmethod
    def for_rig(cls, limits: LimitsSpec) -> ThermalLimits:
        """The loop's limits with a rig's cut-off and setpoint range (the rest the defaults)."""
        return cls(max_temp_c=limits.max_temp_c, min_setpoint_c=limits.min_setpoint_c,
                   max_setpoint_c=limits.max_setpoint_c)

    def check_setpoint(self, temp_c: float) -> float:
        """Return ``temp_c`` if it is a setpoint the loop accepts."""
        if not (math.isfinite(temp_c) and self.min_setpoint_c <= temp_c <= self.max_setpoint_c):
            raise InputError(f"temperature setpoint {temp_c} °C is outside the safe range "
                             f"{self.min_setpoint_c:g}-{self.max_setpoint_c:g} °C")
        return float(temp_c)


#: How far ahead of the loop's clock a frame's stamp may be (s): more is a clock
#: fault, and the frame counts as none.
_FUTURE_S = 0.5


def fresh(frame_t_s: float, t_s: float, stale_after_s: float) -> bool:
    """Whether a frame stamped ``frame_t_s`` is current at ``t_s`` on the loop's clock.

    It is if its stamp is finite, at most ``stale_after_s`` old and not ahead
    of the clock by more than a clock's jitter: a frame stamped far ahead is a
    clock fault, which would otherwise read as fresh until the clock caught up.
    """
    return math.isfinite(frame_t_s) and -_FUTURE_S <= t_s - frame_t_s <= stale_after_s

#: Default gains: duty per kelvin, per kelvin-second.  A finger heats with a time
#: constant of about 2.5 min and about 80 K per unit duty (the default heat
#: model); these give a closed loop of about 20 s with the feed-forward doing
#: the bulk of the work.
DEFAULT_GAINS = PIDGains(kp=0.08, ki=0.002, kd=0.0, out_min=0.0, out_max=1.0)


class TemperatureLoop:
    """Heater duties from infrared features.

    Parameters
    ----------
    heat : HeatParams
        Heat model of a finger, for the feed-forward duty (the rig's, or the
        twin's defaults).
    limits : ThermalLimits
        Safety limits.
    gains : PIDGains
        PID gains (output: duty in [0, 1]).
    """

    def __init__(self, heat: HeatParams | None = None, limits: ThermalLimits | None = None,
                 gains: PIDGains = DEFAULT_GAINS) -> None:
        self.heat = heat if heat is not None else HeatParams()
        self.limits = limits if limits is not None else ThermalLimits()
        self._pids = (PID(gains), PID(gains))
        self.mode: StiffnessMode | None = StiffnessMode.STIFF
        self.setpoint_c: float | None = None
        self.status = TemperatureStatus.OFF
        self._cut = [False, False]
        self.fault: str | None = None
        """Why the heaters are latched off (a heater fault), or None."""
        # Per finger: since when its heater drives hard, and its reading then.
        self._driving: list[tuple[float, float] | None] = [None, None]
        self._duty = (0.0, 0.0)
        self._last_ir_t: float | None = None
        self._seen_t: float | None = None
        # Per finger, the latest frame with no beam covered: its mean and its beams.
        self._clear: list[tuple[float, tuple[float, ...]] | None] = [None, None]
        # Per finger, its beams in the last frame before the fingers closed on an object.
        self._open_beams: list[tuple[float, ...] | None] = [None, None]
        self._grasping = False

    def check_mode(self, mode: StiffnessMode | str) -> tuple[StiffnessMode, float | None]:
        """The mode named and its setpoint, if the limits' setpoint range takes it."""
        try:
            chosen = StiffnessMode(mode)
        except ValueError:
            known = ", ".join(m.value for m in StiffnessMode)
            raise InputError(f"unknown stiffness mode {mode!r}; known: {known}") from None
        setpoint = MODE_SETPOINTS_C[chosen]
        if setpoint is not None:
            self.limits.check_setpoint(setpoint)
        return chosen, setpoint

    def set_mode(self, mode: StiffnessMode | str) -> None:
        """Switch to a stiffness mode's setpoint (within the limits' setpoint range)."""
        self.mode, setpoint = self.check_mode(mode)
        self._set(setpoint)

    def set_temperature(self, temp_c: float | None) -> None:
        """Hold the fingers at ``temp_c`` (°C); ``None`` switches the heaters off."""
        if temp_c is not None:
            self.limits.check_setpoint(temp_c)
        self.mode = None
        self._set(temp_c)

    def _set(self, temp_c: float | None) -> None:
        self.fault = None  # a setpoint given (again) after a fault is the operator's call
        self._driving = [None, None]
        if temp_c is None:
            self.status = TemperatureStatus.OFF  # at once: shown before the next frame
        if temp_c != self.setpoint_c:
            self.setpoint_c = temp_c
            self._last_ir_t = None  # re-seed the integrators on the next frame

    def hold_off(self) -> None:
        """The caller keeps the heaters off this period (the controller, blind to the force).

        The status says so; the heater-fault watch and the integrators start
        again afresh when heating resumes (the heaters were not driven at the
        duty the loop computed, so a finger that did not warm meanwhile is no
        fault).
        """
        self._driving = [None, None]
        self._last_ir_t = None
        self._duty = (0.0, 0.0)
        if self.setpoint_c is not None and self.fault is None:
            self.status = TemperatureStatus.HELD_OFF

    def reading_c(self, finger: FingerThermal) -> float:
        """A finger seen whole: the pads (tip beams) if adhesive, else the mean (°C)."""
        return self._of(finger.beam_temps_c, finger.mean_c)

    def _of(self, beams: tuple[float, ...], mean_c: float) -> float:
        """What the loop regulates of a finger with these beams and this mean (°C)."""
        if self.mode is StiffnessMode.ADHESIVE:
            tip = [b for b in beams[-2:] if math.isfinite(b)]
            if tip:
                return sum(tip) / len(tip)
        return mean_c

    def set_grasping(self, grasping: bool) -> None:
        """Whether the fingers are closing on or holding an object (the controller's phases).

        The adhesive pads are the tip beams, the first an object covers, and
        covers in part before :func:`covered_beams` tells it (a ball at the
        tips read 46-49 °C there against 57 °C before it, with the finger's
        warmest beam at 60 °C).  While grasping, they are read as they were
        in the last frame that showed them before the fingers closed, moved by
        the median change of the proximal beams since.
        """
        self._grasping = grasping

    def readings_c(self, thermal: ThermalFeatures) -> tuple[float, ...]:
        """What the loop regulates of each finger, covered beams made up for (°C).

        Where an object covers beams of a finger (module notes), its reading is
        that of the latest frame with nothing covered (the mean, or the tip
        beams for the adhesive pads, which a grasped object covers first),
        moved by the median change of the beams visible in both; before any
        such frame, the mean of the visible beams (their tip ones if adhesive).
        """
        out = []
        for j, finger in enumerate(thermal.fingers):
            pads = self._pads_while_grasping(j, finger.beam_temps_c)
            if pads is not None:
                out.append(pads)
                continue
            covered = covered_beams(finger.beam_temps_c, thermal.background_c)
            if not any(covered):
                out.append(self.reading_c(finger))
                continue
            clear = self._clear[j] if j < len(self._clear) else None
            now = finger.beam_temps_c
            if clear is None:
                seen = tuple(b if not c else math.nan for b, c in zip(now, covered, strict=True))
                visible = [b for b in seen if math.isfinite(b)]
                out.append(self._of(seen, sum(visible) / len(visible)))
                continue
            mean_c, then = clear
            out.append(self._of(then, mean_c) + _median_change(now, then, covered))
        return tuple(out)

    def _pads_while_grasping(self, j: int, beams: tuple[float, ...]) -> float | None:
        """The adhesive pads' reading while grasping (:meth:`set_grasping`), else None."""
        before = self._open_beams[j] if j < len(self._open_beams) else None
        if self.mode is not StiffnessMode.ADHESIVE or not self._grasping or before is None:
            return None
        tip = [b for b in before[-2:] if math.isfinite(b)]
        if not tip:
            return None
        proximal = (False,) * (len(beams) - 2) + (True, True)
        return sum(tip) / len(tip) + _median_change(beams, before, proximal)

    def _remember_clear(self, thermal: ThermalFeatures) -> None:
        """Keep each finger's latest uncovered frame (once per infrared frame)."""
        if thermal.t_s == self._seen_t:
            return
        self._seen_t = thermal.t_s
        if not self._grasping:
            for j, finger in enumerate(thermal.fingers[: len(self._open_beams)]):
                # Only a frame that shows the pads and a proximal beam: one out of view just
                # before the fingers close would leave the pads read as the object covers them.
                beams = finger.beam_temps_c
                if (any(math.isfinite(b) for b in beams[-2:])
                        and any(math.isfinite(b) for b in beams[:-2])):
                    self._open_beams[j] = tuple(beams)
        for j, finger in enumerate(thermal.fingers[: len(self._clear)]):
            if math.isfinite(finger.mean_c) and not any(
                    covered_beams(finger.beam_temps_c, thermal.background_c)):
                self._clear[j] = (finger.mean_c, tuple(finger.beam_temps_c))

    def update(self, thermal: ThermalFeatures | None, t_s: float) -> tuple[float, float]:
        """Heater duties at ``t_s`` given the latest infrared features.

        Parameters
        ----------
        thermal : ThermalFeatures or None
            The latest infrared features (the same object again between frames).
        t_s : float
            Current time on the loop's clock (s).

        Returns
        -------
        tuple of float
            Duty of each finger's heater, in [0, 1].
        """
        if thermal is None or not fresh(thermal.t_s, t_s, self.limits.stale_after_s):
            self.status = TemperatureStatus.STALE if self.setpoint_c is not None else \
                TemperatureStatus.OFF
            self._duty = (0.0, 0.0)
            self._last_ir_t = None
            self._driving = [None, None]
            return self._duty
        self._remember_clear(thermal)
        for j, finger in enumerate(thermal.fingers):
            hottest = finger.max_c
            if math.isfinite(hottest):
                if hottest > self.limits.max_temp_c:
                    self._cut[j] = True
                elif hottest < self.limits.max_temp_c - self.limits.hysteresis_k:
                    self._cut[j] = False
        if self.setpoint_c is None:
            self.status = TemperatureStatus.OFF
            self._duty = (0.0, 0.0)
            return self._duty
        if self.fault is not None:
            self.status = TemperatureStatus.HEATER_FAULT
            return 0.0, 0.0
        new_frame = thermal.t_s != self._last_ir_t
        if new_frame:
            self._duty = self._regulate(thermal, self.setpoint_c)
        duties = tuple(0.0 if cut else d for cut, d in zip(self._cut, self._duty, strict=True))
        fault = self._watch(thermal, duties) if new_frame else None  # readings change per frame
        if fault is not None:
            self.fault, self.status = fault, TemperatureStatus.HEATER_FAULT
            self._duty = (0.0, 0.0)
            return self._duty
        self.status = (TemperatureStatus.OVER_TEMPERATURE if any(self._cut)
                       else TemperatureStatus.REGULATING)
        return duties[0], duties[1]

    def _watch(self, thermal: ThermalFeatures, duties: tuple[float, ...]) -> str | None:
        """A heater fault to latch: a finger driven hard that does not warm (module notes)."""
        lim = self.limits
        for j, (duty, reading) in enumerate(zip(duties, self.readings_c(thermal), strict=False)):
            if duty < lim.fault_duty or not math.isfinite(reading):
                self._driving[j] = None
                continue
            since = self._driving[j]
            if since is None:
                self._driving[j] = (thermal.t_s, reading)
            elif thermal.t_s - since[0] >= lim.fault_window_s:
                if reading - since[1] < lim.fault_min_rise_k:
                    return (f"heater {j} drove {duty:.2f} duty for {thermal.t_s - since[0]:.0f} "
                            f"s and its finger read {reading - since[1]:+.1f} K: a broken "
                            "heater or a camera that does not see the finger")
                self._driving[j] = (thermal.t_s, reading)  # warming: watch the next window
        return None

    def _regulate(self, thermal: ThermalFeatures, setpoint_c: float) -> tuple[float, float]:
        ambient = thermal.background_c if math.isfinite(thermal.background_c) else 25.0
        feedforward = duty_for_mean_temp(setpoint_c, self.heat, ambient)
        first = self._last_ir_t is None
        dt = 1.0 if first else max(thermal.t_s - (self._last_ir_t or 0.0), 1e-3)
        self._last_ir_t = thermal.t_s
        out = []
        for pid, reading in zip(self._pids, self.readings_c(thermal), strict=True):
            if first:
                pid.reset(0.0)  # out of view or not: its integral is of the old setpoint
            if not math.isfinite(reading):
                out.append(0.0)  # a finger out of view is not heated blind
                continue
            # The PID corrects around the feed-forward; its limits keep the sum in [0, 1].
            pid.gains = _shifted(pid.gains, feedforward)
            out.append(feedforward + pid.update(setpoint_c, reading, dt))
        return out[0], out[1]


def _median_change(now: Sequence[float], then: Sequence[float], skip: Sequence[bool]) -> float:
    """The median change of the beams since ``then``, the ``skip`` ones left out (K).

    The median, for a beam an object half covers drops with it, not with the finger.
    NaN if no beam is seen in both: a finger out of view now is not read as it
    was then (its heater would be driven blind, past the over-temperature cut).
    """
    moved = [b - a for b, a, s in zip(now, then, skip, strict=True)
             if not s and math.isfinite(b) and math.isfinite(a)]
    return statistics.median(moved) if moved else math.nan


def _shifted(gains: PIDGains, feedforward: float) -> PIDGains:
    """Gains whose output limits leave ``feedforward + output`` within [0, 1]."""
    lo, hi = -feedforward, 1.0 - feedforward
    if gains.out_min == lo and gains.out_max == hi:
        return gains
    return PIDGains(gains.kp, gains.ki, gains.kd, lo, hi, gains.derivative_tau_s, gains.rate_limit)
