"""ICFN: NumPy forward pass against scikit-learn, fast path, round trips, selection."""

import copy
import json
import pickle
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from sklearn.base import clone  # type: ignore[import-untyped]
from sklearn.exceptions import NotFittedError  # type: ignore[import-untyped]

from relaxgrip.learning.icfn import ICFN, select_icfn

# Feature scales like the real ICFN input: translations (m), their squares, rotations
# (rad), temperatures (°C), a gradient (K/m).
SCALES = np.array([1.5e-3, 2e-6, 2e-2, 10.0, 150.0])
OFFSETS = np.array([0.0, 2e-6, 0.0, 42.0, 0.0])
SMALL: dict[str, Any] = {"hidden_layer_sizes": (32, 32), "max_iter": 600}


def make_data(n: int, seed: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(n, SCALES.size))
    X = OFFSETS + SCALES * z
    # A smooth nonlinear force (N) of the standardised features.
    y = 3.0 + 1.5 * np.sin(z[:, 0]) + 0.4 * z[:, 2] ** 2 - 0.6 * np.tanh(z[:, 3]) * z[:, 4]
    return X, y + rng.normal(0.0, 0.05, size=n)  # label noise lets early stopping end training


@pytest.fixture(scope="module")
def data():
    return make_data(1500, seed=0)


@pytest.fixture(scope="module")
def fitted(data):
    X, y = data
    return ICFN(**SMALL).fit(X, y)


def test_fit_returns_self_and_learns_a_smooth_function(data, fitted):
    X_test, y_test = make_data(500, seed=1)
    mae = np.mean(np.abs(fitted.predict(X_test) - y_test))
    assert mae < 0.1 * np.std(y_test)
    assert fitted.n_features_in_ == X_test.shape[1]
    assert 0 < fitted.n_iter_ <= SMALL["max_iter"]
    est = ICFN(**SMALL)
    assert est.fit(*make_data(100, seed=2)) is est


def test_numpy_forward_pass_equals_sklearn(data, fitted):
    X, y = data
    Xs = (X - fitted.x_mean_) / fitted.x_scale_
    mlp = fitted._make_mlp().fit(Xs, (y - fitted.y_mean_) / fitted.y_scale_)
    expected = mlp.predict(Xs) * fitted.y_scale_ + fitted.y_mean_
    np.testing.assert_allclose(fitted.predict(X), expected, rtol=0, atol=1e-10)
    assert mlp.n_iter_ == fitted.n_iter_  # training is deterministic


def test_predict_one_equals_predict(data, fitted):
    X, _ = data
    rows = X[:25]
    batch = fitted.predict(rows)
    one = [fitted.predict_one(row) for row in rows]
    np.testing.assert_allclose(one, batch, rtol=1e-12, atol=1e-12)
    assert isinstance(one[0], float)
    assert fitted.predict_one(rows[3].tolist()) == pytest.approx(batch[3], abs=1e-12)
    assert fitted.predict_one(rows[3].astype(np.float32)) == pytest.approx(batch[3], abs=1e-5)
    strided = np.asfortranarray(rows)[3]  # a non-contiguous view
    assert fitted.predict_one(strided) == pytest.approx(batch[3], abs=1e-12)


def test_predict_one_survives_copies(data, fitted):
    X, _ = data
    expected = fitted.predict_one(X[0])
    for other in (copy.deepcopy(fitted), pickle.loads(pickle.dumps(fitted))):
        assert other.predict_one(X[1]) == fitted.predict_one(X[1])
        assert other.predict_one(X[0]) == expected


def test_network_without_hidden_layers_is_linear():
    X, _ = make_data(300, seed=3)
    y = 2.0 + (X - OFFSETS) / SCALES @ np.array([1.0, -0.5, 0.25, 0.0, 0.5])
    est = ICFN(hidden_layer_sizes=(), learning_rate_init=1e-2, max_iter=400).fit(X, y)
    assert np.max(np.abs(est.predict(X) - y)) < 0.05
    assert est.predict_one(X[7]) == pytest.approx(est.predict(X[7:8])[0], abs=1e-12)


def test_arrays_round_trip(data, fitted):
    X, _ = data
    arrays = fitted.to_arrays()
    assert all(a.dtype == np.float64 for a in arrays.values())
    params = json.loads(json.dumps(fitted.get_params()))  # as a manifest gives them back
    rebuilt = ICFN.from_arrays(arrays, params)
    assert rebuilt.get_params() == fitted.get_params()
    np.testing.assert_array_equal(rebuilt.predict(X), fitted.predict(X))
    assert rebuilt.predict_one(X[5]) == fitted.predict_one(X[5])
    assert rebuilt.n_iter_ == fitted.n_iter_
    arrays["x_mean"][:] = 0.0  # to_arrays hands out copies
    np.testing.assert_array_equal(rebuilt.predict(X), fitted.predict(X))


@pytest.mark.parametrize(
    ("change", "words"),
    [
        (lambda a: a.pop("coef_1"), "missing array"),
        (lambda a: a.update(extra=np.zeros(2)), "unexpected array"),
        (lambda a: a.update(coef_1=np.zeros((32, 31))), "shape"),
        (lambda a: a.update(x_scale=-a["x_scale"]), "> 0"),
        (lambda a: a.update(y_mean=np.array(np.nan)), "NaN"),
    ],
)
def test_from_arrays_rejects_bad_arrays(fitted, change, words):
    arrays = fitted.to_arrays()
    change(arrays)
    with pytest.raises(ValueError, match=words):
        ICFN.from_arrays(arrays, fitted.get_params())


def test_from_arrays_rejects_params_that_do_not_fit(fitted):
    params = {**fitted.get_params(), "hidden_layer_sizes": (32, 16)}
    with pytest.raises(ValueError, match="shape"):
        ICFN.from_arrays(fitted.to_arrays(), params)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_constant_feature_is_harmless():
    X, y = make_data(300, seed=4)
    X[:, 3] = 40.0
    est = ICFN(hidden_layer_sizes=(16,), max_iter=50).fit(X, y)
    assert est.x_scale_[3] == 1.0
    assert np.isfinite(est.predict(X)).all()


def test_bad_inputs_raise(data, fitted):
    X, y = data
    bad = X[:100].copy()
    bad[3, 1] = np.nan
    est = ICFN(**SMALL)
    with pytest.raises(ValueError, match="NaN"):
        est.fit(bad, y[:100])
    y_inf = y[:100].copy()
    y_inf[0] = np.inf
    with pytest.raises(ValueError, match="infinity"):
        est.fit(X[:100], y_inf)
    with pytest.raises(ValueError, match="inconsistent"):
        est.fit(X[:100], y[:99])
    with pytest.raises(ValueError, match="2D"):
        est.fit(X[:, 0], y)
    with pytest.raises(ValueError, match="at least"):
        est.fit(X[:5], y[:5])
    with pytest.raises(ValueError, match="2-D"):
        fitted.predict(X[0])
    with pytest.raises(ValueError, match="features"):
        fitted.predict(X[:, :3])
    with pytest.raises(ValueError, match="NaN"):
        fitted.predict(bad)
    with pytest.raises(ValueError, match="shape"):
        fitted.predict_one(X[0, :3])
    with pytest.raises(ValueError, match="shape"):
        fitted.predict_one(X[:2])


def test_unfitted_estimator_raises_not_fitted(data):
    X, _ = data
    est = ICFN()
    for call in (lambda: est.predict(X), lambda: est.predict_one(X[0]), est.to_arrays):
        with pytest.raises(NotFittedError):
            call()


def test_sklearn_conventions(fitted):
    fresh = clone(fitted)
    assert fresh.get_params() == fitted.get_params()
    assert not hasattr(fresh, "coefs_")
    assert "ICFN" in repr(fitted)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_select_icfn_picks_lowest_validation_mae():
    X, y = make_data(600, seed=5)
    X_val, y_val = make_data(200, seed=6)
    candidates = [
        {"hidden_layer_sizes": (4,), "max_iter": 150},
        {"hidden_layer_sizes": (24, 24), "max_iter": 150},
        {"hidden_layer_sizes": (24, 24), "alpha": 1.0, "max_iter": 150},
    ]
    best, table = select_icfn(X, y, X_val, y_val, candidates=candidates, random_state=3)
    assert len(table) == len(candidates)
    assert set(table[0]) == {"params", "val_mae_n", "val_rmse_n", "n_iter", "fit_s"}
    maes = [row["val_mae_n"] for row in table]
    winner = table[int(np.argmin(maes))]
    assert best.get_params() == winner["params"]
    assert all(row["params"]["random_state"] == 3 for row in table)
    assert all(row["val_rmse_n"] >= row["val_mae_n"] for row in table)
    err = best.predict(X_val) - y_val
    assert np.mean(np.abs(err)) == pytest.approx(min(maes), abs=1e-12)
    # Deterministic: the same candidate refitted predicts identically.
    again = ICFN(**winner["params"]).fit(X, y)
    np.testing.assert_array_equal(again.predict(X_val), best.predict(X_val))
    with pytest.raises(ValueError, match="features"):
        select_icfn(X, y, X_val[:, :3], y_val, candidates=candidates)


def test_ctrl_c_during_training_stops_the_fit(data, monkeypatch):
    """scikit-learn's MLP catches KeyboardInterrupt and returns half trained: `relaxgrip
    train` then saved that network and exited 0.  The interrupt now reaches the caller."""
    from sklearn.neural_network import MLPRegressor  # type: ignore[import-untyped]

    calls = {"n": 0}
    original = MLPRegressor._backprop

    def interrupted(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 5:
            raise KeyboardInterrupt
        return original(self, *args, **kwargs)

    monkeypatch.setattr(MLPRegressor, "_backprop", interrupted)
    X, y = data
    with pytest.raises(KeyboardInterrupt):
        ICFN(**SMALL).fit(X, y)
    assert calls["n"] == 5
