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

The estimator asks the RCFN again at every frame of the hold, so it need not
predict one curve for the whole hold.  Several modes relax at once in the
finger, and one exponential cannot follow the fast start and the slow tail of
a 280 s hold together (fitted to the whole hold it correlates 0.98 with it):
the RCFN is trained on per-frame labels, the Eq. 10 curve that touches the
hold at that frame (:meth:`relaxgrip.learning.datastore.Dataset.rcfn_xy`),
and the time since the onset enters also as ``log(1 + t)``
(``time_column``), the scale on which relaxation proceeds.

Both regressors read the same features.  Temperature acts on relaxation
strongly and non-polynomially (slowly in the glassy state, steeply through
the transition), so the temperature column is first replaced by a
piecewise-linear ("hat") basis over the training range; the features are
then standardised, expanded into a polynomial of the chosen degree,
standardised again, and fitted by scikit-learn's
:class:`~sklearn.linear_model.Ridge`, one per target with its own penalty.
The relaxing share scatters multiplicatively (material, object, contact), so
its regressor fits ``log kappa``.  Coefficients are copied into arrays;
prediction is NumPy only, and :meth:`RCFN.relaxation` is a preplanned
per-frame fast path.
"""

from __future__ import annotations

import bisect
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

from relaxgrip.learning.icfn import _check_predict_X, _float_arrays, _location_scale

FloatArray = NDArray[np.float64]

__all__ = ["RCFN", "RCFN_ALPHAS", "RCFN_TARGETS", "n_poly_features", "reconstruct", "select_rcfn"]

#: The two targets, in column order of ``Y``: relaxing share and log relaxation time.
RCFN_TARGETS = ("kappa", "log_tau_s")
#: Default penalties :func:`select_rcfn` tries for each target.
RCFN_ALPHAS = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)
#: Inputs and ``log tau`` are clipped to their training range widened by this share of it.
RANGE_MARGIN = 0.1
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


def _hat_weights(t: FloatArray, knots: FloatArray) -> FloatArray:
    """Piecewise-linear basis of ``t`` on ``knots``, shape ``(n, len(knots))``.

    Each row holds the weights of linear interpolation between the two
    knots around ``t`` (they sum to 1); beyond the ends it is held at the end
    knot.
    """
    k = knots.size
    clipped = np.clip(t, knots[0], knots[-1])
    idx = np.clip(np.searchsorted(knots, clipped, side="right") - 1, 0, k - 2)
    w = (clipped - knots[idx]) / (knots[idx + 1] - knots[idx])
    out = np.zeros((t.size, k))
    rows = np.arange(t.size)
    out[rows, idx] = 1.0 - w
    out[rows, idx + 1] = w
    return out


def _basis(X: FloatArray, knots: FloatArray, column: int) -> FloatArray:
    """``X`` with column ``column`` replaced by its hat basis (first), if there are knots."""
    if knots.size == 0:
        return X
    rest = np.delete(X, column, axis=1)
    return np.hstack([_hat_weights(X[:, column], knots), rest])


def _with_log_time(X: FloatArray, Z: FloatArray, column: int | None) -> FloatArray:
    """``Z`` with ``log(1 + t)`` of ``X``'s time column appended (``column`` None: ``Z``)."""
    if column is None:
        return Z
    return np.hstack([Z, np.log1p(np.maximum(X[:, column], 0.0))[:, None]])


def _ranges(X: FloatArray, Y: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Training ranges of the features and of the ``log tau`` labels, widened by a margin."""
    lo, hi = X.min(axis=0), X.max(axis=0)
    margin = RANGE_MARGIN * (hi - lo)
    t_lo, t_hi = float(Y[:, 1].min()), float(Y[:, 1].max())
    t_margin = RANGE_MARGIN * (t_hi - t_lo)
    return lo - margin, hi + margin, np.array([t_lo - t_margin, t_hi + t_margin])


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
    temp_knots : int
        Knots of the temperature basis, spread evenly over the training range
        (0: temperature enters as it is).
    temp_column : int
        Which feature is the temperature.
    time_column : int or None
        Which feature is the time since the hold onset: ``log(1 + t)`` is
        appended to the features, the scale on which relaxation proceeds
        (None: no such column).
    log_kappa : bool
        Fit ``log kappa`` rather than ``kappa`` (predictions are ``kappa`` either way).

    Attributes
    ----------
    n_features_in_ : int
        Number of features seen in :meth:`fit`.
    n_output_features_ : int
        Number of expanded features.
    temp_knots_ : ndarray, shape (temp_knots,)
        Knot temperatures of the basis (empty without one).
    x_mean_, x_scale_ : ndarray, shape (n_basis_features,)
        Standardisation of the features after the temperature basis.
    phi_mean_, phi_scale_ : ndarray, shape (n_output_features_,)
        Standardisation of the expanded features.
    x_min_, x_max_ : ndarray, shape (n_features_in_,)
        Range of each feature in training (inputs are clipped to it).
    log_tau_range_ : ndarray, shape (2,)
        Range of the ``log tau`` labels in training (predictions are clipped to it).
    coef_ : ndarray, shape (n_output_features_, 2)
        Ridge coefficients, one column per target (``kappa``, ``log_tau_s``).
    intercept_ : ndarray, shape (2,)
        Ridge intercepts.

    Notes
    -----
    A polynomial extrapolates wildly: every feature is clipped to the range
    it had in training (widened by :data:`RANGE_MARGIN` of it) before the
    expansion, ``kappa`` to ``[0, 1]`` (a hold cannot lose more than its
    force) and ``log tau`` to the training labels' range (widened alike).
    :meth:`relaxation` reuses buffers owned by the estimator and is not
    re-entrant; give each thread its own copy.
    """

    def __init__(
        self,
        alpha_kappa: float = 1.0,
        alpha_log_tau: float = 1.0,
        degree: int = 2,
        temp_knots: int = 5,
        temp_column: int = 0,
        log_kappa: bool = True,
        time_column: int | None = None,
    ) -> None:
        self.alpha_kappa = alpha_kappa
        self.alpha_log_tau = alpha_log_tau
        self.degree = degree
        self.temp_knots = temp_knots
        self.temp_column = temp_column
        self.log_kappa = log_kappa
        self.time_column = time_column

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
        knots = self._knots_for(X_arr)
        design, phi = _Design.of(self._transform(X_arr, knots), self.degree)
        targets = self._internal_targets(Y_arr)
        fits = [
            _ridge(phi, targets[:, k], alpha)
            for k, alpha in enumerate((self.alpha_kappa, self.alpha_log_tau))
        ]
        self._set_learned(design, np.column_stack([c for c, _ in fits]), [b for _, b in fits],
                          knots, X_arr.shape[1], _ranges(X_arr, Y_arr))
        return self

    def _transform(self, X: FloatArray, knots: FloatArray) -> FloatArray:
        """Features after the temperature basis and the log-time column."""
        if self.time_column is not None and not 0 <= self.time_column < X.shape[1]:
            raise ValueError(f"time_column {self.time_column} is not a column of X")
        return _with_log_time(X, _basis(X, knots, self.temp_column), self.time_column)

    def _knots_for(self, X: FloatArray) -> FloatArray:
        """Knots spread over the training range of the temperature column."""
        if isinstance(self.temp_knots, bool) or self.temp_knots < 0 or self.temp_knots == 1:
            raise ValueError(f"temp_knots must be 0 or >= 2, got {self.temp_knots!r}")
        if self.temp_knots == 0:
            return np.zeros(0)
        if not 0 <= self.temp_column < X.shape[1]:
            raise ValueError(f"temp_column {self.temp_column} is not a column of X")
        lo, hi = float(X[:, self.temp_column].min()), float(X[:, self.temp_column].max())
        if not hi > lo:
            raise ValueError("the temperature column is constant: no basis to spread over it")
        return np.linspace(lo, hi, self.temp_knots)

    def _internal_targets(self, Y: FloatArray) -> FloatArray:
        """What the regressors fit: ``log kappa`` (if chosen) and ``log tau``."""
        if not self.log_kappa:
            return Y
        if (Y[:, 0] <= 0).any():
            raise ValueError("kappa must be > 0 to fit log kappa")
        return np.column_stack([np.log(Y[:, 0]), Y[:, 1]])

    def _set_learned(
        self,
        design: _Design,
        coef: FloatArray,
        intercept: Sequence[float],
        knots: FloatArray,
        n_features: int,
        ranges: tuple[FloatArray, FloatArray, FloatArray],
    ) -> None:
        self.x_min_, self.x_max_, self.log_tau_range_ = ranges
        self.temp_knots_ = knots
        self.x_mean_ = design.x_mean
        self.x_scale_ = design.x_scale
        self.phi_mean_ = design.phi_mean
        self.phi_scale_ = design.phi_scale
        self.coef_ = coef
        self.intercept_ = np.array(intercept, dtype=np.float64)
        self.n_features_in_ = n_features
        self.n_output_features_ = design.phi_mean.size
        self._plan: _RelaxationPlan | None = None
        # The fast path's temperature basis: plain floats and a reusable vector.
        self._knots_list = knots.tolist()
        self._expanded = np.zeros(design.x_mean.size)
        self._clipped = np.zeros(n_features)
        self._log_tau_bounds = (float(self.log_tau_range_[0]), float(self.log_tau_range_[1]))

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
        X_arr = np.clip(_check_predict_X(X, self.n_features_in_, "RCFN", "relaxation"),
                        self.x_min_, self.x_max_)
        Z = self._transform(X_arr, self.temp_knots_)
        phi = _poly_expand((Z - self.x_mean_) / self.x_scale_, self.degree)
        phi -= self.phi_mean_
        phi /= self.phi_scale_
        result: FloatArray = phi @ self.coef_ + self.intercept_
        if self.log_kappa:
            result[:, 0] = np.exp(np.minimum(result[:, 0], 0.0))
        np.clip(result[:, 0], 0.0, 1.0, out=result[:, 0])
        np.clip(result[:, 1], *self.log_tau_range_, out=result[:, 1])
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
            return kappa * f_inst_n, math.exp(log_tau)
        clipped = np.minimum(x, self.x_max_, out=self._clipped)
        np.maximum(clipped, self.x_min_, out=clipped)
        kappa, log_tau = plan(self._expand_one(clipped))
        kappa = math.exp(min(kappa, 0.0)) if self.log_kappa else min(max(kappa, 0.0), 1.0)
        lo, hi = self._log_tau_bounds
        return kappa * f_inst_n, math.exp(min(max(log_tau, lo), hi))

    def _expand_one(self, x: FloatArray) -> FloatArray:
        """One (clipped) vector through the temperature basis and the log-time column."""
        knots = self._knots_list
        if not knots and self.time_column is None:
            return x
        out = self._expanded
        k = len(knots)
        if k:
            out[:k] = 0.0
            t = min(max(x.item(self.temp_column), knots[0]), knots[-1])
            i = min(bisect.bisect_right(knots, t) - 1, k - 2)
            w = (t - knots[i]) / (knots[i + 1] - knots[i])
            out[i] = 1.0 - w
            out[i + 1] = w
        if k:  # every feature but the temperature, in order: two slices
            c = self.temp_column
            out[k : k + c] = x[:c]
            out[k + c : k + x.size - 1] = x[c + 1 :]
        else:
            out[: x.size] = x
        if self.time_column is not None:
            out[-1] = math.log1p(max(x.item(self.time_column), 0.0))
        return out

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
            "temp_knots": self.temp_knots_.copy(),
            "x_min": self.x_min_.copy(),
            "x_max": self.x_max_.copy(),
            "log_tau_range": self.log_tau_range_.copy(),
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
        expected = {"x_mean", "x_scale", "phi_mean", "phi_scale", "coef", "intercept",
                    "temp_knots", "x_min", "x_max", "log_tau_range"}
        got = _float_arrays(arrays, expected)
        if got["x_mean"].ndim != 1 or got["x_mean"].size == 0:
            shape = got["x_mean"].shape
            raise ValueError(f"array 'x_mean' must have shape (n_features,), got {shape}")
        d = got["x_mean"].size
        m = n_poly_features(d, est.degree)
        knots = got["temp_knots"]
        shapes = {
            "x_mean": (d,), "x_scale": (d,), "phi_mean": (m,), "phi_scale": (m,),
            "coef": (m, 2), "intercept": (2,), "temp_knots": (est.temp_knots,),
        }
        for name, shape in shapes.items():
            if got[name].shape != shape:
                raise ValueError(f"array '{name}' has shape {got[name].shape}, expected {shape}")
        if (got["x_scale"] <= 0).any() or (got["phi_scale"] <= 0).any():
            raise ValueError("scales must be > 0")
        if knots.size and not (np.diff(knots) > 0).all():
            raise ValueError("array 'temp_knots' must be increasing")
        design = _Design(got["x_mean"], got["x_scale"], got["phi_mean"], got["phi_scale"])
        n_features = (d - knots.size + 1 if knots.size else d) - (est.time_column is not None)
        for name, column in (("temp_column", est.temp_column), ("time_column", est.time_column)):
            if column is None and name == "time_column":
                continue
            if (isinstance(column, bool) or not isinstance(column, int | np.integer)
                    or not 0 <= column < n_features):
                raise ValueError(f"{name} must be a column of the {n_features} inputs, "
                                 f"got {column!r}")
        for name, shape in (("x_min", (n_features,)), ("x_max", (n_features,)),
                            ("log_tau_range", (2,))):
            if got[name].shape != shape:
                raise ValueError(f"array '{name}' has shape {got[name].shape}, expected {shape}")
        if (got["x_max"] < got["x_min"]).any() or got["log_tau_range"][1] < got["log_tau_range"][0]:
            raise ValueError("ranges must have min <= max")
        est._set_learned(design, got["coef"], got["intercept"].tolist(), knots, n_features,
                         (got["x_min"], got["x_max"], got["log_tau_range"]))
        return est


def select_rcfn(
    X_train: ArrayLike,
    Y_train: ArrayLike,
    X_val: ArrayLike,
    Y_val: ArrayLike,
    alphas: Sequence[float] = RCFN_ALPHAS,
    *,
    degree: int = 2,
    temp_knots: int = 5,
    log_kappa: bool = True,
    time_column: int | None = None,
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
    degree, temp_knots, log_kappa, time_column : int, int, bool, int or None
        The other hyperparameters, see :class:`RCFN`.

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
    probe = RCFN(degree=degree, temp_knots=temp_knots, log_kappa=log_kappa,
                 time_column=time_column)
    knots = probe._knots_for(X_tr)
    design, phi = _Design.of(probe._transform(X_tr, knots), degree)
    targets = probe._internal_targets(Y_tr)
    ranges = _ranges(X_tr, Y_tr)
    fits: list[list[tuple[FloatArray, float]]] = []
    table: list[dict[str, Any]] = []
    for alpha in alphas:
        start = time.perf_counter()
        pair = [_ridge(phi, targets[:, k], float(alpha)) for k in range(2)]
        fit_s = time.perf_counter() - start
        probe._set_learned(design, np.column_stack([c for c, _ in pair]), [b for _, b in pair],
                           knots, X_tr.shape[1], ranges)
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
        alpha_kappa=float(alphas[best_k]), alpha_log_tau=float(alphas[best_t]), degree=degree,
        temp_knots=temp_knots, log_kappa=log_kappa, time_column=time_column,
    )
    coef = np.column_stack([fits[best_k][0][0], fits[best_t][1][0]])
    best._set_learned(design, coef, [fits[best_k][0][1], fits[best_t][1][1]], knots,
                      X_tr.shape[1], ranges)
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
