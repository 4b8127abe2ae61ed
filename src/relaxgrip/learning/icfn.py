"""Instantaneous contact force network, ICFN (paper §IV-B).

The ICFN maps one ICFN feature vector (:data:`relaxgrip.perception.features.ICFN_SCHEMA`:
marker pose, squared translations, beam temperatures and thermal statistics, SI
units with temperatures in °C) to the instantaneous contact force ``F_inst`` (N)
of Eq. 10.

It is a small ReLU multilayer perceptron trained by scikit-learn's
:class:`~sklearn.neural_network.MLPRegressor` on standardised inputs and a
standardised target.  After training the weights are copied into plain arrays:
prediction is a NumPy forward pass that never calls scikit-learn, the model is
saved as arrays (:mod:`relaxgrip.learning.store`), and :meth:`ICFN.predict_one`
is a preplanned, allocation-free pass for the control loop's every frame.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, RegressorMixin  # type: ignore[import-untyped]
from sklearn.exceptions import NotFittedError  # type: ignore[import-untyped]
from sklearn.neural_network import MLPRegressor  # type: ignore[import-untyped]
from sklearn.utils.validation import check_X_y  # type: ignore[import-untyped]

FloatArray = NDArray[np.float64]

__all__ = ["ICFN", "ICFN_CANDIDATES", "select_icfn"]

#: Share of the training set MLPRegressor holds out for early stopping.
VALIDATION_FRACTION = 0.1
#: Epochs without improvement of the held-out score before training stops.
N_ITER_NO_CHANGE = 30
#: Smallest improvement of the held-out score that counts.
TOL = 1e-6
#: Fewest samples :meth:`ICFN.fit` accepts (two of them held out for early stopping).
MIN_SAMPLES = 20

#: Default grid of :func:`select_icfn`: three architectures × two L2 penalties.
ICFN_CANDIDATES: tuple[dict[str, Any], ...] = tuple(
    {"hidden_layer_sizes": hidden, "alpha": alpha}
    for hidden in ((64, 64), (128, 64), (64, 64, 32))
    for alpha in (1e-4, 1e-3)
)


def _location_scale(a: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Column means and standard deviations, with 1 for (numerically) constant columns.

    Parameters
    ----------
    a : ndarray, shape (n, d)
        Samples in rows.

    Returns
    -------
    mean, scale : ndarray, shape (d,)
        ``(a - mean) / scale`` is standardised; a column whose spread is zero or
        rounding noise (``<= 1e-12 |mean|``) gets scale 1, so it maps to 0.
    """
    mean = a.mean(axis=0)
    scale = a.std(axis=0)
    constant = scale <= 1e-12 * np.abs(mean)
    scale[constant] = 1.0
    return mean, scale


def _check_fit_data(X: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Validate training data: 2-D finite ``X``, 1-D finite ``y`` of the same length."""
    X_arr, y_arr = check_X_y(X, y, dtype=np.float64, y_numeric=True)
    return np.asarray(X_arr, dtype=np.float64), np.asarray(y_arr, dtype=np.float64)


def _check_predict_X(X: ArrayLike, n_features: int, model: str, one_path: str) -> FloatArray:
    """``X`` as a finite float matrix of ``n_features`` columns, or a ValueError saying why.

    ``one_path`` names the model's method for a single feature vector.
    """
    X_arr = np.asarray(X, dtype=np.float64)
    if X_arr.ndim != 2:
        raise ValueError(
            f"X must be 2-D (n_samples, n_features), got shape {X_arr.shape}; "
            f"use {one_path} for one feature vector"
        )
    if X_arr.shape[1] != n_features:
        raise ValueError(
            f"X has {X_arr.shape[1]} features, but {model} was fitted with {n_features}"
        )
    if not np.isfinite(X_arr).all():
        raise ValueError("X contains NaN or infinity")
    return X_arr


class _ForwardPlan:
    """Preallocated single-vector forward pass of a ReLU network.

    Input standardisation is folded into the first layer.  Each hidden layer's
    bias is carried as a ReLU threshold: with ``h_k = g_k + beta_k``,
    ``g_k = max(g_{k-1} W_k, -beta_k)`` and ``beta_k = beta_{k-1} W_k + b_k``
    (``beta_0 = 0``), so ``beta`` moves into the next layer and finally into
    the output's constant, which also takes the target's scaling.  Per call:
    one ``dot`` and one ``maximum`` (against an array, cheaper than against a
    scalar) per hidden layer, and a final ``dot`` -- no copies, no allocation
    besides the returned float.
    """

    __slots__ = ("constant", "layers", "n_features", "out_weights")

    def __init__(
        self,
        x_mean: FloatArray,
        x_scale: FloatArray,
        coefs: Sequence[FloatArray],
        intercepts: Sequence[FloatArray],
        y_mean: float,
        y_scale: float,
    ) -> None:
        self.n_features = x_mean.size
        # (x - m) / s @ W + b  ==  x @ (W / s) + (b - (m / s) @ W)
        weights = [coefs[0] / x_scale[:, None], *coefs[1:]]
        biases = [intercepts[0] - (x_mean / x_scale) @ coefs[0], *intercepts[1:]]
        layers: list[tuple[FloatArray, FloatArray, FloatArray]] = []
        beta = np.zeros(self.n_features)
        for w, b in zip(weights[:-1], biases[:-1], strict=True):
            beta = beta @ w + b
            layers.append((np.ascontiguousarray(w), np.empty(w.shape[1]), -beta))
        self.layers = tuple(layers)
        w_out = weights[-1][:, 0]
        self.out_weights = np.ascontiguousarray(w_out * y_scale)
        self.constant = float((beta @ w_out + biases[-1][0]) * y_scale + y_mean)

    def __call__(self, x: FloatArray) -> float:
        maximum = np.maximum
        g = x
        for w, out, threshold in self.layers:
            g.dot(w, out=out)
            g = maximum(out, threshold, out=out)
        return float(g.dot(self.out_weights)) + self.constant


#: What scikit-learn's MLP warns when Ctrl-C (or SIGTERM, which the command turns into
#: it) stops its training: it then returns the network half trained, as if done.
_INTERRUPTED = "Training interrupted by user"


@contextmanager
def _interrupt_kept() -> Iterator[None]:
    """Let Ctrl-C stop a fit: the MLP catches ``KeyboardInterrupt`` and returns half trained
    (``relaxgrip train`` went on to save such a network and exit 0)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=_INTERRUPTED, category=UserWarning)
        try:
            yield
        except UserWarning as exc:
            if _INTERRUPTED not in str(exc):
                raise
            raise KeyboardInterrupt from None


class ICFN(RegressorMixin, BaseEstimator):  # type: ignore[misc]
    """Instantaneous contact force network: a ReLU MLP from features to force (N).

    Parameters
    ----------
    hidden_layer_sizes : tuple of int
        Units of each hidden layer.
    alpha : float
        L2 penalty on the weights (on standardised data).
    learning_rate_init : float
        Adam's initial step size.
    max_iter : int
        Most training epochs; early stopping usually ends training sooner
        (held-out share :data:`VALIDATION_FRACTION`, patience
        :data:`N_ITER_NO_CHANGE` epochs, tolerance :data:`TOL`).
    random_state : int
        Seed of weight initialisation, batch shuffling and the early-stopping
        split: training is deterministic.

    Attributes
    ----------
    n_features_in_ : int
        Number of features seen in :meth:`fit`.
    n_iter_ : int
        Epochs run.
    x_mean_, x_scale_ : ndarray, shape (n_features_in_,)
        Feature standardisation (units of each feature).
    y_mean_, y_scale_ : float
        Target standardisation (N).
    coefs_ : list of ndarray
        Weight matrix of each layer, on standardised data (``coefs_[i]`` has
        shape ``(units_in, units_out)``; the last has one output unit).
    intercepts_ : list of ndarray
        Bias vector of each layer.

    Notes
    -----
    :meth:`predict_one` reuses buffers owned by the estimator: it is not
    re-entrant, so give each thread its own copy (``copy.deepcopy``), or call
    :meth:`predict`, which is.
    """

    def __init__(
        self,
        hidden_layer_sizes: tuple[int, ...] = (64, 64),
        alpha: float = 1e-4,
        learning_rate_init: float = 1e-3,
        max_iter: int = 2000,
        random_state: int = 0,
    ) -> None:
        self.hidden_layer_sizes = hidden_layer_sizes
        self.alpha = alpha
        self.learning_rate_init = learning_rate_init
        self.max_iter = max_iter
        self.random_state = random_state

    def _make_mlp(self) -> Any:
        """The scikit-learn regressor :meth:`fit` trains (on standardised data)."""
        return MLPRegressor(
            hidden_layer_sizes=tuple(self.hidden_layer_sizes),
            activation="relu",
            solver="adam",
            alpha=self.alpha,
            learning_rate_init=self.learning_rate_init,
            max_iter=self.max_iter,
            early_stopping=True,
            validation_fraction=VALIDATION_FRACTION,
            n_iter_no_change=N_ITER_NO_CHANGE,
            tol=TOL,
            random_state=self.random_state,
        )

    def fit(self, X: ArrayLike, y: ArrayLike) -> ICFN:
        """Train on features ``X`` and forces ``y``.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Feature vectors (units of the feature schema), finite.
        y : array_like, shape (n_samples,)
            Contact forces (N), finite.

        Returns
        -------
        ICFN
            ``self``, fitted.

        Raises
        ------
        ValueError
            Non-finite values, shapes that do not match, or fewer than
            :data:`MIN_SAMPLES` samples.
        """
        X_arr, y_arr = _check_fit_data(X, y)
        if X_arr.shape[0] < MIN_SAMPLES:
            raise ValueError(f"ICFN needs at least {MIN_SAMPLES} samples, got {X_arr.shape[0]}")
        x_mean, x_scale = _location_scale(X_arr)
        y_mean, y_scale = _location_scale(y_arr[:, None])
        mlp = self._make_mlp()
        with _interrupt_kept():
            mlp.fit((X_arr - x_mean) / x_scale, (y_arr - y_mean[0]) / y_scale[0])
        self.x_mean_ = x_mean
        self.x_scale_ = x_scale
        self.y_mean_ = float(y_mean[0])
        self.y_scale_ = float(y_scale[0])
        self.coefs_ = [np.array(c, dtype=np.float64) for c in mlp.coefs_]
        self.intercepts_ = [np.array(b, dtype=np.float64) for b in mlp.intercepts_]
        self.n_features_in_ = X_arr.shape[1]
        self.n_iter_ = int(mlp.n_iter_)
        self._plan: _ForwardPlan | None = None
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "coefs_"):
            raise NotFittedError(
                "This ICFN instance is not fitted yet. Call 'fit' (or 'from_arrays') first."
            )

    def predict(self, X: ArrayLike) -> FloatArray:
        """Instantaneous contact force of each feature vector.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features_in_)
            Feature vectors, finite.

        Returns
        -------
        ndarray, shape (n_samples,)
            Force (N).

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        ValueError
            ``X`` not 2-D, of the wrong width, or not finite.
        """
        self._check_fitted()
        X_arr = _check_predict_X(X, self.n_features_in_, "ICFN", "predict_one")
        h = (X_arr - self.x_mean_) / self.x_scale_
        for w, b in zip(self.coefs_[:-1], self.intercepts_[:-1], strict=True):
            h = h @ w
            h += b
            np.maximum(h, 0.0, out=h)
        out = h @ self.coefs_[-1] + self.intercepts_[-1]
        result: FloatArray = out[:, 0] * self.y_scale_ + self.y_mean_
        return result

    def _make_plan(self) -> _ForwardPlan:
        self._check_fitted()
        self._plan = _ForwardPlan(
            self.x_mean_, self.x_scale_, self.coefs_, self.intercepts_, self.y_mean_, self.y_scale_
        )
        return self._plan

    def predict_one(self, x: ArrayLike) -> float:
        """Force of one feature vector: the control loop's per-frame fast path.

        Equal to ``predict(x[None])[0]`` up to rounding (the standardisation is
        folded into the weights).  Not re-entrant (see the class notes); a
        non-finite entry gives a nan force rather than an exception.

        Parameters
        ----------
        x : array_like, shape (n_features_in_,)
            One feature vector.

        Returns
        -------
        float
            Force (N).

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        ValueError
            ``x`` is not a vector of ``n_features_in_`` numbers.
        """
        plan = getattr(self, "_plan", None)
        if plan is None:
            plan = self._make_plan()
        if type(x) is not np.ndarray or x.shape != (plan.n_features,) or x.dtype != np.float64:
            x = np.asarray(x, dtype=np.float64)
            if x.shape != (plan.n_features,):
                raise ValueError(
                    f"x must have shape ({plan.n_features},), got {x.shape}; use predict for 2-D"
                )
        return plan(x)

    def __getstate__(self) -> dict[str, Any]:
        # The forward plan holds views into its own buffers, which copying would
        # sever; it is rebuilt on the next predict_one.
        state = dict(super().__getstate__())
        state.pop("_plan", None)
        return state

    def to_arrays(self) -> dict[str, FloatArray]:
        """Every learned array, for saving without pickle.

        Returns
        -------
        dict of str to ndarray
            ``x_mean``, ``x_scale``, ``y_mean``, ``y_scale``, ``n_iter`` (0-d),
            ``coef_<i>`` and ``intercept_<i>`` per layer.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        """
        self._check_fitted()
        arrays = {
            "x_mean": self.x_mean_.copy(),
            "x_scale": self.x_scale_.copy(),
            "y_mean": np.array(self.y_mean_),
            "y_scale": np.array(self.y_scale_),
            "n_iter": np.array(float(self.n_iter_)),
        }
        for i, (w, b) in enumerate(zip(self.coefs_, self.intercepts_, strict=True)):
            arrays[f"coef_{i}"] = w.copy()
            arrays[f"intercept_{i}"] = b.copy()
        return arrays

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, ArrayLike], params: Mapping[str, Any]) -> ICFN:
        """Rebuild a fitted estimator from :meth:`to_arrays` and :meth:`get_params`.

        Parameters
        ----------
        arrays : mapping of str to array_like
            The learned arrays, as :meth:`to_arrays` returns them.
        params : mapping
            The hyperparameters (``get_params()``; a list for
            ``hidden_layer_sizes`` is accepted, as JSON gives it back).

        Returns
        -------
        ICFN
            A fitted estimator with the same predictions.

        Raises
        ------
        ValueError
            An array missing, unexpected, not finite, or of a shape that does
            not fit ``params``.
        TypeError
            An unknown parameter.
        """
        kwargs = dict(params)
        if "hidden_layer_sizes" in kwargs:
            kwargs["hidden_layer_sizes"] = tuple(int(h) for h in kwargs["hidden_layer_sizes"])
        est = cls(**kwargs)
        hidden = tuple(est.hidden_layer_sizes)
        n_layers = len(hidden) + 1
        expected = {"x_mean", "x_scale", "y_mean", "y_scale", "n_iter"}
        expected |= {f"{kind}_{i}" for i in range(n_layers) for kind in ("coef", "intercept")}
        got = _float_arrays(arrays, expected)
        d = got["x_mean"].shape[0] if got["x_mean"].ndim == 1 else 0
        if d == 0:
            shape = got["x_mean"].shape
            raise ValueError(f"array 'x_mean' must have shape (n_features,), got {shape}")
        units = (d, *hidden, 1)
        shapes: dict[str, tuple[int, ...]] = {
            "x_mean": (d,), "x_scale": (d,), "y_mean": (), "y_scale": (), "n_iter": (),
        }
        for i in range(n_layers):
            shapes[f"coef_{i}"] = (units[i], units[i + 1])
            shapes[f"intercept_{i}"] = (units[i + 1],)
        for name, shape in shapes.items():
            if got[name].shape != shape:
                raise ValueError(f"array '{name}' has shape {got[name].shape}, expected {shape}")
        if (got["x_scale"] <= 0).any() or got["y_scale"] <= 0:
            raise ValueError("scales must be > 0")
        est.x_mean_ = got["x_mean"]
        est.x_scale_ = got["x_scale"]
        est.y_mean_ = float(got["y_mean"])
        est.y_scale_ = float(got["y_scale"])
        est.coefs_ = [got[f"coef_{i}"] for i in range(n_layers)]
        est.intercepts_ = [got[f"intercept_{i}"] for i in range(n_layers)]
        est.n_features_in_ = d
        est.n_iter_ = int(got["n_iter"])
        est._plan = None
        return est


def _float_arrays(arrays: Mapping[str, ArrayLike], expected: set[str]) -> dict[str, FloatArray]:
    """Check that ``arrays`` holds exactly ``expected``, all finite reals; float64 copies."""
    missing = sorted(expected - set(arrays))
    if missing:
        raise ValueError(f"missing array(s) {', '.join(repr(m) for m in missing)}")
    unexpected = sorted(set(arrays) - expected)
    if unexpected:
        raise ValueError(f"unexpected array(s) {', '.join(repr(u) for u in unexpected)}")
    out: dict[str, FloatArray] = {}
    for name in sorted(expected):
        raw = np.asarray(arrays[name])
        if raw.dtype.kind not in "fiu":
            raise ValueError(f"array '{name}' has dtype {raw.dtype}, expected real numbers")
        a = np.array(raw, dtype=np.float64)
        if not np.isfinite(a).all():
            raise ValueError(f"array '{name}' contains NaN or infinity")
        out[name] = a
    return out


def select_icfn(
    X_train: ArrayLike,
    y_train: ArrayLike,
    X_val: ArrayLike,
    y_val: ArrayLike,
    candidates: Sequence[Mapping[str, Any]] | None = None,
    random_state: int = 0,
) -> tuple[ICFN, list[dict[str, Any]]]:
    """Fit each candidate on the training set and keep the best on the validation set.

    Parameters
    ----------
    X_train, y_train : array_like, shapes (n, d) and (n,)
        Training features and forces (N).
    X_val, y_val : array_like, shapes (m, d) and (m,)
        Validation features and forces (N).
    candidates : sequence of mapping, optional
        :class:`ICFN` hyperparameters of each candidate (default
        :data:`ICFN_CANDIDATES`); ``random_state`` is filled in unless given.
    random_state : int
        Seed of every candidate: selection is deterministic.

    Returns
    -------
    best : ICFN
        The fitted candidate with the lowest validation MAE (the first, on a tie).
    table : list of dict
        Per candidate, in order: ``params`` (all hyperparameters),
        ``val_mae_n``, ``val_rmse_n`` (N), ``n_iter`` and ``fit_s`` (wall time, s).
    """
    grid = ICFN_CANDIDATES if candidates is None else tuple(candidates)
    if not grid:
        raise ValueError("select_icfn needs at least one candidate")
    X_tr, y_tr = _check_fit_data(X_train, y_train)
    X_va, y_va = _check_fit_data(X_val, y_val)
    if X_va.shape[1] != X_tr.shape[1]:
        raise ValueError(
            f"X_val has {X_va.shape[1]} features but X_train has {X_tr.shape[1]}"
        )
    table: list[dict[str, Any]] = []
    best: ICFN | None = None
    best_mae = np.inf
    for candidate in grid:
        est = ICFN(**{"random_state": random_state, **candidate})
        start = time.perf_counter()
        est.fit(X_tr, y_tr)
        fit_s = time.perf_counter() - start
        err = est.predict(X_va) - y_va
        mae = float(np.mean(np.abs(err)))
        table.append({
            "params": est.get_params(),
            "val_mae_n": mae,
            "val_rmse_n": float(np.sqrt(np.mean(err * err))),
            "n_iter": est.n_iter_,
            "fit_s": fit_s,
        })
        if mae < best_mae:
            best, best_mae = est, mae
    assert best is not None
    return best, table
