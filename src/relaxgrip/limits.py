"""One set of safety limits: force, temperature, duty, speed and travel.

A rig file's ``[limits]`` table becomes a :class:`LimitsSpec`; the twin's
gripper (ours) has the defaults, :data:`OUR_LIMITS`, and nowhere else in the
code are these numbers written.  Every entry point checks against the rig's
one object: the command line (``hold --target-n``, ``--temp-c``, the
profiles), the dashboard's controls, the Python API (:class:`GraspPlan
<relaxgrip.control.GraspPlan>`, the controller's and the temperature loop's
setters), the host's commands to the MCU (clamped) and the MCU's own
configuration (its velocity limit may not exceed the rig's).

Each ``check_*`` method returns the cleaned value or raises
:class:`~relaxgrip.errors.InputError` with one line naming the value and the
range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from relaxgrip.errors import InputError

__all__ = ["OUR_LIMITS", "LimitsSpec"]


@dataclass(frozen=True)
class LimitsSpec:
    """Safety limits of one gripper (a rig file's ``[limits]``).

    Attributes
    ----------
    max_target_n : float
        Largest force target accepted (N): the paper's range is 0-10 N.
    max_force_n : float
        Force limit (N): an estimate beyond it, either way (``|F| >
        max_force_n``), is a fault: the grasp stops, motor stopped and heaters
        off.  Above ``max_target_n``, so that regulating to the largest target
        does not trip it.
    min_setpoint_c, max_setpoint_c : float
        Finger temperature setpoints accepted (°C): from a few kelvin above the
        ambient (the heaters cannot cool) to below ``max_temp_c``.
    max_temp_c : float
        Hottest finger temperature allowed on the infrared image (°C): above
        it the grasp stops and the heaters go off.
    heater_duty_limit : float
        Largest heater duty commanded (0..1).
    max_motor_speed_mm_s : float
        Largest motor speed commanded (mm/s); the MCU's own limit may not be
        higher.
    stroke_mm : float
        Motor travel from fully open (mm): the fingers never close past it.
    """

    max_target_n: float = 10.0
    max_force_n: float = 12.0
    min_setpoint_c: float = 28.0
    max_setpoint_c: float = 65.0
    max_temp_c: float = 70.0
    heater_duty_limit: float = 1.0
    max_motor_speed_mm_s: float = 20.0
    stroke_mm: float = 148.0

    def __post_init__(self) -> None:
        for name in ("max_target_n", "max_force_n", "min_setpoint_c", "max_setpoint_c",
                     "max_temp_c", "heater_duty_limit", "max_motor_speed_mm_s", "stroke_mm"):
            if not math.isfinite(getattr(self, name)):
                raise InputError(f"limits: {name} must be finite, got {getattr(self, name)}")
        if not 0.0 < self.max_target_n < self.max_force_n:
            raise InputError("limits: need 0 < max_target_n < max_force_n, got "
                             f"{self.max_target_n:g} and {self.max_force_n:g} N")
        if not self.min_setpoint_c < self.max_setpoint_c < self.max_temp_c:
            raise InputError("limits: need min_setpoint_c < max_setpoint_c < max_temp_c, got "
                             f"{self.min_setpoint_c:g}, {self.max_setpoint_c:g} and "
                             f"{self.max_temp_c:g} °C")
        if not 0.0 <= self.heater_duty_limit <= 1.0:
            raise InputError(f"limits: heater_duty_limit must be in 0..1, got "
                             f"{self.heater_duty_limit:g}")
        if not (self.max_motor_speed_mm_s > 0.0 and self.stroke_mm > 0.0):
            raise InputError("limits: max_motor_speed_mm_s and stroke_mm must be > 0")

    def for_motor(self, stroke_mm: float, max_speed_mm_s: float) -> LimitsSpec:
        """These limits on a gripper with this motor: its travel is the motor's stroke and
        the speed limit at most the motor's top speed (the rule a rig file's ``[limits]``
        follows for the keys it leaves out)."""
        return replace(self, stroke_mm=stroke_mm,
                       max_motor_speed_mm_s=min(self.max_motor_speed_mm_s, max_speed_mm_s))

    def check_target_n(self, value: float, name: str = "target force") -> float:
        """Return a force target (N) if it is within (0, ``max_target_n``]."""
        v = float(value)
        if not (math.isfinite(v) and 0.0 < v <= self.max_target_n):
            raise InputError(f"{name} {value} N is outside (0, {self.max_target_n:g}] N")
        return v

    def force_in_range(self, force_n: float) -> bool:
        """Whether an estimate (N) is within the force limit (NaN is not: no reading)."""
        return abs(force_n) <= self.max_force_n

    def check_setpoint_c(self, value: float, name: str = "temperature setpoint") -> float:
        """Return a temperature setpoint (°C) if it is within the setpoint range."""
        v = float(value)
        if not (math.isfinite(v) and self.min_setpoint_c <= v <= self.max_setpoint_c):
            raise InputError(f"{name} {value} °C is outside the safe range "
                             f"{self.min_setpoint_c:g}-{self.max_setpoint_c:g} °C")
        return v

    def check_duty(self, value: float, name: str = "heater duty") -> float:
        """Return a heater duty if it is within 0..``heater_duty_limit``."""
        v = float(value)
        if not (math.isfinite(v) and 0.0 <= v <= self.heater_duty_limit):
            raise InputError(f"{name} {value} is outside 0-{self.heater_duty_limit:g}")
        return v

    def check_speed_mm_s(self, value: float, name: str = "motor speed") -> float:
        """Return a motor speed (mm/s, either sign) if its size is within the speed limit."""
        v = float(value)
        if not (math.isfinite(v) and abs(v) <= self.max_motor_speed_mm_s):
            raise InputError(f"{name} {value} mm/s is beyond the rig's limit of "
                             f"{self.max_motor_speed_mm_s:g} mm/s")
        return v

    def check_mcu_speed_mm_s(self, mcu_limit_mm_s: float) -> float:
        """Return the MCU's own velocity limit (mm/s) if it is not above the rig's.

        The MCU's clamp is the last guard of the motor's speed: one set higher
        than the rig allows would let a host's mistake through.
        """
        if not mcu_limit_mm_s <= self.max_motor_speed_mm_s:
            raise InputError(f"the MCU's velocity limit {mcu_limit_mm_s:g} mm/s is above the "
                             f"rig's [limits] max_motor_speed_mm_s {self.max_motor_speed_mm_s:g}"
                             " mm/s: flash the MCU with the rig's limit or raise the limit")
        return mcu_limit_mm_s

    def check_travel_mm(self, value: float, name: str = "motor position") -> float:
        """Return a motor position (mm from fully open) if it is within 0..``stroke_mm``."""
        v = float(value)
        if not (math.isfinite(v) and 0.0 <= v <= self.stroke_mm):
            raise InputError(f"{name} {value} mm is outside the stroke 0-{self.stroke_mm:g} mm")
        return v

    def clamp(self, velocity_mm_s: float, duty: tuple[float, float]
              ) -> tuple[float, tuple[float, float]]:
        """A command brought within the speed and duty limits (NaN becomes 0: stopped, off)."""
        vmax, dmax = self.max_motor_speed_mm_s, self.heater_duty_limit
        v = 0.0 if math.isnan(velocity_mm_s) else min(max(velocity_mm_s, -vmax), vmax)
        d = tuple(0.0 if math.isnan(x) else min(max(x, 0.0), dmax) for x in duty)
        return v, (d[0], d[1])


#: Our gripper's limits: the twin's, and the defaults of a rig file's ``[limits]``.
OUR_LIMITS = LimitsSpec()
