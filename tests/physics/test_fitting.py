"""Relaxation fits are true least-squares optima, and the hold phase is found."""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from relaxgrip.errors import InputError
from relaxgrip.physics.fitting import (
    find_hold,
    find_hold_start,
    fit_prony,
    fit_reduced,
    quadrature_weights,
)
from relaxgrip.physics.viscoelastic import prony_force, reduced_force

DATA_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "vhb4910-relaxation"
REAL_FILES = sorted(DATA_DIR.glob("*.csv")) if DATA_DIR.is_dir() else []

# The sampling of the measured records: 50 Hz for 10 s, 5 Hz to 60 s, 1 Hz to 600 s.
T_S = np.concatenate(
    [np.arange(0.0, 10.0, 0.02), np.arange(10.0, 60.0, 0.2), np.arange(60.0, 600.5, 1.0)]
)


def time_objective(f_model: np.ndarray, f_n: np.ndarray) -> float:
    """The documented time-weighted objective, computed independently of the module."""
    return float(np.trapezoid((f_model - f_n) ** 2, T_S))


def relaxing_force(rng: np.random.Generator, noise_n: float = 2e-3) -> np.ndarray:
    """A four-mode curve with noise: no 1- or 3-term model fits it exactly."""
    clean = prony_force(T_S, 0.8, (0.3, 0.35, 0.25, 0.2), (0.7, 6.0, 45.0, 350.0))
    return clean + noise_n * rng.standard_normal(T_S.size)


def brute_force_min(f_n: np.ndarray, n_terms: int, grid_s: np.ndarray) -> float:
    """Smallest time-weighted objective over every ``n_terms`` subset of ``grid_s``.

    The amplitudes are the exact linear least-squares solution for each set of times.
    """
    sqrt_w = np.sqrt(quadrature_weights(T_S, "time"))
    best = math.inf
    for taus in itertools.combinations(grid_s, n_terms):
        basis = np.column_stack([np.ones_like(T_S), np.exp(-T_S[:, None] / np.array(taus))])
        coef = np.linalg.lstsq(sqrt_w[:, None] * basis, sqrt_w * f_n, rcond=None)[0]
        best = min(best, time_objective(basis @ coef, f_n))
    return best


# --- recovery of known parameters -------------------------------------------------------


@pytest.mark.parametrize("weighting", ["time", "sample"])
def test_recovers_reduced_model(weighting: str) -> None:
    f_n = reduced_force(T_S, 2.4, 0.9, 37.0)
    fit = fit_reduced(T_S, f_n, weighting=weighting)
    assert fit.f_inst_n == pytest.approx(2.4, rel=1e-7)
    assert fit.k_n == pytest.approx(0.9, rel=1e-7)
    assert fit.tau_s == pytest.approx(37.0, rel=1e-7)
    assert fit.objective == pytest.approx(0.0, abs=1e-18)
    assert fit.weighting == weighting


@pytest.mark.parametrize("weighting", ["time", "sample"])
def test_recovers_three_term_prony(weighting: str) -> None:
    k_n, tau_s = (0.45, 0.3, 0.25), (1.5, 20.0, 180.0)
    f_n = prony_force(T_S, 0.6, k_n, tau_s)
    fit = fit_prony(T_S, f_n, n_terms=3, weighting=weighting)
    assert fit.f_eq_n == pytest.approx(0.6, rel=1e-6)
    assert fit.k_n == pytest.approx(k_n, rel=1e-6)
    assert fit.tau_s == pytest.approx(tau_s, rel=1e-6)
    assert fit.f_inst_n == pytest.approx(0.6 + sum(k_n), rel=1e-9)
    np.testing.assert_allclose(fit.predict(T_S), f_n, atol=1e-9)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    f_inst_n=st.floats(0.5, 5.0),
    k_share=st.floats(0.05, 0.9),
    tau_s=st.floats(0.2, 200.0),
)
def test_reduced_recovery_property(f_inst_n: float, k_share: float, tau_s: float) -> None:
    k_n = k_share * f_inst_n
    fit = fit_reduced(T_S, reduced_force(T_S, f_inst_n, k_n, tau_s))
    assert fit.f_inst_n == pytest.approx(f_inst_n, rel=1e-6)
    assert fit.k_n == pytest.approx(k_n, rel=1e-6)
    assert fit.tau_s == pytest.approx(tau_s, rel=1e-6)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    f_eq_n=st.floats(0.0, 2.0),
    k_n=st.tuples(st.floats(0.1, 1.0), st.floats(0.1, 1.0), st.floats(0.1, 1.0)),
    tau1_s=st.floats(0.3, 3.0),
    ratios=st.tuples(st.floats(6.0, 15.0), st.floats(6.0, 15.0)),
)
def test_prony_recovery_property(
    f_eq_n: float,
    k_n: tuple[float, float, float],
    tau1_s: float,
    ratios: tuple[float, float],
) -> None:
    # Modes a decade apart inside the record: identifiable from noiseless data.
    tau_s = (tau1_s, tau1_s * ratios[0], tau1_s * ratios[0] * ratios[1])
    fit = fit_prony(T_S, prony_force(T_S, f_eq_n, k_n, tau_s), n_terms=3)
    assert fit.tau_s == pytest.approx(tau_s, rel=1e-4)
    assert fit.k_n == pytest.approx(k_n, rel=1e-4, abs=1e-6)
    assert fit.f_eq_n == pytest.approx(f_eq_n, rel=1e-4, abs=1e-6)


# --- optimality ---------------------------------------------------------------------------


def test_reduced_fit_is_the_global_optimum() -> None:
    rng = np.random.default_rng(7)
    f_n = relaxing_force(rng)
    fit = fit_reduced(T_S, f_n)
    # The reported objective is the trapezoidal int (F_model - F)^2 dt.
    assert fit.objective == pytest.approx(time_objective(fit.predict(T_S), f_n), rel=1e-10)
    # Dense brute force over tau (amplitudes exact for each tau) never does better...
    dense_tau_s = np.geomspace(0.02, 6000.0, 2000)
    assert fit.objective <= brute_force_min(f_n, 1, dense_tau_s) * (1 + 1e-12)
    # ...and neither does any perturbation of all three parameters.
    for scale in (1e-2, 1e-4):
        for _ in range(200):
            p = np.array([fit.f_inst_n, fit.k_n, fit.tau_s]) * (1 + scale * rng.standard_normal(3))
            f_model = reduced_force(T_S, p[0], p[1], p[2])
            assert time_objective(f_model, f_n) >= fit.objective * (1 - 1e-12)


@pytest.mark.parametrize("n_terms", [2, 3])
def test_prony_fit_is_the_global_optimum(n_terms: int) -> None:
    rng = np.random.default_rng(11)
    f_n = relaxing_force(rng)
    fit = fit_prony(T_S, f_n, n_terms=n_terms)
    assert fit.objective == pytest.approx(time_objective(fit.predict(T_S), f_n), rel=1e-10)
    assert list(fit.tau_s) == sorted(fit.tau_s)
    assert all(math.isfinite(tau) and tau > 0 for tau in fit.tau_s)
    grid_s = np.geomspace(0.05, 3000.0, 40 if n_terms == 2 else 22)
    assert fit.objective <= brute_force_min(f_n, n_terms, grid_s) * (1 + 1e-12)
    params = np.array([fit.f_eq_n, *fit.k_n, *fit.tau_s])
    for scale in (1e-2, 1e-4):
        for _ in range(200):
            p = params * (1 + scale * rng.standard_normal(params.size))
            f_model = prony_force(T_S, p[0], p[1 : n_terms + 1], p[n_terms + 1 :])
            assert time_objective(f_model, f_n) >= fit.objective * (1 - 1e-12)


def test_more_terms_never_fit_worse() -> None:
    f_n = relaxing_force(np.random.default_rng(3))
    objectives = [fit_reduced(T_S, f_n).objective] + [
        fit_prony(T_S, f_n, n_terms=n).objective for n in (1, 2, 3, 4)
    ]
    # One Prony term is the reduced model reparametrised: same optimum.
    assert objectives[1] == pytest.approx(objectives[0], rel=1e-9)
    assert all(b <= a * (1 + 1e-12) for a, b in itertools.pairwise(objectives[1:]))


def test_time_weighting_is_not_dominated_by_dense_samples() -> None:
    # A curve whose first 10 s (500 samples at 50 Hz) disagree with the 1 Hz tail (540 samples):
    # per sample the head weighs as much as the tail, per second it is 1/60 of the record.
    f_n = reduced_force(T_S, 2.0, 1.0, 80.0) + np.where(T_S < 10.0, 0.05, 0.0)
    by_time = fit_reduced(T_S, f_n, weighting="time")
    by_sample = fit_reduced(T_S, f_n, weighting="sample")
    tail = T_S >= 10.0
    tail_err = [
        float(np.sqrt(np.mean((f.predict(T_S) - f_n)[tail] ** 2))) for f in (by_time, by_sample)
    ]
    assert tail_err[0] < tail_err[1]


# --- degenerate input ---------------------------------------------------------------------


def test_constant_force_is_rejected() -> None:
    with pytest.raises(InputError, match="constant"):
        fit_reduced(T_S, np.full_like(T_S, 1.5))
    with pytest.raises(InputError, match="constant"):
        fit_prony(T_S, np.full_like(T_S, 1.5))


def test_too_few_samples_are_rejected() -> None:
    t, f = T_S[:6], reduced_force(T_S[:6], 2.0, 1.0, 0.05)
    with pytest.raises(InputError, match="7 parameters to 6 samples"):
        fit_prony(t, f, n_terms=3)
    with pytest.raises(InputError, match="3 parameters to 2 samples"):
        fit_reduced(t[:2], f[:2])


@pytest.mark.parametrize(
    ("t_s", "f_n", "kwargs", "match"),
    [
        (T_S, T_S[:-1], {}, "shape"),
        (T_S[::-1], T_S, {}, "strictly increasing"),
        (T_S, np.where(T_S > 5, np.nan, 1.0), {}, "non-finite"),
        (T_S, np.exp(-T_S), {"weighting": "log"}, "weighting"),
        (T_S, np.exp(-T_S), {"n_terms": 0}, "n_terms"),
        (T_S, np.exp(-T_S), {"n_terms": 6}, "n_terms must be an integer from 1 to 5"),
    ],
)
def test_malformed_arrays_raise_value_error(
    t_s: np.ndarray, f_n: np.ndarray, kwargs: dict[str, Any], match: str
) -> None:
    with pytest.raises(ValueError, match=match):
        fit_prony(t_s, f_n, **kwargs)


@pytest.mark.parametrize(
    ("t_scale", "f_scale", "match"),
    [
        (1.0, 1e300, r"the force reaches 2e\+300 N, beyond any relaxation test"),
        (1.0, 1e10, r"the force reaches 2e\+10 N, .*at most 1e\+09 N"),
        (1e300, 1.0, r"the record lasts .*e\+30\d s, beyond any relaxation test"),
        (1e10, 1.0, r"the record lasts .* s, .*at most 1e\+10 s"),
    ],
)
def test_out_of_range_records_are_refused_before_any_arithmetic(
    t_scale: float, f_scale: float, match: str
) -> None:
    f_n = f_scale * reduced_force(T_S, 2.0, 1.0, 5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # formerly overflow warnings, then scipy's own error
        for fit in (fit_reduced, fit_prony):
            with pytest.raises(InputError, match=match):
                fit(t_scale * T_S, f_n)
        with pytest.raises(InputError, match="the force reaches"):
            fit_reduced(T_S, reduced_force(T_S, 2.0, 1.0, 5.0), f_inst_n=1e12)


def test_records_at_the_limits_fit_without_warnings() -> None:
    f_n = 4e8 * reduced_force(T_S, 2.0, 1.0, 5.0)
    t_s = T_S * (0.9e10 / float(T_S[-1]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit = fit_reduced(t_s, f_n)
    assert fit.tau_s == pytest.approx(5.0 * 0.9e10 / float(T_S[-1]), rel=1e-6)
    assert fit.f_inst_n == pytest.approx(8e8, rel=1e-6)


def test_quadrature_weights_are_the_trapezoid_rule() -> None:
    w = quadrature_weights(T_S, "time")
    g = np.sin(T_S / 7.0) ** 2
    assert float(w @ g) == pytest.approx(float(np.trapezoid(g, T_S)), rel=1e-13)
    assert float(w.sum()) == pytest.approx(float(T_S[-1] - T_S[0]), rel=1e-13)
    np.testing.assert_array_equal(quadrature_weights(T_S, "sample"), np.ones_like(T_S))


# --- hold-phase detection -------------------------------------------------------------


def ramp_overshoot_plateau(
    plateau_mm: float = 40.0,
    overshoot_mm: float = 0.7,
    settle_s: float = 0.1,
    hold_s: float = 60.0,
) -> tuple[np.ndarray, np.ndarray, float]:
    """20 mm/s ramp, exponentially settling overshoot, plateau; returns t, x, ramp end."""
    t = np.arange(0.0, plateau_mm / 20.0 + hold_s, 0.02)
    ramp_end_s = plateau_mm / 20.0
    x = np.where(
        t < ramp_end_s,
        20.0 * t,
        plateau_mm + overshoot_mm * np.exp(-(t - ramp_end_s) / settle_s),
    )
    return t, x, ramp_end_s


def test_hold_start_after_overshoot() -> None:
    t, x, ramp_end_s = ramp_overshoot_plateau()
    start = find_hold_start(t, x, rel_tol=1e-3)
    # Inside the band 1e-3 * 40 mm once 0.7 e^{-s/0.1} <= 0.04, i.e. s >= 0.1 ln(17.5).
    settled_s = ramp_end_s + 0.1 * math.log(0.7 / 0.04)
    assert t[start - 1] < settled_s <= t[start]


def test_hold_start_with_measurement_noise() -> None:
    t, x, ramp_end_s = ramp_overshoot_plateau()
    rng = np.random.default_rng(5)
    sigma_mm = 2e-3
    start = find_hold_start(t, x + sigma_mm * rng.standard_normal(t.size), rel_tol=1e-3)
    # The band widens by about 5 sigma: 0.7 e^{-s/0.1} <= 0.04 + 0.01.
    expected_s = ramp_end_s + 0.1 * math.log(0.7 / 0.05)
    assert abs(t[start] - expected_s) < 0.05


def test_hold_start_with_undershoot_and_offset_origin() -> None:
    t, x, ramp_end_s = ramp_overshoot_plateau(overshoot_mm=-0.5)
    start = find_hold_start(t, x + 100.0)
    # The band is relative to the 40 mm step, not to the 140 mm absolute displacement.
    assert t[start] == pytest.approx(ramp_end_s + 0.1 * math.log(0.5 / 0.04), abs=0.021)


@pytest.mark.skipif(not REAL_FILES, reason=f"VHB4910 data not found in {DATA_DIR}")
@pytest.mark.parametrize("path", REAL_FILES, ids=lambda p: p.name)
def test_hold_start_on_measured_records(path: Path) -> None:
    t, x, _ = np.loadtxt(path, delimiter=",", skiprows=1, unpack=True)
    start = find_hold_start(t, x)
    plateau = x[-1]
    peak = int(np.argmax(x))
    # After the overshoot peak, within a second of it, and settled for good from there on.
    assert start > peak
    assert t[start] - t[peak] < 1.0
    assert np.all(np.abs(x[start:] - plateau) <= 1e-3 * abs(plateau))
    assert abs(x[start - 1] - plateau) > 1e-3 * abs(plateau)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda t: 20.0 * t, "never settles"),
        (lambda t: np.zeros_like(t), "no step"),
        (lambda t: np.where((t > 1) & (t < 5), 40.0, 0.0), "no step"),
        (lambda t: np.full_like(t, 40.0), "no step"),
        (lambda t: 40.0 + 0.3 * np.sin(t), "never settles"),
    ],
    ids=["ramp", "zero", "returns-to-start", "constant", "oscillating"],
)
def test_no_hold_phase_raises(make: Callable[[np.ndarray], np.ndarray], match: str) -> None:
    t = np.arange(0.0, 10.0, 0.02)
    with pytest.raises(InputError, match=match):
        find_hold_start(t, make(t))


def test_hold_must_last_one_second() -> None:
    t = np.arange(0.0, 1.8, 0.02)  # 1 s ramp (50 samples), then 0.78 s (40 samples) held
    x = np.minimum(40.0 * t, 40.0)
    with pytest.raises(InputError, match=r"last 40 samples \(0\.78 s\)"):
        find_hold_start(t, x)
    assert find_hold_start(t, x, min_duration_s=0.5) == 50


def test_hold_must_have_ten_samples() -> None:
    t = np.concatenate([np.arange(0.0, 2.0, 0.1), 2.0 + np.arange(8) * 1.0])  # 8 samples over 7 s
    x = np.minimum(20.0 * t, 40.0)
    with pytest.raises(InputError, match="last 8 samples"):
        find_hold_start(t, x)


def test_anchored_fit_recovers_the_reduced_model_with_fixed_f_inst() -> None:
    t = np.linspace(0.0, 100.0, 1001)
    fit = fit_reduced(t, reduced_force(t, 5.0, 0.6, 20.0), f_inst_n=5.0)
    assert fit.f_inst_n == 5.0
    assert fit.k_n == pytest.approx(0.6, rel=1e-6)
    assert fit.tau_s == pytest.approx(20.0, rel=1e-6)


def test_anchored_fit_is_the_least_squares_optimum_and_passes_through_the_anchor() -> None:
    t = np.linspace(0.0, 100.0, 1001)
    f = prony_force(t, 4.0, (0.3, 0.4, 0.3), (1.5, 15.0, 150.0))
    fit = fit_reduced(t, f, f_inst_n=float(f[0]))
    assert fit.predict(0.0) == pytest.approx(f[0])
    w = quadrature_weights(t)

    def cost(k: float, tau: float) -> float:
        return float(w @ (reduced_force(t, float(f[0]), k, tau) - f) ** 2)

    best = cost(fit.k_n, fit.tau_s)
    assert best == pytest.approx(fit.objective, rel=1e-9)
    for dk in (-0.01, 0.01):
        for dtau in (-0.01, 0.01):
            assert best <= cost(fit.k_n * (1 + dk), fit.tau_s * (1 + dtau))
    free = fit_reduced(t, f)
    assert free.objective <= fit.objective  # one parameter fewer cannot fit better


def test_osculating_reduced_recovers_one_exponential_and_touches_three() -> None:
    from relaxgrip.physics.fitting import osculating_reduced

    t = np.arange(0.0, 280.0 + 1e-9, 0.1)
    one = 5.0 * (1.0 - 0.2 * -np.expm1(-t / 30.0))
    kappa, tau = osculating_reduced(t, one, 5.0, [0.0, 10.0, 100.0, 280.0])
    np.testing.assert_allclose(kappa, 0.2, rtol=1e-2)
    np.testing.assert_allclose(tau, 30.0, rtol=1e-2)
    # Three modes: the touching curve has the hold's force and slope where it touches.
    three = 5.0 - 0.4 * -np.expm1(-t / 2.0) - 0.3 * -np.expm1(-t / 25.0) \
        - 0.3 * -np.expm1(-t / 300.0)
    at = np.array([2.0, 20.0, 150.0])
    kappa, tau = osculating_reduced(t, three, 5.0, at)
    touch = 5.0 * (1.0 - kappa * -np.expm1(-at / tau))
    np.testing.assert_allclose(touch, np.interp(at, t, three), atol=1e-4)
    slope = -5.0 * kappa / tau * np.exp(-at / tau)
    true_slope = -(0.4 / 2.0 * np.exp(-at / 2.0) + 0.3 / 25.0 * np.exp(-at / 25.0)
                   + 0.3 / 300.0 * np.exp(-at / 300.0))
    np.testing.assert_allclose(slope, true_slope, rtol=0.03)  # a local quadratic
    assert tau[0] < tau[1] < tau[2]  # the slower modes take over


def test_osculating_reduced_is_undefined_where_the_force_rises() -> None:
    from relaxgrip.physics.fitting import osculating_reduced

    t = np.arange(0.0, 20.0, 0.1)
    kappa, tau = osculating_reduced(t, 5.0 + 0.01 * t, 5.0, [5.0, 10.0])
    assert np.isnan(kappa).all()
    assert np.isnan(tau).all()
    with pytest.raises(ValueError, match="> 0"):
        osculating_reduced(t, 5.0 + 0 * t, 0.0, [5.0])


def _step_and_hold(seconds: float = 600.0) -> tuple[np.ndarray, np.ndarray]:
    """A 1 s ramp to 2 mm at 10 Hz, then the hold."""
    t = np.arange(0.0, seconds, 0.1)
    return t, np.minimum(2.0 * t, 2.0)


def test_a_displacement_logged_in_counts_holds_from_the_step() -> None:
    """Rounded to 0.01 mm with one-count flickers on the plateau: the noise estimate of
    the differences is zero, and the resolution takes its place."""
    t, x = _step_and_hold()
    rng = np.random.default_rng(2)
    x = x + 0.004 * rng.standard_normal(t.size) * (t > 1.0)
    counts = np.round(x / 0.01) * 0.01
    assert np.median(np.abs(np.diff(counts[t > 1.0]))) == 0.0
    start, stop = find_hold(t, counts)
    assert t[start] == pytest.approx(1.0, abs=0.15)
    assert stop == t.size


def test_one_glitching_sample_does_not_move_the_hold() -> None:
    t, x = _step_and_hold()
    clean = find_hold(t, x)
    x[3000] += 0.2  # one sample 10 % of the step off, at 300 s
    assert find_hold(t, x) == clean


def test_an_unloading_at_the_end_is_cut() -> None:
    t, x = _step_and_hold()
    x[t >= 590.0] = np.maximum(2.0 - 2.0 * (t[t >= 590.0] - 590.0), 0.0)  # back to 0 in 1 s
    start, stop = find_hold(t, x)
    assert t[start] == pytest.approx(1.0, abs=0.15)
    assert t[stop - 1] == pytest.approx(590.0, abs=0.15)


@pytest.mark.parametrize("creep_rel", [0.002, 0.005, 0.009])
def test_a_hold_that_creeps_a_little_holds_from_the_step(creep_rel: float) -> None:
    # A clamp that gives a little: held along the trend, not from where the creep has
    # brought the displacement within 0.1 % of its final value (minutes late).
    t, x = _step_and_hold()
    clean = find_hold(t, x)
    held = t >= t[clean[0]]
    x[held] += creep_rel * 2.0 * (t[held] - t[clean[0]]) / (t[-1] - t[clean[0]])
    assert find_hold(t, x) == clean


@pytest.mark.parametrize("unload_dt_s", [0.002, 0.01])
def test_an_unloading_sampled_finely_does_not_widen_the_band(unload_dt_s: float) -> None:
    # A plateau whose displacement never changes, then an unloading sampled finer than
    # it: its first step (0.4 or 2 % of the step) had been taken for the recording's
    # resolution, and the band of five of them reached into the ramp.
    t, x = _step_and_hold()
    clean = find_hold(t, x)
    t_off = t[-1] + unload_dt_s * np.arange(1, 101)
    t2 = np.concatenate([t, t_off])
    x2 = np.concatenate([x, np.maximum(2.0 - 2.0 * (t_off - t[-1]), 0.0)])
    start, stop = find_hold(t2, x2)
    assert start == clean[0]
    assert stop <= t.size + 5  # the first thousandths of a millimetre of the unloading


def test_a_prony_series_with_more_terms_than_the_hold_shows_is_refused() -> None:
    """The first second of a VHB-like hold (modes of 5.5, 55 and 540 s) with 1 mN of
    noise: the best three-term fits merge two relaxation times into a pair of amplitudes
    of hundreds of newtons that cancel (as on stretch_2.0.csv with --window-s 1)."""
    t = np.arange(0.0, 1.0, 0.02)
    f = prony_force(t, 0.5, (0.6, 0.35, 0.22), (5.5, 55.0, 540.0))
    f = f + 1e-3 * np.random.default_rng(0).standard_normal(t.size)
    assert len(fit_prony(t, f, n_terms=1).tau_s) == 1
    with pytest.raises(InputError, match="Prony series is not identifiable on this hold"):
        fit_prony(t, f, n_terms=3)


def test_a_long_record_is_searched_pooled_and_solved_on_every_sample() -> None:
    """Past 20 000 samples the global search runs on 2 000 pooled bins; the last solve on
    all samples lands on the modes (a million rows fitted in 30 s instead of 12 min)."""
    t = np.linspace(0.0, 1800.0, 30_001)
    f = prony_force(t, 2.0, (1.5, 1.0, 0.5), (5.0, 60.0, 600.0))
    f = f + 1e-3 * np.random.default_rng(4).standard_normal(t.size)
    fit = fit_prony(t, f, n_terms=3)
    assert fit.tau_s == pytest.approx((5.0, 60.0, 600.0), rel=5e-3)
    assert fit.k_n == pytest.approx((1.5, 1.0, 0.5), rel=5e-3)
