"""Relaxation compensation model, RCFN (paper §IV-B, Eq. 10).

During holding the force follows the reduced model of Eq. 9::

    F(t) = F_inst - K (1 - exp(-t / tau))

and the paper's RCFN is two Ridge regressors predicting the relaxation
magnitude ``K`` and ``log tau`` from the thermal and kinematic context
(:data:`relaxgrip.perception.features.RCFN_SCHEMA`: temperature, pose at
contact onset, current pose, pose velocity).  By Eq. 7, ``K = X0 sum k_i`` and
``F_inst = X0 (k_e + sum k_i)``, so the relaxing share
``kappa = K / F_inst = sum k_i / (k_e + sum k_i)`` is a property of the
material state, independent of the load: the first regressor predicts
``kappa`` and ``K_hat = kappa_hat * F_inst_hat``.

Both regressors read the same features: standardised, expanded into a
polynomial of the chosen degree, standardised again, then fitted by
scikit-learn's :class:`~sklearn.linear_model.Ridge`, one per target with its
own penalty.  Coefficients are copied into arrays; prediction is NumPy only,
and :meth:`RCFN.relaxation` is a preplanned per-frame fast path.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations_with_replacement
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator  # type: ignore[import-untyped]
from sklearn.exceptions import NotFittedError  # type: ignore[import-untyped]
from sklearn.linear_model import Ridge  # type: ignore[import-untyped]
from sklearn.utils.validation import check_X_y  # type: ignore[import-untyped]

from relaxgrip.learning.icfn import _float_arrays, _location_scale

FloatArray = NDArray[np.float64]

__all__ = ["RCFN", "RCFN_ALPHAS", "RCFN_TARGETS", "n_poly_features", "reconstruct", "select_rcfn"]

#: The two targets, in column order of ``Y``: relaxing share and log relaxation time.
RCFN_TARGETS = ("kappa", "log_tau_s")
#: Default penalties :func:`select_rcfn` tries for each target.
RCFN_ALPHAS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0)
#: Fewest samples :meth:`RCFN.fit` accepts.
MIN_SAMPLES = 2


def n_poly_features(n_features: int, degree: int) -> int:
    """Number of monomials of degree 1 to ``degree`` in ``n_features`` variables.

    Parameters
    ----------
    n_features : int
        Input width ``d``.
    degree : int
        Highest total degree, ``>= 1``.

    Returns
    -------
    int
        ``C(d + degree, degree) - 1`` (no constant term).
    """
    return math.comb(n_features + degree, degree) - 1


def _poly_expand(Z: FloatArray, degree: int) -> FloatArray:
    """All monomials of degree 1..``degree`` of the columns of ``Z``.

    Column order is scikit-learn's ``PolynomialFeatures(degree,
    include_bias=False)``: by degree, then
    ``itertools.combinations_with_replacement`` order (lexicographic in the
    sorted index tuple).  Each degree's block is built from the previous one,
    multiplying the term ``(i, ..., j)`` by columns ``j..d-1``.

    Parameters
    ----------
    Z : ndarray, shape (n, d)
        Inputs (standardised).
    degree : int
        Highest degree, ``>= 1``.

    Returns
    -------
    ndarray, shape (n, n_poly_features(d, degree))
    """
    n, d = Z.shape
    out = np.empty((n, n_poly_features(d, degree)))
    out[:, :d] = Z
    prev_start, prev_last = 0, list(range(d))
    pos = d
    for _ in range(2, degree + 1):
        last: list[int] = []
        for c, j in enumerate(prev_last):
            width = d - j
            np.multiply(out[:, prev_start + c, None], Z[:, j:], out=out[:, pos : pos + width])
            pos += width
            last += range(j, d)
        prev_start, prev_last = pos - len(last), last
    return out


class _RelaxationPlan:
    """Preallocated single-vector evaluation of both regressors (degree 1 or 2).

    Both standardisations and the intercepts are folded into one matrix per
    target acting on ``v = [x - x_mean, 1]``: target ``t`` is the bilinear form
    ``v . (A_t v)``, whose upper-left block holds the quadratic weights (upper
    triangle), the last column the linear weights and the corner the
    intercept.  Per call: one subtraction and two matrix-vector products
    (degree 1: one product with the linear rows only).
    """

    __slots__ = ("a", "av", "av_rows", "centred", "linear", "n_features", "v", "x_mean")

    def __init__(
        self,
        x_mean: FloatArray,
        x_scale: FloatArray,
        phi_mean: FloatArray,
        phi_scale: FloatArray,
        coef: FloatArray,
        intercept: FloatArray,
        degree: int,
    ) -> None:
        d = x_mean.size
        self.n_features = d
        self.x_mean = x_mean.copy()
        c = coef / phi_scale[:, None]
        b = intercept - phi_mean @ c
        # Linear rows: [l_t / x_scale, b_t], applied to v.
        self.linear = np.vstack([c[:d] / x_scale[:, None], b]).T.copy()
        self.v = np.ones(d + 1)
        self.centred = self.v[:d]
        self.a: FloatArray | None = None
        if degree == 2:
            a = np.zeros((2, d + 1, d + 1))
            i, j = np.array(list(combinations_with_replacement(range(d), 2))).T
            a[:, i, j] = (c[d:] / (x_scale[i] * x_scale[j])[:, None]).T
            a[:, :, d] = self.linear
            self.a = a.reshape(2 * (d + 1), d + 1)
        self.av = np.empty(2 * (d + 1))
        self.av_rows = self.av.reshape(2, d + 1)

    def __call__(self, x: ArrayLike) -> list[float]:
        np.subtract(x, self.x_mean, out=self.centred)
        if self.a is None:
            out: list[float] = self.linear.dot(self.v).tolist()
            return out
        self.a.dot(self.v, out=self.av)
        out = self.av_rows.dot(self.v).tolist()
        return out


def _check_targets(X: ArrayLike, Y: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Validate 2-D finite ``X`` and ``Y`` of shape ``(n, 2)``."""
    X_arr, Y_arr = check_X_y(X, Y, dtype=np.float64, multi_output=True, y_numeric=True)
    Y_arr = np.asarray(Y_arr, dtype=np.float64)
    if Y_arr.ndim != 2 or Y_arr.shape[1] != 2:
        raise ValueError(
            f"Y must have shape (n_samples, 2) with columns {list(RCFN_TARGETS)}, "
            f"got {Y_arr.shape}"
        )
    X_arr = np.asarray(X_arr, dtype=np.float64)
    if X_arr.shape[0] < MIN_SAMPLES:
        raise ValueError(f"RCFN needs at least {MIN_SAMPLES} samples, got {X_arr.shape[0]}")
    return X_arr, Y_arr


def _check_degree(degree: int) -> None:
    if isinstance(degree, bool) or not isinstance(degree, int | np.integer) or degree < 1:
        raise ValueError(f"degree must be an integer >= 1, got {degree!r}")


def _ridge(phi: FloatArray, y: FloatArray, alpha: float) -> tuple[FloatArray, float]:
    """Coefficients and intercept of one Ridge fit."""
    model = Ridge(alpha=alpha, fit_intercept=True).fit(phi, y)
    return np.array(model.coef_, dtype=np.float64), float(model.intercept_)


@dataclass
class _Design:
    """Standardisation statistics of the features and of their expansion."""

    x_mean: FloatArray
    x_scale: FloatArray
    phi_mean: FloatArray
    phi_scale: FloatArray

    @classmethod
    def of(cls, X: FloatArray, degree: int) -> tuple[_Design, FloatArray]:
        """Statistics of training features ``X`` and their standardised expansion."""
        x_mean, x_scale = _location_scale(X)
        phi = _poly_expand((X - x_mean) / x_scale, degree)
        phi_mean, phi_scale = _location_scale(phi)
        phi -= phi_mean
        phi /= phi_scale
        return cls(x_mean, x_scale, phi_mean, phi_scale), phi


class RCFN(BaseEstimator):  # type: ignore[misc]
    """Relaxation compensation model: features to relaxing share and log relaxation time.

    Parameters
    ----------
    alpha_kappa : float
        Ridge penalty of the ``kappa`` regressor (on standardised features).
    alpha_log_tau : float
        Ridge penalty of the ``log tau`` regressor.
    degree : int
        Degree of the polynomial feature expansion: 1 is linear in the
        standardised features, 2 adds their squares and pairwise products.

    Attributes
    ----------
    n_features_in_ : int
        Number of features seen in :meth:`fit`.
    n_output_features_ : int
        Number of expanded features.
    x_mean_, x_scale_ : ndarray, shape (n_features_in_,)
        Feature standardisation.
    phi_mean_, phi_scale_ : ndarray, shape (n_output_features_,)
        Standardisation of the expanded features.
    coef_ : ndarray, shape (n_output_features_, 2)
        Ridge coefficients, one column per target (``kappa``, ``log_tau_s``).
    intercept_ : ndarray, shape (2,)
        Ridge intercepts.

    Notes
    -----
    Predictions are not clipped: far outside the training data ``kappa`` may
    leave ``[0, 1)``.  :meth:`relaxation` reuses buffers owned by the
    estimator and is not re-entrant; give each thread its own copy.
    """

    def __init__(
        self, alpha_kappa: float = 1.0, alpha_log_tau: float = 1.0, degree: int = 2
    ) -> None:
        self.alpha_kappa = alpha_kappa
        self.alpha_log_tau = alpha_log_tau
        self.degree = degree

    def fit(self, X: ArrayLike, Y: ArrayLike) -> RCFN:
        """Fit both regressors.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Feature vectors (units of the feature schema), finite.
        Y : array_like, shape (n_samples, 2)
            Columns ``kappa`` (relaxing share ``K / F_inst``, dimensionless)
            and ``log_tau_s`` (natural log of the relaxation time in s).

        Returns
        -------
        RCFN
            ``self``, fitted.

        Raises
        ------
        ValueError
            Non-finite values, shapes that do not match, or a bad ``degree``.
        """
        _check_degree(self.degree)
        X_arr, Y_arr = _check_targets(X, Y)
        design, phi = _Design.of(X_arr, self.degree)
        fits = [
            _ridge(phi, Y_arr[:, k], alpha)
            for k, alpha in enumerate((self.alpha_kappa, self.alpha_log_tau))
        ]
        self._set_learned(design, np.column_stack([c for c, _ in fits]), [b for _, b in fits])
        return self

    def _set_learned(self, design: _Design, coef: FloatArray, intercept: Sequence[float]) -> None:
        self.x_mean_ = design.x_mean
        self.x_scale_ = design.x_scale
        self.phi_mean_ = design.phi_mean
        self.phi_scale_ = design.phi_scale
        self.coef_ = coef
        self.intercept_ = np.array(intercept, dtype=np.float64)
        self.n_features_in_ = design.x_mean.size
        self.n_output_features_ = design.phi_mean.size
        self._plan: _RelaxationPlan | None = None

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise NotFittedError(
                "This RCFN instance is not fitted yet. Call 'fit' (or 'from_arrays') first."
            )

    def predict(self, X: ArrayLike) -> FloatArray:
        """Relaxing share and log relaxation time of each feature vector.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features_in_)
            Feature vectors, finite.

        Returns
        -------
        ndarray, shape (n_samples, 2)
            Columns ``kappa`` (dimensionless) and ``log_tau_s`` (log of s).

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        ValueError
            ``X`` not 2-D, of the wrong width, or not finite.
        """
        self._check_fitted()
        X_arr = np.asarray(X, dtype=np.float64)
        if X_arr.ndim != 2:
            raise ValueError(
                f"X must be 2-D (n_samples, n_features), got shape {X_arr.shape}; "
                "use relaxation for one feature vector"
            )
        if X_arr.shape[1] != self.n_features_in_:
            raise ValueError(
                f"X has {X_arr.shape[1]} features, but RCFN was fitted with {self.n_features_in_}"
            )
        if not np.isfinite(X_arr).all():
            raise ValueError("X contains NaN or infinity")
        phi = _poly_expand((X_arr - self.x_mean_) / self.x_scale_, self.degree)
        phi -= self.phi_mean_
        phi /= self.phi_scale_
        result: FloatArray = phi @ self.coef_ + self.intercept_
        return result

    def _make_plan(self) -> _RelaxationPlan | None:
        self._check_fitted()
        if self.degree > 2:
            return None
        self._plan = _RelaxationPlan(
            self.x_mean_, self.x_scale_, self.phi_mean_, self.phi_scale_,
            self.coef_, self.intercept_, self.degree,
        )
        return self._plan

    def relaxation(self, x: ArrayLike, f_inst_n: float) -> tuple[float, float]:
        """Relaxation magnitude and time for one feature vector: the per-frame fast path.

        Parameters
        ----------
        x : array_like, shape (n_features_in_,)
            One feature vector.
        f_inst_n : float
            Instantaneous force at the hold onset (N), e.g. from the ICFN.

        Returns
        -------
        k_n : float
            Relaxation magnitude ``K = kappa * f_inst_n`` (N).
        tau_s : float
            Relaxation time ``exp(log_tau)`` (s).

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
        n = self.n_features_in_
        if getattr(x, "shape", None) != (n,):
            x = np.asarray(x, dtype=np.float64)
            if x.shape != (n,):
                raise ValueError(f"x must have shape ({n},), got {x.shape}; use predict for 2-D")
        if plan is None:
            kappa, log_tau = self.predict(np.asarray(x, dtype=np.float64)[None, :])[0].tolist()
        else:
            kappa, log_tau = plan(x)
        return kappa * f_inst_n, math.exp(log_tau)

    def __getstate__(self) -> dict[str, Any]:
        # The plan holds views into its own buffers, which copying would sever.
        state = dict(super().__getstate__())
        state.pop("_plan", None)
        return state

    def to_arrays(self) -> dict[str, FloatArray]:
        """Every learned array, for saving without pickle.

        Returns
        -------
        dict of str to ndarray
            ``x_mean``, ``x_scale``, ``phi_mean``, ``phi_scale``, ``coef``,
            ``intercept``.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            Before :meth:`fit`.
        """
        self._check_fitted()
        return {
            "x_mean": self.x_mean_.copy(),
            "x_scale": self.x_scale_.copy(),
            "phi_mean": self.phi_mean_.copy(),
            "phi_scale": self.phi_scale_.copy(),
            "coef": self.coef_.copy(),
            "intercept": self.intercept_.copy(),
        }

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, ArrayLike], params: Mapping[str, Any]) -> RCFN:
        """Rebuild a fitted estimator from :meth:`to_arrays` and :meth:`get_params`.

        Parameters
        ----------
        arrays : mapping of str to array_like
            The learned arrays, as :meth:`to_arrays` returns them.
        params : mapping
            The hyperparameters (``get_params()``).

        Returns
        -------
        RCFN
            A fitted estimator with the same predictions.

        Raises
        ------
        ValueError
            An array missing, unexpected, not finite, or of a shape that does
            not fit ``params``.
        TypeError
            An unknown parameter.
        """
        est = cls(**params)
        _check_degree(est.degree)
        expected = {"x_mean", "x_scale", "phi_mean", "phi_scale", "coef", "intercept"}
        got = _float_arrays(arrays, expected)
        if got["x_mean"].ndim != 1 or got["x_mean"].size == 0:
            shape = got["x_mean"].shape
            raise ValueError(f"array 'x_mean' must have shape (n_features,), got {shape}")
        d = got["x_mean"].size
        m = n_poly_features(d, est.degree)
        shapes = {
            "x_mean": (d,), "x_scale": (d,), "phi_mean": (m,), "phi_scale": (m,),
            "coef": (m, 2), "intercept": (2,),
        }
        for name, shape in shapes.items():
            if got[name].shape != shape:
                raise ValueError(f"array '{name}' has shape {got[name].shape}, expected {shape}")
        if (got["x_scale"] <= 0).any() or (got["phi_scale"] <= 0).any():
            raise ValueError("scales must be > 0")
        design = _Design(got["x_mean"], got["x_scale"], got["phi_mean"], got["phi_scale"])
        est._set_learned(design, got["coef"], got["intercept"].tolist())
        return est


def select_rcfn(
    X_train: ArrayLike,
    Y_train: ArrayLike,
    X_val: ArrayLike,
    Y_val: ArrayLike,
    alphas: Sequence[float] = RCFN_ALPHAS,
    *,
    degree: int = 2,
) -> tuple[RCFN, list[dict[str, Any]]]:
    """Choose each target's Ridge penalty by validation RMSE.

    The two regressors are independent, so each target takes the ``alpha``
    with the lowest validation RMSE of that target (the first, on a tie); the
    returned model equals ``RCFN(best_kappa, best_log_tau, degree).fit(X_train, Y_train)``.

    Parameters
    ----------
    X_train, Y_train : array_like, shapes (n, d) and (n, 2)
        Training features and targets (``kappa``, ``log_tau_s``).
    X_val, Y_val : array_like, shapes (m, d) and (m, 2)
        Validation features and targets.
    alphas : sequence of float
        Penalties to try, each ``> 0``.
    degree : int
        Polynomial degree of the expansion.

    Returns
    -------
    best : RCFN
        The fitted model with the chosen penalties.
    table : list of dict
        Per alpha, in order: ``alpha``, ``val_rmse_kappa``, ``val_rmse_log_tau``
        and ``fit_s`` (wall time of both fits, s).
    """
    _check_degree(degree)
    if not alphas or min(alphas) <= 0:
        raise ValueError(f"alphas must be a non-empty sequence of values > 0, got {alphas!r}")
    X_tr, Y_tr = _check_targets(X_train, Y_train)
    X_va, Y_va = _check_targets(X_val, Y_val)
    if X_va.shape[1] != X_tr.shape[1]:
        raise ValueError(f"X_val has {X_va.shape[1]} features but X_train has {X_tr.shape[1]}")
    design, phi = _Design.of(X_tr, degree)
    probe = RCFN(degree=degree)
    fits: list[list[tuple[FloatArray, float]]] = []
    table: list[dict[str, Any]] = []
    for alpha in alphas:
        start = time.perf_counter()
        pair = [_ridge(phi, Y_tr[:, k], float(alpha)) for k in range(2)]
        fit_s = time.perf_counter() - start
        probe._set_learned(design, np.column_stack([c for c, _ in pair]), [b for _, b in pair])
        rmse = np.sqrt(np.mean((probe.predict(X_va) - Y_va) ** 2, axis=0))
        fits.append(pair)
        table.append({
            "alpha": float(alpha),
            "val_rmse_kappa": float(rmse[0]),
            "val_rmse_log_tau": float(rmse[1]),
            "fit_s": fit_s,
        })
    best_k = int(np.argmin([row["val_rmse_kappa"] for row in table]))
    best_t = int(np.argmin([row["val_rmse_log_tau"] for row in table]))
    best = RCFN(
        alpha_kappa=float(alphas[best_k]), alpha_log_tau=float(alphas[best_t]), degree=degree
    )
    coef = np.column_stack([fits[best_k][0][0], fits[best_t][1][0]])
    best._set_learned(design, coef, [fits[best_k][0][1], fits[best_t][1][1]])
    return best, table


def reconstruct(
    t_s: ArrayLike, f_inst_n: ArrayLike, k_n: ArrayLike, tau_s: ArrayLike
) -> FloatArray:
    """Reconstructed holding force ``F = F_inst - K (1 - exp(-t / tau))`` (Eq. 10).

    Elementwise, with NumPy broadcasting, so each sample may have its own
    ``t``, ``F_inst``, ``K`` and ``tau``; the same formula as
    :func:`relaxgrip.physics.viscoelastic.reduced_force`.

    Parameters
    ----------
    t_s : array_like
        Times since the hold onset (s).
    f_inst_n : array_like
        Instantaneous force at the hold onset (N).
    k_n : array_like
        Relaxation magnitude ``K`` (N).
    tau_s : array_like
        Relaxation time (s), ``> 0``.

    Returns
    -------
    ndarray
        Force (N), of the broadcast shape of the inputs.

    Raises
    ------
    ValueError
        A relaxation time that is not ``> 0``, or shapes that do not broadcast.
    """
    t, f, k, tau = (np.asarray(a, dtype=np.float64) for a in (t_s, f_inst_n, k_n, tau_s))
    if not (tau > 0).all():
        raise ValueError("relaxation times tau_s must be > 0")
    result: FloatArray = f + k * np.expm1(-t / tau)
    return result
