"""Error metrics between a predicted and a ground-truth force curve (paper §V-B).

The time-domain metrics (:func:`nrmse`, :func:`auc_rel`) integrate over time
with the trapezoid rule on the samples as given, so a record sampled densely
at the start and sparsely later is weighted by duration, not by sample count.
The pointwise metrics (:func:`mae`, :func:`rmse`, :func:`r2`,
:func:`curve_correlation`) treat every sample alike.

This module depends on NumPy only.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

__all__ = [
    "FORCE_RANGES_N",
    "amplitude",
    "auc_rel",
    "curve_correlation",
    "mae",
    "median_ae_by_range",
    "nrmse",
    "r2",
    "rmse",
]

#: The paper's force ranges for the ICFN's error breakdown (N), lower bound inclusive.
FORCE_RANGES_N: tuple[tuple[float, float], ...] = ((0.0, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 10.0))


def nrmse(t_s: ArrayLike, f_pred: ArrayLike, f_gt: ArrayLike) -> float:
    """Time-normalised RMSE over the range of the ground truth.

    ``sqrt((1/T) int (F_pred - F_gt)^2 dt) / (max F_gt - min F_gt)``, with
    ``T`` the record duration and the integral by the trapezoid rule.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Strictly increasing sample times (s), possibly non-uniform.
    f_pred : array_like, shape (n,)
        Predicted force (N).
    f_gt : array_like, shape (n,)
        Ground-truth force (N).

    Returns
    -------
    float
        Dimensionless NRMSE, ``>= 0``.

    Raises
    ------
    ValueError
        If the shapes differ, there are fewer than two samples, the times are
        not strictly increasing, a value is not finite, or ``f_gt`` is
        constant (its range is zero).
    """
    t, pred, gt = _timed(t_s, f_pred, f_gt)
    span = float(np.ptp(gt))
    if span == 0.0:
        raise ValueError("f_gt is constant: NRMSE is undefined (zero range)")
    mean_sq = _trapezoid((pred - gt) ** 2, t) / float(t[-1] - t[0])
    return math.sqrt(mean_sq) / span


def auc_rel(t_s: ArrayLike, f_pred: ArrayLike, f_gt: ArrayLike) -> float:
    """Relative area error ``|int (F_pred - F_gt) dt| / |int F_gt dt|``.

    Both integrals use the trapezoid rule.  Errors of opposite sign cancel:
    this measures bias in the impulse, not pointwise accuracy.  The paper's
    forces are positive; the absolute value in the denominator keeps the
    measure non-negative for compressive (negative) forces as well.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Strictly increasing sample times (s), possibly non-uniform.
    f_pred : array_like, shape (n,)
        Predicted force (N).
    f_gt : array_like, shape (n,)
        Ground-truth force (N).

    Returns
    -------
    float
        Dimensionless relative area error, ``>= 0``.

    Raises
    ------
    ValueError
        As :func:`nrmse`, and if ``int F_gt dt`` is zero.
    """
    t, pred, gt = _timed(t_s, f_pred, f_gt)
    area = _trapezoid(gt, t)
    if area == 0.0:
        raise ValueError("the ground-truth area int F_gt dt is zero: AUC_rel is undefined")
    return abs(_trapezoid(pred - gt, t)) / abs(area)


def amplitude(f_gt: ArrayLike) -> float:
    """Relaxation amplitude ``F_0 - F_end`` of a force curve.

    Parameters
    ----------
    f_gt : array_like, shape (n,)
        Force curve (N), first sample at the hold start.

    Returns
    -------
    float
        First minus last force (N); positive for a relaxing force.

    Raises
    ------
    ValueError
        If ``f_gt`` is not 1-D with at least one sample or has non-finite values.
    """
    (f,) = _curves(f_gt, min_size=1)
    return float(f[0] - f[-1])


def curve_correlation(f_pred: ArrayLike, f_gt: ArrayLike) -> float:
    """Pearson correlation coefficient between two curves.

    Parameters
    ----------
    f_pred : array_like, shape (n,)
        Predicted force (N).
    f_gt : array_like, shape (n,)
        Ground-truth force (N).

    Returns
    -------
    float
        Correlation in ``[-1, 1]``.

    Raises
    ------
    ValueError
        If the shapes differ, there are fewer than two samples, a value is not
        finite, or either curve is constant.
    """
    pred, gt = _curves(f_pred, f_gt, min_size=2)
    dp, dg = pred - pred.mean(), gt - gt.mean()
    norm = math.sqrt(float(dp @ dp) * float(dg @ dg))
    if norm == 0.0:
        raise ValueError("a constant curve has no correlation coefficient")
    return float(np.clip(float(dp @ dg) / norm, -1.0, 1.0))


def mae(f_pred: ArrayLike, f_gt: ArrayLike) -> float:
    """Mean absolute error over the samples.

    Parameters
    ----------
    f_pred : array_like, shape (n,)
        Predicted values.
    f_gt : array_like, shape (n,)
        Ground-truth values.

    Returns
    -------
    float
        ``mean |f_pred - f_gt|``, in the unit of the inputs.

    Raises
    ------
    ValueError
        If the shapes differ, the arrays are empty or a value is not finite.
    """
    pred, gt = _curves(f_pred, f_gt, min_size=1)
    return float(np.mean(np.abs(pred - gt)))


def rmse(f_pred: ArrayLike, f_gt: ArrayLike) -> float:
    """Root-mean-square error over the samples.

    Parameters
    ----------
    f_pred : array_like, shape (n,)
        Predicted values.
    f_gt : array_like, shape (n,)
        Ground-truth values.

    Returns
    -------
    float
        ``sqrt(mean (f_pred - f_gt)^2)``, in the unit of the inputs.

    Raises
    ------
    ValueError
        If the shapes differ, the arrays are empty or a value is not finite.
    """
    pred, gt = _curves(f_pred, f_gt, min_size=1)
    return math.sqrt(float(np.mean((pred - gt) ** 2)))


def r2(f_pred: ArrayLike, f_gt: ArrayLike) -> float:
    """Coefficient of determination ``1 - SS_res / SS_tot``.

    Parameters
    ----------
    f_pred : array_like, shape (n,)
        Predicted values.
    f_gt : array_like, shape (n,)
        Ground-truth values.

    Returns
    -------
    float
        ``R²``; 1 for a perfect prediction, unbounded below.

    Raises
    ------
    ValueError
        If the shapes differ, there are fewer than two samples, a value is not
        finite, or ``f_gt`` is constant (``SS_tot = 0``).
    """
    pred, gt = _curves(f_pred, f_gt, min_size=2)
    ss_tot = float(np.sum((gt - gt.mean()) ** 2))
    if ss_tot == 0.0:
        raise ValueError("f_gt is constant: R² is undefined (zero total variance)")
    return 1.0 - float(np.sum((pred - gt) ** 2)) / ss_tot


def median_ae_by_range(
    f_pred: ArrayLike,
    f_gt: ArrayLike,
    ranges_n: tuple[tuple[float, float], ...] = FORCE_RANGES_N,
) -> dict[str, float]:
    """Median absolute error within ranges of the true force (paper Fig. "acc" b).

    Parameters
    ----------
    f_pred, f_gt : array_like, shape (n,)
        Predicted and true forces (N).
    ranges_n : tuple of (low, high)
        Ranges of the true force, ``low <= F < high`` (the last also takes ``F == high``).

    Returns
    -------
    dict
        ``"low-high"`` (e.g. ``"0-1"``) to the median absolute error (N); nan
        for a range with no samples.
    """
    pred, gt = _curves(f_pred, f_gt, min_size=1)
    error = np.abs(pred - gt)
    out = {}
    for k, (lo, hi) in enumerate(ranges_n):
        last = k == len(ranges_n) - 1
        inside = (gt >= lo) & ((gt <= hi) if last else (gt < hi))
        out[f"{lo:g}-{hi:g}"] = float(np.median(error[inside])) if inside.any() else math.nan
    return out


def _curves(*arrays: ArrayLike, min_size: int) -> list[FloatArray]:
    """Validate 1-D finite float arrays of one common length ``>= min_size``."""
    out = [np.asarray(a, dtype=np.float64) for a in arrays]
    shape = out[0].shape
    if len(shape) != 1:
        raise ValueError(f"expected 1-D arrays, got shape {shape}")
    for a in out[1:]:
        if a.shape != shape:
            raise ValueError(f"arrays must have the same shape, got {shape} and {a.shape}")
    if shape[0] < min_size:
        raise ValueError(f"need at least {min_size} samples, got {shape[0]}")
    if not all(np.all(np.isfinite(a)) for a in out):
        raise ValueError("arrays contain non-finite values")
    return out


def _timed(
    t_s: ArrayLike, f_pred: ArrayLike, f_gt: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Validate a time grid and two curves on it."""
    t, pred, gt = _curves(t_s, f_pred, f_gt, min_size=2)
    if np.any(np.diff(t) <= 0):
        raise ValueError("t_s must be strictly increasing")
    return t, pred, gt


def _trapezoid(y: FloatArray, t: FloatArray) -> float:
    """Trapezoid rule ``int y dt`` on a (possibly non-uniform) grid."""
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))
