"""Closed-form checks of the paper's error metrics (§V-B)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from relaxgrip.metrics import amplitude, auc_rel, curve_correlation, mae, nrmse, r2, rmse

# Non-uniform like the measured records: dense first, sparse later.
T_S = np.concatenate([np.arange(0.0, 2.0, 0.02), np.arange(2.0, 10.0, 0.5), [10.0, 30.0, 60.0]])
F_GT = 1.0 + 2.0 * np.exp(-T_S / 3.0)


@pytest.mark.parametrize("offset_n", [0.05, -0.3])
def test_constant_offset_closed_forms(offset_n: float) -> None:
    pred = F_GT + offset_n
    span = float(F_GT.max() - F_GT.min())
    duration = float(T_S[-1] - T_S[0])
    # int F_gt dt for 1 + 2 e^{-t/3} is exact up to the trapezoid error; use the same rule.
    area = float(np.trapezoid(F_GT, T_S))
    assert nrmse(T_S, pred, F_GT) == pytest.approx(abs(offset_n) / span, rel=1e-12)
    assert auc_rel(T_S, pred, F_GT) == pytest.approx(abs(offset_n) * duration / area, rel=1e-12)
    assert mae(pred, F_GT) == pytest.approx(abs(offset_n), rel=1e-12)
    assert rmse(pred, F_GT) == pytest.approx(abs(offset_n), rel=1e-12)
    ss_tot = float(np.sum((F_GT - F_GT.mean()) ** 2))
    assert r2(pred, F_GT) == pytest.approx(1.0 - T_S.size * offset_n**2 / ss_tot, rel=1e-12)
    assert curve_correlation(pred, F_GT) == pytest.approx(1.0, abs=1e-12)


def test_nrmse_integrates_over_time_not_samples() -> None:
    # Error 1 on [0, 1] sampled at 101 points, error 0 at t = 3 (a single sparse sample):
    # the trapezoid rule gives int e^2 dt = 1 + (3 - 1) * (1 + 0) / 2 = 2 over T = 3.
    t = np.concatenate([np.linspace(0.0, 1.0, 101), [3.0]])
    gt = np.concatenate([np.zeros(101), [1.0]])
    pred = gt + np.concatenate([np.ones(101), [0.0]])
    assert nrmse(t, pred, gt) == pytest.approx(math.sqrt(2.0 / 3.0), rel=1e-12)
    # A per-sample mean would be dominated by the 101 dense samples instead.
    assert rmse(pred, gt) == pytest.approx(math.sqrt(101 / 102), rel=1e-12)


def test_time_metrics_do_not_depend_on_sampling_density() -> None:
    # Piecewise-linear curves: the trapezoid rule is exact for int (pred - gt) dt and int gt dt,
    # so inserting samples on the linear pieces leaves AUC_rel unchanged.
    def curves(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        gt = np.interp(t, [0.0, 4.0, 10.0], [3.0, 1.0, 1.0])
        pred = np.interp(t, [0.0, 4.0, 10.0], [2.5, 1.2, 0.9])
        return pred, gt

    coarse = np.array([0.0, 4.0, 10.0])
    fine = np.unique(np.concatenate([coarse, np.linspace(0.0, 4.0, 97), [7.3]]))
    assert auc_rel(fine, *curves(fine)) == pytest.approx(auc_rel(coarse, *curves(coarse)))
    # Exact value: int (pred - gt) = 4 (-0.5 + 0.2) / 2 + 6 (0.2 - 0.1) / 2, int gt = 8 + 6.
    assert auc_rel(coarse, *curves(coarse)) == pytest.approx(abs(-0.6 + 0.3) / 14.0)


def test_auc_rel_cancels_opposite_errors() -> None:
    t = np.linspace(0.0, 2.0, 200)  # no sample at t = 1: one interval straddles the sign change
    gt = np.full_like(t, 2.0)
    pred = gt + np.where(t < 1.0, 0.5, -0.5)
    # +0.5 on [0, t_99], -0.5 on [t_100, 2], and the straddling interval averages to zero.
    assert auc_rel(t, pred, gt) == pytest.approx(0.0, abs=1e-12)
    assert mae(pred, gt) == pytest.approx(0.5)


def test_amplitude_and_correlation() -> None:
    assert amplitude([3.0, 2.0, 1.25]) == pytest.approx(1.75)
    assert amplitude([1.0, 2.0]) == pytest.approx(-1.0)
    assert curve_correlation(-2.0 * F_GT + 5.0, F_GT) == pytest.approx(-1.0, abs=1e-12)
    x = np.array([1.0, 2.0, 3.0, 4.0])
    y = np.array([1.0, 3.0, 2.0, 4.0])
    assert curve_correlation(x, y) == pytest.approx(np.corrcoef(x, y)[0, 1], rel=1e-12)


def test_perfect_prediction() -> None:
    assert nrmse(T_S, F_GT, F_GT) == 0.0
    assert auc_rel(T_S, F_GT, F_GT) == 0.0
    assert r2(F_GT, F_GT) == 1.0
    assert rmse(F_GT, F_GT) == 0.0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: nrmse(T_S, F_GT[:-1], F_GT), "same shape"),
        (lambda: nrmse(T_S[:-1], F_GT, F_GT), "same shape"),
        (lambda: auc_rel(T_S[::-1], F_GT, F_GT), "strictly increasing"),
        (lambda: nrmse([0.0], [1.0], [1.0]), "at least 2"),
        (lambda: nrmse(T_S, F_GT, np.ones_like(T_S)), "constant"),
        (lambda: auc_rel(T_S, F_GT, np.zeros_like(T_S)), "zero"),
        (lambda: mae(np.ones((2, 3)), np.ones((2, 3))), "1-D"),
        (lambda: rmse([1.0, math.nan], [1.0, 2.0]), "non-finite"),
        (lambda: r2([1.0, 2.0], [3.0, 3.0]), "constant"),
        (lambda: curve_correlation([1.0, 1.0], [1.0, 2.0]), "constant"),
        (lambda: amplitude([]), "at least 1"),
    ],
)
def test_invalid_input_raises(call: Callable[[], float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()


def test_median_error_by_paper_force_range() -> None:
    from relaxgrip.metrics import median_ae_by_range

    gt = np.array([0.5, 0.9, 1.5, 3.0, 4.0, 6.0, 10.0])
    pred = gt + np.array([0.1, 0.3, -0.2, 0.5, -0.1, 1.0, 2.0])
    out = median_ae_by_range(pred, gt)
    assert list(out) == ["0-1", "1-2", "2-5", "5-10"]
    assert out["0-1"] == pytest.approx(0.2)
    assert out["1-2"] == pytest.approx(0.2)
    assert out["2-5"] == pytest.approx(0.3)
    assert out["5-10"] == pytest.approx(1.5)  # 10 N falls in the last range
    assert np.isnan(median_ae_by_range([3.0], [3.0], ((0.0, 1.0),))["0-1"])
