"""The paper's claims about its holding experiment (§V-C), on the twin: seeded, virtual time.

Over six seeds of a 280 s hold at 5 N and 40 °C: ``relax`` (Eq. 10) holds the force with
less than 0.3 times the MAE of a fixed aperture; ``icfn`` over-estimates the true force as
relaxation proceeds (by more than 0.2 N on average over 100-280 s) while its estimate stays
on target; and the observer's calibration against the force reference lowers the MAE on
seeds it was not fitted on.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from relaxgrip.experiments.controlled_hold import map_holds, run_hold
from relaxgrip.learning.store import ModelBundle
from relaxgrip.learning.training import load_default_models

SEEDS = tuple(range(5000, 5006))
pytestmark = pytest.mark.slow


def _mae(args: tuple[str, int, ModelBundle]) -> dict[str, float]:
    estimator, seed, models = args
    hold = run_hold(estimator, 5.0, 280.0, 40.0, seed, models)
    lo, hi = hold.window
    steady = (hold.t_s >= lo) & (hold.t_s <= hi)
    return {**hold.metrics(),
            "estimate_from_target_n": float(np.mean(hold.estimate_n[steady] - 5.0))}


@pytest.fixture(scope="module")
def holds() -> dict[str, list[dict[str, float]]]:
    models = load_default_models()
    uncalibrated = replace(models, calibration=None)
    runs = [(name, seed, models) for name in ("fixed", "icfn", "relax", "observer")
            for seed in SEEDS] + [("observer", seed, uncalibrated) for seed in SEEDS]
    results = map_holds(_mae, runs, n_jobs=2)
    out: dict[str, list[dict[str, float]]] = {}
    for (name, _, bundle), figures in zip(runs, results, strict=True):
        key = name if bundle.calibration is not None or name != "observer" else "uncalibrated"
        out.setdefault(key, []).append(figures)
    return out


def _mean(holds: dict[str, list[dict[str, float]]], name: str, figure: str) -> float:
    return float(np.mean([run[figure] for run in holds[name]]))


def test_relax_holds_with_less_than_a_third_of_the_fixed_apertures_error(holds) -> None:
    assert _mean(holds, "relax", "mae_n") < 0.3 * _mean(holds, "fixed", "mae_n")


def test_icfn_over_estimates_the_relaxed_force_while_its_estimate_stays_on_target(holds) -> None:
    # The estimate minus the true force, over 100-280 s, averaged over the seeds.
    assert _mean(holds, "icfn", "est_error_mean_n") > 0.2
    assert abs(_mean(holds, "icfn", "estimate_from_target_n")) < 0.05


def test_the_calibration_lowers_the_mae_on_seeds_it_was_not_fitted_on(holds) -> None:
    # The shipped calibration was fitted on seeds 1000-1011; these are 5000-5005.
    assert _mean(holds, "observer", "mae_n") < _mean(holds, "uncalibrated", "mae_n")
