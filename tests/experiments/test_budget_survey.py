"""``survey_budget``: relax's error budget over seeds, and what the twin's draw predicts of it."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments import budget_survey
from relaxgrip.experiments.budget_survey import (
    BUDGET_PARTS,
    PERCEPTS,
    SCATTER_GROUPS,
    BudgetSurvey,
    _explained,
    _loo_mae,
    hold_percepts,
    survey_budget,
)
from relaxgrip.experiments.controlled_hold import run_hold, steady_window_s
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
    assert parts["total_n"]["sd"] == pytest.approx(total.std(ddof=1))  # as hold --seeds
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


def test_the_percepts_are_what_the_estimator_read_of_its_run(survey) -> None:
    hold = run_hold("relax", duration_s=14.0, seed=4, budget=True)
    seen = hold_percepts(hold)
    assert survey.percepts[1] == seen
    assert set(seen) == set(PERCEPTS)
    assert all(math.isfinite(v) for v in seen.values())
    # Read at the steady state's start, 5 s of a 14 s hold (100 s of 280 s), over the
    # 0.25 s before it, and the drift from 0.05-0.2 s: a 280 s hold's 5 s and 1-4 s, scaled.
    t, motor, icfn = hold.t_s, hold.series("motor_mm"), hold.series("icfn_n")
    late, early = (t >= 4.75 - 1e-9) & (t <= 5.0 + 1e-9), (t >= 0.05 - 1e-9) & (t <= 0.2 + 1e-9)
    assert late.sum() == 8  # 30 Hz
    assert early.sum() == 5
    assert seen["motor_travel_mm"] == pytest.approx(motor[late].mean() - motor[0])
    assert seen["icfn_drift_n"] == pytest.approx(icfn[late].mean() - icfn[early].mean())
    f_onset = hold.series("f_onset_n")
    assert seen["f_onset_n"] == f_onset[np.isfinite(f_onset)][-1]
    assert hold_percepts(hold, at_s=8.0) != seen
    # Only the estimator's own series: without the truth the reads are the same.
    blind = copy.deepcopy(hold)
    for name in [k for k in blind.loop.series if k.startswith("truth_")]:
        blind.loop.series[name][:] = np.nan
    blind.truth_n[:] = np.nan
    assert hold_percepts(blind) == seen
    # Three seeds: correlations, but too few runs for any corrective fit.
    observed = survey.observability()
    assert observed["at_s"] == 5.0
    assert observed["percepts"] == list(PERCEPTS)
    assert set(observed["correlation"]) == {*PERCEPTS, "total_n"}
    assert observed["correlation"]["total_n"]["total_n"] == pytest.approx(1.0)
    corrected = observed["corrected_mae_n"]
    assert corrected["bias"] == survey.bias_free_mae_n()
    assert all(math.isnan(corrected[k]) for k in ("percepts", "finger_0_share", "both_shares"))
    assert survey.to_dict()["runs"][1]["percepts"] == seen


@pytest.mark.parametrize(("duration_s", "at_s"), [(280.0, 100.0), (14.0, 5.0), (20.0, 100 / 14),
                                                  (140.0, 50.0), (3600.0, 9000 / 7)])
def test_the_percepts_are_read_at_the_steady_states_start(duration_s: float, at_s: float) -> None:
    # min(100 s, the hold) read a 20 s hold at its end and a 140 s one at 100 s, not at 50 s.
    assert budget_survey.percept_at_s(duration_s) == pytest.approx(at_s)
    assert budget_survey.percept_at_s(duration_s) == steady_window_s(duration_s)[0]


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


def _with_percepts(survey: BudgetSurvey, drift_of) -> BudgetSurvey:
    """``survey`` with percepts: noise, but the ICFN's drift ``drift_of(scatter, total, rng)``."""
    rng = np.random.default_rng(1)
    percepts = []
    for s, b in zip(survey.scatter, survey.budgets, strict=True):
        p = {k: float(rng.standard_normal()) for k in PERCEPTS}
        p["icfn_drift_n"] = drift_of(s, b["total_n"], rng)
        percepts.append(p)
    return BudgetSurvey(survey.target_n, survey.temp_c, survey.duration_s, survey.seeds,
                        survey.budgets, survey.scatter, survey.twin_version, percepts)


def test_a_correction_reaches_only_what_the_percepts_show_of_the_draw() -> None:
    def total(s, rng):
        return (-0.3 * math.log(s["relax_scale_0"]) - 0.4 * math.log(s["relax_scale_1"])
                + 0.002 * rng.standard_normal())

    def creep(s, total, rng):  # the marker's finger less half the other: not the total's mix
        return (math.log(s["relax_scale_0"]) - 0.5 * math.log(s["relax_scale_1"])
                + 0.01 * rng.standard_normal())

    seen = _with_percepts(_synthetic(48, total), creep).observability()
    r = seen["correlation"]["icfn_drift_n"]
    assert r["finger_0"] > 0.8
    assert r["finger_1"] < -0.3
    mae = seen["corrected_mae_n"]
    assert mae["both_shares"] < 0.1 * mae["bias"]
    assert mae["finger_0_share"] > 0.5 * mae["bias"]
    assert mae["percepts"] > 0.6 * mae["bias"]
    # Percepts that do show the total's mix correct it.
    shown = _with_percepts(_synthetic(48, total),
                           lambda s, t, rng: t + 0.002 * rng.standard_normal())
    assert shown.observability()["corrected_mae_n"]["percepts"] < 0.2 * mae["bias"]
    # A percept some run lacks (no chain blended in) is left out of the fit.
    survey = _with_percepts(_synthetic(48, total), creep)
    survey.percepts[3]["chain_n"] = math.nan
    assert survey.observability()["percepts"] == [k for k in PERCEPTS if k != "chain_n"]
    # A survey without reads (built by hand) fits none.
    bare = _synthetic(48, total).observability()
    assert bare["percepts"] == []
    assert list(bare["correlation"]) == ["total_n"]
    assert math.isnan(bare["corrected_mae_n"]["percepts"])


def test_leave_one_out_mae_is_the_brute_force_one() -> None:
    rng = np.random.default_rng(4)
    x = rng.standard_normal((20, 2))
    y = x[:, 0] - x[:, 1] + 0.3 * rng.standard_normal(20)
    design = np.column_stack([x, np.ones(20)])
    residuals = []
    for i in range(20):
        keep = np.arange(20) != i
        coef, *_ = np.linalg.lstsq(design[keep], y[keep], rcond=None)
        residuals.append(y[i] - design[i] @ coef)
    assert _loo_mae(x, y) == pytest.approx(np.mean(np.abs(residuals)))
    assert math.isnan(_loo_mae(x[:7], y[:7]))


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
    # The same run twice: each one's bias "measured on the other seeds" was its own.
    ({"seeds": [2, 5, 2]}, "seeds repeat in \\[2, 5, 2\\]"),
])
def test_bad_input_is_refused_before_any_hold(kwargs, message) -> None:
    with pytest.raises(InputError, match=message):
        survey_budget(**kwargs)



@pytest.mark.parametrize("duration_s", [1.0, 2.0, 5.0])
def test_a_short_holds_percepts_are_read_over_frames(duration_s: float) -> None:
    """Scaled from 280 s, a 1 s hold's windows were 18 ms and 11 ms, under a frame at 30 Hz:
    every percept but F_inst was NaN.  They span three frames at least.  (The closed chain
    blends nothing in this early: its ``chain_n`` is NaN, as documented.)"""
    hold = run_hold("relax", duration_s=duration_s, seed=0)
    seen = hold_percepts(hold)
    assert all(math.isfinite(v) for k, v in seen.items() if k != "chain_n"), seen
    if duration_s == 1.0:  # read over 0.2571-0.3571 s, the drift from 0.0036-0.1036 s
        t, icfn = hold.t_s, hold.series("icfn_n")
        at = 100 / 280
        late = (t >= at - 0.1 - 1e-9) & (t <= at + 1e-9)
        early = (t >= 1 / 280 - 1e-9) & (t <= 1 / 280 + 0.1 + 1e-9)
        assert late.sum() == early.sum() == 3
        assert seen["icfn_drift_n"] == pytest.approx(icfn[late].mean() - icfn[early].mean())
