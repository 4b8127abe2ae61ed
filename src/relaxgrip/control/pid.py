"""A discrete PID controller with time injected (after simple-pid's ``dt`` habit).

Derivative on the measurement (no kick when the setpoint steps), through a
first-order low-pass filter; the integral is clamped by back-calculation so it
never winds up against the output limits; the output is limited in value and
optionally in rate.  ``update`` takes ``dt``: nothing here reads a clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from relaxgrip.errors import InputError

__all__ = ["PID", "PIDGains"]


@dataclass(frozen=True)
class PIDGains:
    """Gains and limits of a :class:`PID`.

    Attributes
    ----------
    kp : float
        Proportional gain (output per unit of error).
    ki : float
        Integral gain (output per unit of error and second).
    kd : float
        Derivative gain (output per unit of error rate, s).
    out_min, out_max : float
        Output limits.
    derivative_tau_s : float
        Time constant of the derivative's low-pass filter (s).
    rate_limit : float
        Largest output change per second (``inf``: none).
    """

    kp: float
    ki: float = 0.0
    kd: float = 0.0
    out_min: float = -math.inf
    out_max: float = math.inf
    derivative_tau_s: float = 0.1
    rate_limit: float = math.inf

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"PID gain {name} must be finite and >= 0, got {value}")
        if not self.out_min < self.out_max:
            raise InputError(f"PID output limits must satisfy min < max, got "
                             f"[{self.out_min}, {self.out_max}]")
        if not self.derivative_tau_s >= 0:
            raise InputError(f"derivative filter time must be >= 0 s, got {self.derivative_tau_s}")
        if not self.rate_limit > 0:
            raise InputError(f"output rate limit must be > 0, got {self.rate_limit}")


class PID:
    """PID with anti-windup, filtered derivative on the measurement, output limits.

    Parameters
    ----------
    gains : PIDGains
        Gains and limits.

    Notes
    -----
    ``u = kp e + I - kd dy_f/dt`` with ``e = setpoint - measurement`` and
    ``dy_f`` the filtered measurement.  After limiting, the integral is moved
    back by the part of ``u`` the output limits cut off (back-calculation), so
    it holds what the output can actually deliver; with ``ki = 0`` it stays
    where :meth:`reset` put it.  While the rate limit holds the output back,
    the integral does not change.
    """

    def __init__(self, gains: PIDGains) -> None:
        self.gains = gains
        self.reset()

    def reset(self, output: float = 0.0) -> None:
        """Forget the history; the integral starts so that the output is ``output``."""
        self.integral = min(max(output, self.gains.out_min), self.gains.out_max)
        self._y_filtered: float | None = None
        self.derivative = 0.0
        self.output = self.integral

    def update(self, setpoint: float, measurement: float, dt_s: float) -> float:
        """One control step.

        Parameters
        ----------
        setpoint, measurement : float
            Desired and measured value (same unit).
        dt_s : float
            Time since the previous update (s, > 0).

        Returns
        -------
        float
            The limited output.

        Raises
        ------
        ValueError
            If ``dt_s`` is not finite and > 0, or the setpoint or the measurement
            is not finite (the filtered measurement would keep a nan, and every
            later output with it).
        """
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"PID step must be > 0 s, got {dt_s}")
        if not (math.isfinite(setpoint) and math.isfinite(measurement)):
            raise ValueError(f"PID setpoint and measurement must be finite, got {setpoint} "
                             f"and {measurement}")
        g = self.gains
        error = setpoint - measurement
        if self._y_filtered is None:
            self._y_filtered = measurement
            self.derivative = 0.0
        else:
            alpha = dt_s / (g.derivative_tau_s + dt_s)
            previous = self._y_filtered
            self._y_filtered = previous + alpha * (measurement - previous)
            self.derivative = (self._y_filtered - previous) / dt_s
        integral = self.integral + g.ki * error * dt_s
        raw = g.kp * error + integral - g.kd * self.derivative
        bounded = min(max(raw, g.out_min), g.out_max)
        step = g.rate_limit * dt_s
        limited = min(max(bounded, self.output - step), self.output + step)
        if limited == bounded and g.ki > 0:
            # Back-calculation: the integral keeps only what the limits let through.  (With
            # ki = 0 there is no integral to wind up: moved back, it would stay an offset.)
            back = integral + bounded - raw
            if not math.isnan(back):  # inf - inf: gains so large that the terms overflowed
                self.integral = min(max(back, g.out_min), g.out_max)
        # Rate-limited: the integral waits, for the output is still on its way (taking
        # the cut into the integral would hold the output where the ramp began).
        self.output = limited
        return limited
