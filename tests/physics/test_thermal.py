"""Finger heat model: closed forms, exact stepping, and the paper's heating times."""

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from relaxgrip.physics.thermal import (
    HeatParams,
    duty_for_mean_temp,
    heat_step,
    node_positions_m,
    steady_state_c,
)


def test_uniform_heating_steady_state_is_p_over_ha():
    n = 4
    p = HeatParams(n_nodes=n, heater_share=(0.25,) * n, base_conductance_w_per_k=0.0)
    ss = steady_state_c(0.6, p, 22.0)
    expected = 22.0 + 0.6 * p.heater_power_w / (n * p.convection_w_per_k)
    np.testing.assert_allclose(ss, expected, rtol=1e-12)


def test_single_node_exponential_approach():
    p = HeatParams(n_nodes=1, heater_share=(1.0,), base_conductance_w_per_k=0.0)
    tau = p.capacity_j_per_k / p.convection_w_per_k
    t_inf = 25.0 + p.heater_power_w / p.convection_w_per_k
    got = heat_step([25.0], 1.0, 30.0, p, 25.0)[0]
    assert got == pytest.approx(t_inf + (25.0 - t_inf) * np.exp(-30.0 / tau), rel=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.01, 5.0), min_size=1, max_size=12), st.floats(0.0, 1.0))
def test_stepping_is_exact_for_any_split(dts, duty):
    p = HeatParams()
    t0 = np.array([30.0, 35.0, 40.0, 38.0, 33.0])
    temps = t0
    for dt in dts:
        temps = heat_step(temps, duty, dt, p, 24.0)
    once = heat_step(t0, duty, float(np.sum(dts)), p, 24.0)
    np.testing.assert_allclose(temps, once, rtol=1e-9, atol=1e-9)


def test_paper_heating_time_and_spread():
    p = HeatParams()
    temps = np.full(p.n_nodes, 25.0)
    t = 0.0
    while temps.mean() < 60.0:
        temps = heat_step(temps, 1.0, 0.5, p, 25.0)
        t += 0.5
    assert 60.0 <= t <= 180.0, "25 -> 60 °C takes 1-3 min at full duty"
    soft = steady_state_c(duty_for_mean_temp(58.0, p, 25.0), p, 25.0)
    assert soft.mean() == pytest.approx(58.0, abs=1e-9)
    assert 1.0 <= soft.max() - soft.min() <= 6.0, "a spread of a few °C along the finger"
    assert steady_state_c(1.0, p, 25.0).mean() > 75.0, "full duty can overheat: cut-off matters"
    assert np.all(np.diff(node_positions_m(p)) > 0)


def test_invalid_duty_and_params():
    with pytest.raises(ValueError, match=r"in \[0, 1\]"):
        heat_step(np.full(5, 25.0), 1.5, 1.0, HeatParams(), 25.0)
    with pytest.raises(ValueError, match="heater_share"):
        replace(HeatParams(), heater_share=(1.0, 0.0))


@pytest.mark.parametrize("dt_s", [-1.0, float("nan"), float("inf")])
def test_a_step_that_is_not_a_finite_non_negative_time_is_refused(dt_s):
    # NaN slipped past ``dt_s < 0`` and turned every temperature into NaN.
    with pytest.raises(ValueError, match="dt_s"):
        heat_step(np.full(5, 25.0), 0.5, dt_s, HeatParams(), 25.0)


def test_a_huge_step_lands_on_the_steady_state():
    temps = heat_step(np.full(5, 25.0), 0.7, 1e7, HeatParams(), 22.0)
    assert temps == pytest.approx(steady_state_c(0.7, HeatParams(), 22.0), abs=1e-6)
    assert np.array_equal(heat_step(temps, 0.3, 0.0, HeatParams(), 22.0), temps)
