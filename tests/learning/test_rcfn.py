"""RCFN: polynomial Ridge regressors of kappa and log tau, fast path, Eq. 10."""

import copy
import json
import math
import pickle
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from sklearn.exceptions import NotFittedError  # type: ignore[import-untyped]
from sklearn.preprocessing import PolynomialFeatures  # type: ignore[import-untyped]

from relaxgrip.learning.rcfn import (
    RCFN,
    _poly_expand,
    n_poly_features,
    reconstruct,
    select_rcfn,
)
from relaxgrip.physics.viscoelastic import reduced_force

# Like the RCFN input: temperature (°C), translations (m), rotations (rad), a velocity (m/s).
SCALES = np.array([10.0, 1.5e-3, 1e-3, 2e-2, 1e-2, 1e-4])
OFFSETS = np.array([42.0, 2e-3, 0.0, 0.0, 0.0, 0.0])


#: The plain polynomial model these tests describe (no temperature basis, kappa fitted as is).
PLAIN: dict[str, Any] = {"temp_knots": 0, "log_kappa": False}


def make_data(
    n: int, seed: int, noise: tuple[float, float] = (0.0, 0.0)
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(n, SCALES.size))
    X = OFFSETS + SCALES * z
    # A known quadratic relation in the standardised features (z is close to it).
    # kappa stays inside [0, 1] (the RCFN clips it there) over the draws' tails.
    kappa = 0.4 + 0.04 * z[:, 0] - 0.01 * z[:, 0] ** 2 + 0.01 * z[:, 1] * z[:, 3]
    log_tau = math.log(20.0) - 0.6 * z[:, 0] + 0.1 * z[:, 2] ** 2 + 0.05 * z[:, 4] * z[:, 5]
    Y = np.column_stack([kappa, log_tau]) + rng.normal(size=(n, 2)) * noise
    return X, Y


@pytest.fixture(scope="module")
def data():
    return make_data(2000, seed=0)


@pytest.fixture(scope="module")
def fitted(data):
    return RCFN(alpha_kappa=1e-6, alpha_log_tau=1e-6, **PLAIN).fit(*data)


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_expansion_matches_sklearn_polynomial_features(degree):
    Z = np.random.default_rng(1).normal(size=(40, 5))
    expected = PolynomialFeatures(degree, include_bias=False).fit_transform(Z)
    np.testing.assert_allclose(_poly_expand(Z, degree), expected, rtol=1e-14, atol=0)
    assert n_poly_features(5, degree) == expected.shape[1]


def test_recovers_a_known_quadratic(fitted):
    X_test, Y_test = make_data(500, seed=1)
    assert np.max(np.abs(fitted.predict(X_test) - Y_test)) < 1e-4
    assert fitted.n_features_in_ == SCALES.size
    assert fitted.n_output_features_ == n_poly_features(SCALES.size, 2)
    assert fitted.coef_.shape == (fitted.n_output_features_, 2)


def test_degree_one_cannot_and_degree_two_can(data):
    X, Y = data
    X_test, Y_test = make_data(500, seed=1)
    linear = RCFN(alpha_kappa=1e-6, alpha_log_tau=1e-6, degree=1, **PLAIN).fit(X, Y)
    rmse_1 = np.sqrt(np.mean((linear.predict(X_test) - Y_test) ** 2, axis=0))
    quadratic = RCFN(degree=2, **PLAIN).fit(X, Y)
    rmse_2 = np.sqrt(np.mean((quadratic.predict(X_test) - Y_test) ** 2, axis=0))
    assert linear.n_output_features_ == SCALES.size
    assert (rmse_1 > 0.01).all()
    assert (rmse_2 < rmse_1 / 10).all()


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_relaxation_is_kappa_times_force_and_exp_log_tau(data, degree):
    X, Y = data
    model = RCFN(degree=degree, **PLAIN).fit(X[:400], Y[:400])
    predicted = model.predict(X[400:420])
    for x, (kappa, log_tau) in zip(X[400:420], predicted, strict=True):
        k_n, tau_s = model.relaxation(x, 6.5)
        assert isinstance(k_n, float)
        assert isinstance(tau_s, float)
        assert k_n == pytest.approx(kappa * 6.5, rel=1e-12, abs=1e-13)
        assert tau_s == pytest.approx(math.exp(log_tau), rel=1e-12)
    assert model.relaxation(list(X[400]), 1.0) == pytest.approx(model.relaxation(X[400], 1.0))
    strided = np.asfortranarray(X[400:410])[0]
    assert model.relaxation(strided, 1.0) == pytest.approx(model.relaxation(X[400], 1.0))


def test_relaxation_survives_copies(data, fitted):
    X, _ = data
    expected = fitted.relaxation(X[0], 3.0)
    for other in (copy.deepcopy(fitted), pickle.loads(pickle.dumps(fitted))):
        assert other.relaxation(X[1], 3.0) == fitted.relaxation(X[1], 3.0)
        assert other.relaxation(X[0], 3.0) == expected


def test_reconstruct_matches_reduced_force():
    rng = np.random.default_rng(2)
    n = 50
    t = rng.uniform(0.0, 100.0, n)
    f = rng.uniform(0.5, 8.0, n)
    k = rng.uniform(0.0, 2.0, n)
    tau = np.exp(rng.uniform(math.log(2.0), math.log(200.0), n))
    got = reconstruct(t, f, k, tau)
    expected = [reduced_force(*sample) for sample in zip(t, f, k, tau, strict=True)]
    np.testing.assert_allclose(got, expected, rtol=1e-15)
    # One curve: per-time samples with scalar parameters broadcast.
    times = np.linspace(0.0, 100.0, 11)
    np.testing.assert_allclose(
        reconstruct(times, 5.0, 1.0, 20.0), reduced_force(times, 5.0, 1.0, 20.0)
    )
    assert reconstruct(0.0, 5.0, 1.0, 20.0) == 5.0
    with pytest.raises(ValueError, match="> 0"):
        reconstruct(t, f, k, np.zeros(n))


def test_arrays_round_trip(data, fitted):
    X, _ = data
    params = json.loads(json.dumps(fitted.get_params()))
    rebuilt = RCFN.from_arrays(fitted.to_arrays(), params)
    assert rebuilt.get_params() == fitted.get_params()
    np.testing.assert_array_equal(rebuilt.predict(X), fitted.predict(X))
    assert rebuilt.relaxation(X[9], 2.0) == fitted.relaxation(X[9], 2.0)


@pytest.mark.parametrize(
    ("change", "words"),
    [
        (lambda a: a.pop("coef"), "missing array"),
        (lambda a: a.update(coef=a["coef"][:-1]), "shape"),
        (lambda a: a.update(intercept=np.zeros(3)), "shape"),
        (lambda a: a.update(phi_scale=np.zeros_like(a["phi_scale"])), "> 0"),
        (lambda a: a.update(coef=a["coef"].astype(str)), "dtype"),
    ],
)
def test_from_arrays_rejects_bad_arrays(fitted, change, words):
    arrays = fitted.to_arrays()
    change(arrays)
    with pytest.raises(ValueError, match=words):
        RCFN.from_arrays(arrays, fitted.get_params())
    with pytest.raises(ValueError, match="shape"):
        RCFN.from_arrays(fitted.to_arrays(), {**fitted.get_params(), "degree": 1})


def test_bad_inputs_raise(data, fitted):
    X, Y = data
    with pytest.raises(ValueError, match="shape"):
        RCFN(**PLAIN).fit(X, Y[:, 0])
    with pytest.raises(ValueError, match="shape"):
        RCFN(**PLAIN).fit(X, np.column_stack([Y, Y[:, 0]]))
    bad = Y.copy()
    bad[4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        RCFN(**PLAIN).fit(X, bad)
    with pytest.raises(ValueError, match="inconsistent"):
        RCFN(**PLAIN).fit(X[:10], Y[:9])
    with pytest.raises(ValueError, match="degree"):
        RCFN(degree=0, **PLAIN).fit(X, Y)
    with pytest.raises(ValueError, match="features"):
        fitted.predict(X[:, :3])
    with pytest.raises(ValueError, match="2-D"):
        fitted.predict(X[0])
    with pytest.raises(ValueError, match="shape"):
        fitted.relaxation(X[0, :3], 1.0)
    unfitted = RCFN(**PLAIN)
    with pytest.raises(NotFittedError):
        unfitted.predict(X)
    with pytest.raises(NotFittedError):
        unfitted.relaxation(X[0], 1.0)


def test_select_rcfn_picks_each_targets_lowest_validation_rmse():
    # Noisy kappa, few samples: a middling penalty wins there, the smallest for log tau.
    X, Y = make_data(60, seed=3, noise=(0.05, 0.0))
    X_val, Y_val = make_data(300, seed=4, noise=(0.05, 0.0))
    alphas = (1e-4, 1e-2, 1.0, 100.0)
    best, table = select_rcfn(X, Y, X_val, Y_val, alphas, **PLAIN)
    assert [row["alpha"] for row in table] == list(alphas)
    i_k = int(np.argmin([row["val_rmse_kappa"] for row in table]))
    i_t = int(np.argmin([row["val_rmse_log_tau"] for row in table]))
    assert i_k != i_t  # the targets really are chosen independently
    assert (best.alpha_kappa, best.alpha_log_tau) == (alphas[i_k], alphas[i_t])
    rmse = np.sqrt(np.mean((best.predict(X_val) - Y_val) ** 2, axis=0))
    assert rmse[0] == pytest.approx(table[i_k]["val_rmse_kappa"], rel=1e-9)
    assert rmse[1] == pytest.approx(table[i_t]["val_rmse_log_tau"], rel=1e-9)
    refit = RCFN(**best.get_params()).fit(X, Y)
    np.testing.assert_allclose(refit.predict(X_val), best.predict(X_val), rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="alphas"):
        select_rcfn(X, Y, X_val, Y_val, alphas=(0.0, 1.0), **PLAIN)


def steep_data(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Relaxing share flat when glassy, steep above 50 °C, times an object factor."""
    rng = np.random.default_rng(seed)
    temp = rng.uniform(25.0, 60.0, n)
    other = rng.normal(size=(n, 3))
    kappa = (0.08 + 0.2 / (1 + np.exp(-(temp - 55.0) / 2.0))) * np.exp(0.3 * other[:, 0])
    log_tau = 3.5 - 0.04 * (temp - 40.0) + 0.1 * other[:, 1]
    return np.column_stack([temp, other]), np.column_stack([kappa, log_tau])


def test_temperature_basis_and_log_kappa_follow_a_steep_multiplicative_share() -> None:
    X, Y = steep_data(2000, 0)
    X_test, Y_test = steep_data(500, 1)

    def rel_error(model: RCFN) -> float:
        return float(np.median(np.abs(model.predict(X_test)[:, 0] / Y_test[:, 0] - 1)))

    plain = RCFN(alpha_kappa=1e-3, alpha_log_tau=1e-3, **PLAIN).fit(X, Y)
    shaped = RCFN(alpha_kappa=1e-3, alpha_log_tau=1e-3, temp_knots=6).fit(X, Y)
    assert shaped.temp_knots_.tolist() == pytest.approx(np.linspace(X[:, 0].min(),
                                                                     X[:, 0].max(), 6).tolist())
    assert rel_error(shaped) < 0.5 * rel_error(plain)
    assert (shaped.predict(X_test)[:, 0] > 0).all()  # exp(log kappa): never negative


def test_fast_path_and_round_trip_with_the_basis() -> None:
    X, Y = steep_data(800, 2)
    model = RCFN(temp_knots=5).fit(X, Y)
    X_out = X[:50].copy()
    X_out[:5, 0] = [10.0, 20.0, 70.0, 80.0, 60.0]  # held at the end knots beyond the range
    predicted = model.predict(X_out)
    for x, (kappa, log_tau) in zip(X_out, predicted, strict=True):
        k_n, tau_s = model.relaxation(x, 4.0)
        assert k_n == pytest.approx(kappa * 4.0, rel=1e-10)
        assert tau_s == pytest.approx(np.exp(log_tau), rel=1e-10)
    rebuilt = RCFN.from_arrays(model.to_arrays(), model.get_params())
    assert np.allclose(rebuilt.predict(X_out), predicted, rtol=1e-12)
    assert rebuilt.n_features_in_ == X.shape[1]


def test_basis_and_log_kappa_validation() -> None:
    X, Y = steep_data(100, 3)
    with pytest.raises(ValueError, match="temp_knots"):
        RCFN(temp_knots=1).fit(X, Y)
    with pytest.raises(ValueError, match="kappa must be > 0"):
        RCFN().fit(X, np.column_stack([-Y[:, 0], Y[:, 1]]))
    with pytest.raises(ValueError, match="temp_column"):
        RCFN(temp_column=9).fit(X, Y)


def relaxing_data(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame labels of a three-mode hold: the touching curve's share grows as log time."""
    rng = np.random.default_rng(seed)
    temp = rng.uniform(25.0, 60.0, n)
    hold = rng.uniform(0.0, 280.0, n)
    other = rng.normal(size=n)
    kappa = (0.05 + 0.02 * np.log1p(hold)) * np.exp(0.1 * other)
    log_tau = 1.0 + 0.8 * np.log1p(hold) - 0.02 * (temp - 40.0)
    return np.column_stack([temp, other, hold]), np.column_stack([kappa, log_tau])


@pytest.mark.parametrize("knots", [0, 5])
def test_log_time_column_fits_relaxation_in_log_time_and_round_trips(knots: int) -> None:
    X, Y = relaxing_data(2000, 4)
    X_test, Y_test = relaxing_data(300, 5)
    plain = RCFN(alpha_kappa=1e-3, alpha_log_tau=1e-3, temp_knots=knots).fit(X, Y)
    timed = RCFN(alpha_kappa=1e-3, alpha_log_tau=1e-3, temp_knots=knots, time_column=2).fit(X, Y)
    error = [float(np.sqrt(np.mean((m.predict(X_test)[:, 1] - Y_test[:, 1]) ** 2)))
             for m in (plain, timed)]
    assert error[1] < 0.5 * error[0]
    predicted = timed.predict(X_test[:20])
    for x, (kappa, log_tau) in zip(X_test[:20], predicted, strict=True):
        k_n, tau_s = timed.relaxation(x, 2.0)
        assert k_n == pytest.approx(kappa * 2.0, rel=1e-10)
        assert tau_s == pytest.approx(np.exp(log_tau), rel=1e-10)
    rebuilt = RCFN.from_arrays(timed.to_arrays(), timed.get_params())
    assert np.allclose(rebuilt.predict(X_test), timed.predict(X_test), rtol=1e-12)
    assert rebuilt.n_features_in_ == 3
    with pytest.raises(ValueError, match="time_column"):
        RCFN(time_column=7).fit(X, Y)


def test_far_outside_its_training_range_the_rcfn_stays_physical() -> None:
    X, Y = relaxing_data(1000, 6)
    model = RCFN(alpha_kappa=1e-3, alpha_log_tau=1e-3, time_column=2).fit(X, Y)
    wild = np.array([[200.0, 50.0, 1e5], [-100.0, -50.0, 0.0], [40.0, 30.0, 280.0]])
    predicted = model.predict(wild)
    assert ((predicted[:, 0] >= 0) & (predicted[:, 0] <= 1)).all()
    lo, hi = model.log_tau_range_
    assert ((predicted[:, 1] >= lo) & (predicted[:, 1] <= hi)).all()
    assert hi - lo < 1.3 * np.ptp(Y[:, 1])
    for x, (kappa, log_tau) in zip(wild, predicted, strict=True):
        assert model.relaxation(x, 3.0) == pytest.approx((3.0 * kappa, np.exp(log_tau)))
