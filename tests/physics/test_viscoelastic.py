"""Maxwell–Wiechert model against closed forms (paper Eqs. 1–10)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from relaxgrip.physics.smp import SMPParams
from relaxgrip.physics.viscoelastic import (
    PronySeries,
    RelaxationParams,
    branch_update,
    dominant_mode,
    finger_prony,
    phi1,
    prony_force,
    reduced_force,
    step_response,
)

taus = st.lists(st.floats(0.05, 500.0), min_size=1, max_size=4)


def test_phi1_limit_and_values():
    h = np.array([0.0, 1e-12, 1e-3, 1.0, 50.0])
    expected = np.array([1.0, 1.0, (1 - np.exp(-1e-3)) / 1e-3, 1 - np.exp(-1.0), 1 / 50.0])
    np.testing.assert_allclose(phi1(h), expected, rtol=1e-12)


def test_single_maxwell_ramp_matches_closed_form():
    # Ramp X = v t: F(t) = k_e v t + k tau v (1 - e^{-t/tau}).
    k_e, k, tau, v = 300.0, 700.0, 2.5, 1e-3
    t_end, n = 10.0, 37
    forces = np.zeros(1)
    dt = t_end / n
    for _ in range(n):
        forces, _ = branch_update(forces, v * dt, dt, [k], [tau])
    total = k_e * v * t_end + forces[0]
    exact = k_e * v * t_end + k * tau * v * (1 - np.exp(-t_end / tau))
    assert total == pytest.approx(exact, rel=1e-12)


@settings(max_examples=60, deadline=None)
@given(
    taus=taus,
    dts=st.lists(st.floats(1e-4, 50.0), min_size=1, max_size=30),
    x0=st.floats(1e-4, 0.02),
)
def test_recursive_update_equals_step_closed_form_for_any_dt(taus, dts, x0):
    k = np.linspace(100.0, 400.0, len(taus))
    tau = np.asarray(taus)
    forces, gain = branch_update(np.zeros(len(taus)), x0, 0.0, k, tau)  # instantaneous step
    np.testing.assert_allclose(gain, k)
    t = 0.0
    for dt in dts:
        forces, _ = branch_update(forces, 0.0, dt, k, tau)
        t += dt
    expected = step_response(t, x0, 0.0, k, tau)
    assert forces.sum() == pytest.approx(float(expected), rel=1e-9, abs=1e-15)


@settings(max_examples=60, deadline=None)
@given(taus=taus, t=st.lists(st.floats(0.0, 1e3), min_size=2, max_size=20))
def test_relaxation_monotone_at_fixed_displacement(taus, t):
    times = np.sort(np.asarray(t))
    k = np.full(len(taus), 250.0)
    f = step_response(times, 0.004, 500.0, k, taus)
    assert np.all(np.diff(f) <= 1e-12)
    assert np.all(f >= 500.0 * 0.004 - 1e-12)


def test_reduced_model_and_prony_forms():
    t = np.array([0.0, 10.0, 1e6])
    f = reduced_force(t, 5.0, 0.8, 20.0)
    np.testing.assert_allclose(f, [5.0, 5.0 - 0.8 * (1 - np.exp(-0.5)), 4.2])
    p = prony_force(t, 3.0, [1.0, 0.5], [1.0, 100.0])
    np.testing.assert_allclose(p[0], 4.5)
    np.testing.assert_allclose(p[-1], 3.0)


def test_dominant_mode_recovers_single_mode_exactly():
    big_k, tau = dominant_mode([0.7], [35.0], horizon_s=280.0)
    assert big_k == pytest.approx(0.7, rel=1e-6)
    assert tau == pytest.approx(35.0, rel=1e-5)


def test_dominant_mode_is_least_squares_optimum():
    k, taus, horizon = np.array([0.2, 0.3, 0.5]), np.array([2.0, 30.0, 300.0]), 280.0
    big_k, tau = dominant_mode(k, taus, horizon)
    t = np.linspace(0, horizon, 2001)
    loss = -np.expm1(-t[:, None] / taus) @ k

    def cost(bk: float, tt: float) -> float:
        return float(np.mean((loss + bk * np.expm1(-t / tt)) ** 2))

    best = cost(big_k, tau)
    for dk in (-0.01, 0.01):
        for dt in (-0.01, 0.01):
            assert best <= cost(big_k * (1 + dk), tau * (1 + dt))
    assert 0.5 < big_k < 1.0  # the effective mode carries most of the slow loss


def test_finger_prony_splits_instantaneous_stiffness():
    smp = SMPParams()
    relax = RelaxationParams()
    cold, hot = finger_prony(1500.0, 30.0, relax, smp), finger_prony(1500.0, 60.0, relax, smp)
    for p in (cold, hot):
        assert p.k_inst_n_per_m == pytest.approx(1500.0)
    assert sum(hot.k_n_per_m) > sum(cold.k_n_per_m)  # relaxation grows above Tg
    assert hot.tau_s[0] < cold.tau_s[0]  # and runs faster
    f = cold.step_response([0.0, 1e7], 0.002)
    assert f[0] == pytest.approx(3.0)
    assert f[1] == pytest.approx(cold.k_e_n_per_m * 0.002)


def test_prony_series_validates():
    with pytest.raises(ValueError, match="same length"):
        PronySeries(1.0, (1.0,), (1.0, 2.0))
    with pytest.raises(ValueError, match="> 0"):
        PronySeries(1.0, (1.0,), (0.0,))
