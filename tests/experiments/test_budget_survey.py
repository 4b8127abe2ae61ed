"""``survey_budget``: relax's error budget over seeds, and what the twin's draw predicts of it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments.budget_survey import (
    BUDGET_PARTS,
    SCATTER_GROUPS,
    BudgetSurvey,
    _explained,
    survey_budget,
)
from relaxgrip.experiments.controlled_hold import run_hold
from relaxgrip.twin import TwinConfig
from relaxgrip.twin.twin import TwinMaterial


@pytest.fixture(scope="module")
def survey() -> BudgetSurvey:
    return survey_budget([1, 4, 6], duration_s=14.0, n_jobs=2)


def test_each_run_is_its_budgeted_hold_with_the_twins_draw(survey) -> None:
    assert survey.seeds == [1, 4, 6]
    hold = run_hold("relax", duration_s=14.0, seed=4, budget=True)
    assert survey.budgets[1] == {**hold.error_budget(), "mae_n": hold.metrics()["mae_n"]}
    draw = TwinMaterial.draw(TwinConfig(), np.random.default_rng(4))
    assert survey.scatter[1] == draw.scatter() == hold.twin_scatter
    assert hold.to_dict()["twin_scatter"] == survey.scatter[1]
    assert survey.scatter[1]["relax_scale_1"] == draw.relax_scale[1]


def test_the_summary_is_over_the_seeds(survey) -> None:
    total = survey.column("total_n")
    parts = survey.parts()
    # The shipped models are calibrated, and relax blends the closed chain's reading in:
    # both are parts before the total.
    assert list(parts) == [*BUDGET_PARTS[:-1], "calibration_n", "chain_n", BUDGET_PARTS[-1]]
    assert survey.part_names == tuple(parts)
    assert parts["total_n"]["mean"] == pytest.approx(total.mean())
    assert parts["total_n"]["sd"] == pytest.approx(total.std())
    assert parts["onset_n"]["min"] <= parts["onset_n"]["mean"] <= parts["onset_n"]["max"]
    # Leave-one-out: each seed against the mean of the other two.
    expected = np.mean([abs(total[0] - (total[1] + total[2]) / 2),
                        abs(total[1] - (total[0] + total[2]) / 2),
                        abs(total[2] - (total[0] + total[1]) / 2)])
    assert survey.bias_free_mae_n() == pytest.approx(expected)
    d = survey.to_dict()
    assert d["mae_n"] == pytest.approx(survey.column("mae_n").mean())
    assert [r["seed"] for r in d["runs"]] == [1, 4, 6]
    # Three seeds are too few to fit any draw.
    assert all(math.isnan(v) for part in d["r2"].values() for v in part.values())


def _synthetic(n: int, total_of) -> BudgetSurvey:
    rng = np.random.default_rng(0)
    scatter, budgets = [], []
    for _ in range(n):
        s = {k: float(np.exp(0.1 * rng.standard_normal()))
             for k in SCATTER_GROUPS["finger_0"] + SCATTER_GROUPS["finger_1"]}
        s["contact_position_m"] = float(0.08 + 0.002 * rng.standard_normal())
        s["ambient_c"] = float(25.0 + 0.5 * rng.standard_normal())
        onset = 0.01 * rng.standard_normal()
        total = total_of(s, rng)
        budgets.append({"onset_n": onset, "relaxation_n": total - onset, "closure_n": 0.0,
                        "total_n": total, "mae_n": abs(total)})
        scatter.append(s)
    return BudgetSurvey(5.0, 40.0, 280.0, list(range(n)), budgets, scatter, "test")


def test_the_draw_that_drives_a_part_is_the_one_that_predicts_it() -> None:
    survey = _synthetic(40, lambda s, rng: 0.4 * math.log(s["relax_scale_1"])
                        + 0.002 * rng.standard_normal())
    r2 = survey.r2()["total_n"]
    assert r2["finger_1"] > 0.95
    assert r2["all"] > 0.9
    assert r2["finger_0"] < 0.2
    assert r2["contact_ambient"] < 0.2
    # A constant part has no spread to explain.
    assert all(math.isnan(v) for v in survey.r2()["closure_n"].values())


def test_leave_one_out_r2_is_the_brute_force_one() -> None:
    rng = np.random.default_rng(3)
    x = rng.standard_normal((15, 2))
    y = x[:, 0] + 0.5 * rng.standard_normal(15)
    design = np.column_stack([x, np.ones(15)])
    pred = []
    for i in range(15):
        keep = np.arange(15) != i
        coef, *_ = np.linalg.lstsq(design[keep], y[keep], rcond=None)
        pred.append(design[i] @ coef)
    press = np.sum((y - np.array(pred)) ** 2)
    assert _explained(x, y) == pytest.approx(1 - press / np.sum((y - y.mean()) ** 2))
    assert math.isnan(_explained(x[:7], y[:7]))  # under 2 (k + 1) + 2 runs


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"seeds": []}, "at least one seed"),
    ({"seeds": [-1]}, ">= 0"),
    ({"seeds": [0], "target_n": 11.0}, "target force"),
    ({"seeds": [0], "temp_c": 90.0}, "safe range"),
    ({"seeds": [0], "duration_s": 0.0}, "duration"),
])
def test_bad_input_is_refused_before_any_hold(kwargs, message) -> None:
    with pytest.raises(InputError, match=message):
        survey_budget(**kwargs)
