"""``relax``'s error budget over many runs, and what their scatter explains (``relaxgrip budget``).

One hold's :meth:`~relaxgrip.experiments.controlled_hold.HoldResult.error_budget`
splits its mean estimate error over the steady state into the onset force,
Eq. 10's relaxation and the added closure.  Over seeds, the mean of each part
is the design's bias and its spread is what no bias correction removes.  This
module runs those holds and relates each part to the scatter the twin drew
for the run (ground truth, read here by an experiment only): each finger's
relaxing share, its rubbery share and its relaxation times, the contact
position and the ambient temperature.  The marker sits on finger 0; finger
1's draw is what no percept shows.

Two summaries bound what a redesign of the estimator could reach:

* ``bias_free_mae_n``: the mean of ``|total_i - mean_j≠i total_j|``, the
  estimate's error had its bias been measured on the other runs and taken
  off (leave-one-out, so it is not flattered by the run it scores).  The
  controller holds the estimate on the target within a few mN, so this is
  also the hold's MAE from the target such a correction would give.
* ``r2``: per part, the share of its variance across runs a least-squares
  fit on the logarithms of one finger's factors, on the other's, or on every
  draw predicts, each run left out of its own fit.  What finger 1's draw
  explains is out of reach of the one marker; what no draw explains is the
  ICFN's own per-run reading.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.control import check_target_n
from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import (
    PAPER_DURATION_S,
    HoldResult,
    check_hold_duration_s,
    check_hold_temp_c,
    map_holds,
    run_hold,
)
from relaxgrip.learning.store import ModelBundle

__all__ = ["BUDGET_PARTS", "SCATTER_GROUPS", "BudgetSurvey", "survey_budget"]

FloatArray = NDArray[np.float64]

#: The budget's parts, in the order they add up to ``total_n``.
BUDGET_PARTS = ("onset_n", "relaxation_n", "closure_n", "total_n")
#: The twin's draws each attribution fits on: per finger (logarithms of its
#: factors), the run's own, and all of them.
SCATTER_GROUPS: dict[str, tuple[str, ...]] = {
    "finger_0": ("relax_scale_0", "relax_scale_rubbery_0", "tau_scale_0"),
    "finger_1": ("relax_scale_1", "relax_scale_rubbery_1", "tau_scale_1"),
    "contact_ambient": ("contact_position_m", "ambient_c"),
}
SCATTER_GROUPS["all"] = tuple(k for group in SCATTER_GROUPS.values() for k in group)
_LOG_FACTORS = frozenset(SCATTER_GROUPS["finger_0"] + SCATTER_GROUPS["finger_1"])


@dataclass(frozen=True)
class BudgetSurvey:
    """Per-seed error budgets of ``relax`` holds under one condition.

    Attributes
    ----------
    target_n, temp_c, duration_s : float
        The holds' condition.
    seeds : list of int
    budgets : list of dict
        Each seed's :meth:`HoldResult.error_budget` with its ``mae_n``.
    scatter : list of dict
        Each seed's draw (:meth:`relaxgrip.twin.twin.TwinMaterial.scatter`).
    twin_version : str
    """

    target_n: float
    temp_c: float
    duration_s: float
    seeds: list[int]
    budgets: list[dict[str, float]]
    scatter: list[dict[str, float]]
    twin_version: str

    def column(self, name: str) -> FloatArray:
        """One budget part (or ``mae_n``) over the seeds, in seed order."""
        return np.array([b[name] for b in self.budgets])

    @property
    def part_names(self) -> tuple[str, ...]:
        """:data:`BUDGET_PARTS`, with the calibration and chain parts every run had."""
        extra = tuple(name for name in ("calibration_n", "chain_n")
                      if self.budgets and all(name in b for b in self.budgets))
        return (*BUDGET_PARTS[:-1], *extra, BUDGET_PARTS[-1])

    def parts(self) -> dict[str, dict[str, float]]:
        """Per part: mean, SD and range over the seeds (N)."""
        out = {}
        for name in self.part_names:
            v = self.column(name)
            out[name] = {"mean": float(v.mean()), "sd": float(v.std()),
                         "min": float(v.min()), "max": float(v.max())}
        return out

    def bias_free_mae_n(self) -> float:
        """Mean ``|total_i - mean of the other runs' totals|`` (N); NaN under two seeds."""
        total = self.column("total_n")
        n = total.size
        if n < 2:
            return float("nan")
        others = (total.sum() - total) / (n - 1)
        return float(np.mean(np.abs(total - others)))

    def r2(self) -> dict[str, dict[str, float]]:
        """Per part and scatter group, the variance share a fit predicts (leave-one-out R²).

        NaN where there are fewer than twice as many seeds as the fit has
        coefficients and two more (10 for a finger, 20 for every draw), or the
        part does not vary.
        """
        out: dict[str, dict[str, float]] = {}
        for part in self.part_names:
            y = self.column(part)
            out[part] = {group: _explained(self._design(keys), y)
                         for group, keys in SCATTER_GROUPS.items()}
        return out

    def _design(self, keys: Sequence[str]) -> FloatArray:
        cols = [[s[k] for s in self.scatter] for k in keys]
        x = np.array(cols, dtype=np.float64).T
        for j, k in enumerate(keys):
            if k in _LOG_FACTORS:
                x[:, j] = np.log(x[:, j])
        return x

    def to_dict(self) -> dict[str, Any]:
        """The ``relaxgrip budget --json`` object."""
        return {
            "twin_version": self.twin_version, "estimator": "relax",
            "target_n": self.target_n, "temp_c": self.temp_c, "duration_s": self.duration_s,
            "seeds": self.seeds, "mae_n": float(self.column("mae_n").mean()),
            "parts": self.parts(), "bias_free_mae_n": self.bias_free_mae_n(),
            "r2": self.r2(),
            "runs": [{"seed": s, **b, "twin_scatter": d}
                     for s, b, d in zip(self.seeds, self.budgets, self.scatter, strict=True)],
        }


def _explained(x: FloatArray, y: FloatArray) -> float:
    """Leave-one-out R² of ``y`` on ``x`` with an intercept (``1 - PRESS / SS``).

    Each run is predicted by the fit on the others, so a draw that explains
    nothing scores about 0 or below, however few the runs.  NaN with fewer
    runs than twice the coefficients and two more, or if ``y`` is constant.
    """
    n, k = x.shape
    ss = float(np.sum((y - y.mean()) ** 2))
    if n < 2 * (k + 1) + 2 or ss <= 0.0:
        return float("nan")
    design = np.column_stack([x, np.ones(n)])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    hat = np.einsum("ij,ji->i", design, np.linalg.pinv(design))
    loo = (y - design @ coef) / (1.0 - hat)
    return float(1.0 - loo @ loo / ss)


def _one(args: tuple[int, float, float, float, ModelBundle | None]) -> HoldResult:
    seed, target_n, temp_c, duration_s, models = args
    return run_hold("relax", target_n, duration_s, temp_c, seed, models, budget=True)


def survey_budget(seeds: Sequence[int], target_n: float = 5.0, temp_c: float = 40.0,
                  duration_s: float = PAPER_DURATION_S, models: ModelBundle | None = None,
                  n_jobs: int = 1) -> BudgetSurvey:
    """Run ``relax`` holds with an error budget on every seed (``n_jobs`` at once).

    Parameters
    ----------
    seeds : sequence of int
        Twin seeds, at least one.
    target_n, temp_c, duration_s : float
        The holds' condition (checked as :func:`run_hold` checks it).
    models : ModelBundle, optional
        ICFN and RCFN (default: the shipped models).
    n_jobs : int
        Holds in parallel.

    Raises
    ------
    InputError
        No seeds, a negative one, or a condition :func:`run_hold` refuses;
        checked before any hold starts.
    """
    if not seeds:
        raise InputError("an error-budget survey needs at least one seed")
    if min(seeds) < 0:
        raise InputError(f"seeds must be >= 0, got {min(seeds)}")
    check_target_n(target_n)
    check_hold_temp_c(temp_c)
    check_hold_duration_s(duration_s)
    holds = map_holds(_one, [(int(s), target_n, temp_c, duration_s, models) for s in seeds],
                      n_jobs)
    budgets, scatter = [], []
    for hold in holds:
        assert hold.twin_scatter is not None  # a budgeted twin hold carries its draw
        budgets.append({**hold.error_budget(), "mae_n": hold.metrics()["mae_n"]})
        scatter.append(hold.twin_scatter)
    return BudgetSurvey(target_n, temp_c, duration_s, [int(s) for s in seeds], budgets,
                        scatter, holds[0].twin_version)
