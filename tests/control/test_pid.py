"""The PID: limits, anti-windup, derivative on the measurement, injected time."""

from __future__ import annotations

import math

import pytest

from relaxgrip.control.pid import PID, PIDGains
from relaxgrip.errors import InputError


def integrate(pid: PID, setpoint: float, y0: float, steps: int, dt: float = 0.02,
              gain: float = 1.0) -> list[float]:
    """An integrating plant dy/dt = gain * u, like force under a velocity command."""
    y, out = y0, []
    for _ in range(steps):
        y += gain * pid.update(setpoint, y, dt) * dt
        out.append(y)
    return out


def test_pi_on_an_integrator_settles_on_the_setpoint():
    pid = PID(PIDGains(kp=2.0, ki=0.5))
    ys = integrate(pid, 5.0, 0.0, 1000)
    assert ys[-1] == pytest.approx(5.0, abs=0.01)
    assert max(ys) < 5.5  # no wild overshoot


def test_output_stays_within_limits():
    pid = PID(PIDGains(kp=10.0, ki=5.0, out_min=-1.0, out_max=2.0))
    outs = [pid.update(100.0, 0.0, 0.05) for _ in range(50)]
    outs += [pid.update(-100.0, 0.0, 0.05) for _ in range(50)]
    assert max(outs) == 2.0
    assert min(outs) == -1.0


def test_anti_windup_recovers_at_once_after_saturation():
    gains = PIDGains(kp=1.0, ki=1.0, out_min=-1.0, out_max=1.0)
    pid = PID(gains)
    for _ in range(1000):  # 100 s against the limit
        pid.update(10.0, 0.0, 0.1)
    assert pid.integral <= gains.out_max
    # The error changes sign: the output follows within one step instead of
    # unwinding a huge integral for tens of seconds.
    assert pid.update(-10.0, 0.0, 0.1) < 0.0


def test_no_derivative_kick_on_a_setpoint_step():
    pid = PID(PIDGains(kp=0.0, kd=1.0))
    pid.update(0.0, 1.0, 0.01)
    assert pid.update(50.0, 1.0, 0.01) == 0.0  # the measurement did not move


def test_derivative_acts_on_the_filtered_measurement():
    pid = PID(PIDGains(kp=0.0, kd=1.0, derivative_tau_s=0.1))
    pid.update(0.0, 0.0, 0.01)
    first = pid.update(0.0, 1.0, 0.01)  # a unit jump of the measurement
    assert first < 0.0
    assert abs(first) < 1.0 / 0.01  # filtered: far below the raw difference quotient


def test_rate_limit_bounds_the_output_change_per_second():
    pid = PID(PIDGains(kp=100.0, out_min=-10, out_max=10, rate_limit=2.0))
    outs = [pid.update(1.0, 0.0, 0.1) for _ in range(5)]
    assert outs == pytest.approx([0.2, 0.4, 0.6, 0.8, 1.0])


def test_a_rate_limited_output_ramps_to_where_the_gains_put_it():
    # P only: the ramp ends at kp * error, not where it began.
    pid = PID(PIDGains(kp=1.0, rate_limit=1.0))
    outs = [pid.update(10.0, 0.0, 0.1) for _ in range(150)]
    assert outs[:3] == pytest.approx([0.1, 0.2, 0.3])
    assert outs[-1] == pytest.approx(10.0)
    assert pid.integral == 0.0


def test_the_integral_waits_while_the_rate_limit_holds_the_output():
    # Integrated through the ramp, the error would push the output past kp * error after it.
    pid = PID(PIDGains(kp=1.0, ki=1.0, out_min=-20, out_max=20, rate_limit=1.0))
    outs = [pid.update(5.0, 0.0, 0.1) for _ in range(10)]
    assert outs == pytest.approx([0.1 * k for k in range(1, 11)])
    assert pid.integral == 0.0
    pid.update(5.0, 4.05, 0.1)  # the measurement catches up: within the rate limit
    assert pid.integral == pytest.approx(0.095)


def test_time_is_injected_and_checked():
    pid = PID(PIDGains(kp=1.0, ki=1.0))
    a = [pid.update(1.0, 0.0, 0.5) for _ in range(4)]
    pid.reset()
    b = [pid.update(1.0, 0.0, 0.5) for _ in range(4)]
    assert a == b  # nothing depends on the wall clock
    with pytest.raises(ValueError, match="step"):
        pid.update(1.0, 0.0, 0.0)


def test_reset_starts_from_a_given_output():
    pid = PID(PIDGains(kp=0.0, ki=1.0, out_min=-5, out_max=5))
    pid.reset(3.0)
    assert pid.update(0.0, 0.0, 0.1) == pytest.approx(3.0)


@pytest.mark.parametrize("bad", [
    {"kp": -1.0}, {"kp": math.nan}, {"kp": 1.0, "ki": -0.1},
    {"kp": 1.0, "out_min": 1.0, "out_max": 1.0}, {"kp": 1.0, "rate_limit": 0.0},
    {"kp": 1.0, "derivative_tau_s": -1.0},
])
def test_bad_gains_are_refused(bad):
    with pytest.raises(InputError):
        PIDGains(**bad)


def test_a_p_only_pid_keeps_no_offset_after_saturating():
    # ki = 0: nothing to wind up; back-calculation used to leave -1 in the integral, and the
    # output then had the wrong sign for a small positive error and -1 at zero error.
    pid = PID(PIDGains(kp=1.0, out_min=-1.0, out_max=1.0))
    assert pid.update(10.0, 0.0, 0.1) == 1.0
    assert pid.update(0.5, 0.0, 0.1) == pytest.approx(0.5)
    assert pid.update(0.0, 0.0, 0.1) == 0.0
    assert pid.integral == 0.0


@pytest.mark.parametrize(("setpoint", "measurement", "dt"), [
    (1.0, math.nan, 0.1), (1.0, math.inf, 0.1), (math.nan, 0.0, 0.1), (1.0, 0.0, math.inf),
])
def test_non_finite_inputs_are_refused_and_leave_the_state(setpoint, measurement, dt):
    # Taken in, one nan measurement left the filtered measurement nan: every later output nan.
    pid = PID(PIDGains(kp=2.5, ki=1.0, out_min=-3.0, out_max=3.0))
    pid.update(5.0, 4.0, 0.1)
    with pytest.raises(ValueError, match=r"finite|step"):
        pid.update(setpoint, measurement, dt)
    assert pid.update(5.0, 4.0, 0.1) == pytest.approx(2.5 + 0.2)


def test_gains_that_overflow_still_give_a_limited_output():
    # kp and ki near the float maximum: the terms overflow to inf, and the back-calculation's
    # inf - inf left a nan integral (and nan outputs) behind.
    pid = PID(PIDGains(kp=1e308, ki=1e308, out_min=-3.0, out_max=3.0))
    outs = [pid.update(5.0, y, 1.0) for y in (0.0, 4.0, 6.0, 4.0)]
    assert outs == [3.0, 3.0, -3.0, 3.0]
    assert math.isfinite(pid.integral)
