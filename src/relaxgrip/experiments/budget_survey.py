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

And one measures what the estimator could learn of its own run:

* ``observability``: what the estimator reads by the steady state's start
  (:data:`PERCEPTS`, from its own series, never the truth; at
  :func:`percept_at_s`, 100 s of a 280 s hold, scaled with the duration), each
  correlated across runs with each finger's relaxing share; and the MAE a
  per-run correction would leave, fitted (each run left out) on those
  percepts, on finger 0's true share, or on both fingers' true shares.  A
  correction on the percepts can only reach what they show of the draw.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
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
    steady_window_s,
)
from relaxgrip.experiments.hold_calibration import icfn_drift_n
from relaxgrip.learning.hold_bias import drift_windows
from relaxgrip.learning.store import ModelBundle
from relaxgrip.validate import check_seeds

__all__ = ["BUDGET_PARTS", "PERCEPTS", "SCATTER_GROUPS", "BudgetSurvey", "hold_percepts",
           "percept_at_s", "survey_budget"]

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
#: Each finger's relaxing share, the draw the percepts are set against.
_SHARES = {"finger_0": "relax_scale_0", "finger_1": "relax_scale_1"}

#: What ``relax`` reads of its own run (its series, no truth): ``F_inst``; the
#: per-frame ICFN's drift since the hold's first seconds (the marker finger's
#: creep); the motor's travel since the onset; Eq. 10's ``K`` and ``tau``; and
#: what the closed chain's reading adds.
PERCEPTS = ("f_onset_n", "icfn_drift_n", "motor_travel_mm", "k_n", "tau_s", "chain_n")


def percept_at_s(duration_s: float) -> float:
    """Time into a hold of ``duration_s`` the percepts are read at (s).

    The steady state's start (:func:`~relaxgrip.experiments.controlled_hold.steady_window_s`:
    100 s of a 280 s hold, 5 s of a 14 s one), from which a correction on them
    would count in full.
    """
    return steady_window_s(duration_s)[0]


def hold_percepts(hold: HoldResult, at_s: float | None = None) -> dict[str, float]:
    """:data:`PERCEPTS` of one hold, read ``at_s`` into it (default :func:`percept_at_s`).

    Means over the ICFN drift's late window before that time (the 5 s
    before it), the drift from its early one (1-4 s after the onset), as
    ``relax`` reads it (:func:`relaxgrip.learning.hold_bias.drift_windows`);
    in a hold shorter than the paper's both shrink with it, as the read
    time does, so that they stay apart (a 14 s hold: the drift from
    0.05-0.2 s, read over 4.75-5 s), to no less than three frames (a 1 s
    hold: from 0.0036-0.1036 s, over 0.2571-0.3571 s).  NaN where the
    estimator had no value there (``chain_n`` without a chain blended in).
    """
    at = percept_at_s(hold.duration_s) if at_s is None else min(at_s, hold.duration_s)
    scale = min(1.0, hold.duration_s / PAPER_DURATION_S)
    t = hold.t_s

    def mean(name: str, lo: float, hi: float) -> float:
        values = hold.series(name)[(t >= lo - 1e-9) & (t <= hi + 1e-9)]
        values = values[np.isfinite(values)]
        return float(values.mean()) if values.size else float("nan")

    windows = drift_windows(at, scale)
    lo = windows[1][0]
    f_onset = hold.series("f_onset_n")
    f_onset = f_onset[np.isfinite(f_onset)]
    motor = hold.series("motor_mm")
    return {
        "f_onset_n": float(f_onset[-1]) if f_onset.size else float("nan"),
        "icfn_drift_n": icfn_drift_n(t, hold.series("icfn_n"), windows),
        "motor_travel_mm": mean("motor_mm", lo, at) - float(motor[0]),
        "k_n": mean("k_n", lo, at),
        "tau_s": mean("tau_s", lo, at),
        "chain_n": mean("chain_n", lo, at),
    }


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
    percepts : list of dict
        Each seed's :func:`hold_percepts` (empty: not read).
    """

    target_n: float
    temp_c: float
    duration_s: float
    seeds: list[int]
    budgets: list[dict[str, float]]
    scatter: list[dict[str, float]]
    twin_version: str
    percepts: list[dict[str, float]] = field(default_factory=list)

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
        """Per part: mean, SD (the sample's, as ``hold --seeds`` gives) and range over the
        seeds (N)."""
        out = {}
        for name in self.part_names:
            v = self.column(name)
            sd = float(v.std(ddof=1)) if v.size > 1 else math.nan
            out[name] = {"mean": float(v.mean()), "sd": sd,
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

    def observability(self) -> dict[str, Any]:
        """What the estimator's percepts show of the draw, and what correcting on them would reach.

        Returns
        -------
        dict
            ``correlation``: per percept (those finite in every run) and for
            ``total_n``, its correlation across runs with the logarithm of
            each finger's relaxing share (``finger_0``, ``finger_1``) and with
            ``total_n``.  ``corrected_mae_n``: the mean ``|total_i - fit_i|``
            of a least-squares fit with an intercept, each run left out of
            its own fit, on nothing (``bias``, :meth:`bias_free_mae_n`), on
            the percepts, on finger 0's true share, on both fingers' true
            shares; NaN where the runs are too few for the fit.
        """
        total = self.column("total_n")
        names = [k for k in PERCEPTS
                 if self.percepts and all(math.isfinite(p[k]) for p in self.percepts)]
        percepts = np.array([[p[k] for k in names] for p in self.percepts]).reshape(
            len(self.percepts), len(names))
        shares = self._design(tuple(_SHARES.values()))
        correlation: dict[str, dict[str, float]] = {}
        for name, values in [*zip(names, percepts.T, strict=True), ("total_n", total)]:
            correlation[name] = {
                **{finger: _correlation(values, shares[:, j]) for j, finger in enumerate(_SHARES)},
                "total_n": _correlation(values, total),
            }
        corrected = {
            "bias": self.bias_free_mae_n(),
            "percepts": _loo_mae(percepts, total) if names else float("nan"),
            "finger_0_share": _loo_mae(shares[:, :1], total),
            "both_shares": _loo_mae(shares, total),
        }
        return {"at_s": percept_at_s(self.duration_s), "percepts": names,
                "correlation": correlation, "corrected_mae_n": corrected}

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
            "r2": self.r2(), "observability": self.observability(),
            "runs": [{"seed": s, **b, "twin_scatter": d,
                      **({"percepts": self.percepts[i]} if self.percepts else {})}
                     for i, (s, b, d) in enumerate(zip(self.seeds, self.budgets, self.scatter,
                                                       strict=True))],
        }


def _loo_residuals(x: FloatArray, y: FloatArray) -> FloatArray | None:
    """Each run's residual from the least-squares fit (with an intercept) on the others.

    ``None`` with fewer runs than twice the coefficients and two more: a fit
    with that few runs to spare says little.
    """
    n, k = x.shape
    if n < 2 * (k + 1) + 2:
        return None
    design = np.column_stack([x, np.ones(n)])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    hat = np.einsum("ij,ji->i", design, np.linalg.pinv(design))
    out: FloatArray = (y - design @ coef) / (1.0 - hat)
    return out


def _explained(x: FloatArray, y: FloatArray) -> float:
    """Leave-one-out R² of ``y`` on ``x`` with an intercept (``1 - PRESS / SS``).

    Each run is predicted by the fit on the others, so a draw that explains
    nothing scores about 0 or below, however few the runs.  NaN with fewer
    runs than twice the coefficients and two more, or if ``y`` is constant.
    """
    ss = float(np.sum((y - y.mean()) ** 2))
    loo = _loo_residuals(x, y)
    if loo is None or ss <= 0.0:
        return float("nan")
    return float(1.0 - loo @ loo / ss)


def _loo_mae(x: FloatArray, y: FloatArray) -> float:
    """Mean absolute leave-one-out residual of ``y`` on ``x`` (NaN with too few runs)."""
    loo = _loo_residuals(x, y)
    return float("nan") if loo is None else float(np.mean(np.abs(loo)))


def _correlation(a: FloatArray, b: FloatArray) -> float:
    """Pearson's correlation; NaN under three runs or where either does not vary."""
    if a.size < 3 or np.ptp(a) == 0.0 or np.ptp(b) == 0.0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


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
        No seeds, a negative one or one given twice, or a condition
        :func:`run_hold` refuses; checked before any hold starts.
    """
    if not seeds:
        raise InputError("an error-budget survey needs at least one seed")
    check_seeds(seeds)  # a run twice: its bias "from the others" would be its own
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
                        scatter, holds[0].twin_version, [hold_percepts(h) for h in holds])
