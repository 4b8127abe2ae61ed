"""``survey_holds``: each estimator's hold over seeds, its summaries and their intervals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import run_hold
from relaxgrip.experiments.hold_survey import (
    HoldSurvey,
    mean_interval,
    reduction_interval,
    survey_holds,
)
from relaxgrip.experiments.profiles import parse_target_profile


def _survey(runs: dict[str, list[float]]) -> HoldSurvey:
    seeds = list(range(len(next(iter(runs.values())))))
    return HoldSurvey(5.0, 40.0, 280.0, seeds,
                      {name: [{"seed": s, "mae_n": m, "est_error_mean_n": -m}
                              for s, m in zip(seeds, maes, strict=True)]
                       for name, maes in runs.items()}, {}, "test")


def test_the_mean_interval_is_students_t() -> None:
    rng = np.random.default_rng(7)
    few, many = rng.normal(0.06, 0.03, 12), rng.normal(0.06, 0.03, 192)
    lo, hi = mean_interval(few)
    assert (lo + hi) / 2 == pytest.approx(few.mean())
    # 12 seeds: t(0.975, 11) = 2.201 standard errors either side.
    assert hi - lo == pytest.approx(2 * 2.201 * few.std(ddof=1) / math.sqrt(12), rel=1e-3)
    lo_many, hi_many = mean_interval(many)
    assert 0.15 < (hi_many - lo_many) / (hi - lo) < 0.35  # 16 times the seeds: about 1/4
    assert all(math.isnan(v) for v in mean_interval(np.array([0.05])))


def test_the_reduction_interval_resamples_the_seeds_in_pairs() -> None:
    """Each seed's relax MAE follows its baseline's (a hard draw is hard for both): the
    paired interval is narrow, the ratio's spread without the pairing is wide."""
    rng = np.random.default_rng(5)
    base = rng.uniform(0.2, 0.6, 24)
    ours = 0.1 * base * rng.uniform(0.95, 1.05, 24)
    lo, hi = reduction_interval(ours, base)
    assert lo < 1 - ours.mean() / base.mean() < hi
    assert hi - lo < 0.01
    unpaired = [1 - rng.choice(ours, 24).mean() / rng.choice(base, 24).mean()
                for _ in range(2000)]
    assert np.ptp(np.percentile(unpaired, [2.5, 97.5])) > 5 * (hi - lo)
    assert all(math.isnan(v) for v in reduction_interval(ours[:2], base[:2]))
    assert all(math.isnan(v) for v in reduction_interval(ours, base[:20]))


def test_the_summary_and_the_reductions_are_over_the_seeds() -> None:
    survey = _survey({"fixed": [0.4, 0.5, 0.3, 0.4], "icfn": [0.8, 0.8, 0.9, 0.7],
                      "relax": [0.04, 0.06, 0.02, 0.08]})
    s = survey.summary("relax")
    assert s["mae_n"]["mean"] == pytest.approx(0.05)
    assert s["mae_n"]["median"] == pytest.approx(0.05)
    assert s["mae_n"]["sd"] == pytest.approx(np.std([0.04, 0.06, 0.02, 0.08], ddof=1))
    assert (s["mae_n"]["min"], s["mae_n"]["max"]) == (0.02, 0.08)
    assert s["est_error_mean_n"]["mean"] == pytest.approx(-0.05)
    assert "band_coverage" not in s  # no run has a band
    lo, hi = s["mae_n"]["ci95"]
    assert lo < 0.05 < hi
    assert (lo + hi) / 2 == pytest.approx(0.05)
    r = survey.reductions()
    assert r["vs_fixed"]["reduction"] == pytest.approx(1 - 0.05 / 0.4)
    assert r["vs_icfn"]["reduction"] == pytest.approx(1 - 0.05 / 0.8)
    lo, hi = r["vs_fixed"]["ci95"]
    assert lo <= r["vs_fixed"]["reduction"] <= hi
    assert _survey({"observer": [0.1, 0.2]}).reductions() == {}


def test_a_figure_some_runs_lack_is_summarised_over_those_that_have_it() -> None:
    survey = _survey({"observer": [0.04, 0.06, 0.05]})
    survey.runs["observer"][0]["band_coverage"] = 0.9
    survey.runs["observer"][1]["est_error_mean_n"] = math.nan
    s = survey.summary("observer")
    assert s["mae_n"]["n"] == 3
    assert s["band_coverage"]["n"] == 1
    assert s["band_coverage"]["mean"] == 0.9
    assert math.isnan(s["band_coverage"]["sd"])
    assert s["est_error_mean_n"]["n"] == 2
    assert s["est_error_mean_n"]["mean"] == pytest.approx(-0.045)


def test_a_survey_is_each_seeds_own_hold(tmp_path) -> None:
    survey = survey_holds(("relax", "fixed"), [2, 5], duration_s=12.0, n_jobs=2)
    assert survey.seeds == [2, 5]
    assert list(survey.runs) == ["relax", "fixed"]
    hold = run_hold("relax", duration_s=12.0, seed=5)
    assert survey.runs["relax"][1] == {"seed": 5, **hold.metrics()}
    assert survey.column("fixed", "mae_n").shape == (2,)
    d = survey.to_dict()
    assert d["seeds"] == [2, 5]
    assert set(d["summary"]) == {"relax", "fixed"}
    assert set(d["mae_reduction"]) == {"vs_fixed"}
    assert d["twin_version"] == hold.twin_version


def test_a_scenario_is_the_same_for_every_seed() -> None:
    step = parse_target_profile("step:3:8")
    survey = survey_holds(("observer",), [1], duration_s=12.0, target_profile=step,
                          profile_text={"target_profile": "step:3:8"})
    hold = run_hold("observer", duration_s=12.0, seed=1, target_profile=step)
    assert survey.runs["observer"][0] == {"seed": 1, **hold.metrics()}
    assert survey.to_dict()["target_profile"] == "step:3:8"
    assert "band_coverage" in survey.summary("observer")


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"estimators": ()}, "at least one estimator"),
    ({"estimators": ("magic",)}, "unknown estimator"),
    ({"seeds": []}, "at least one seed"),
    ({"seeds": [3, 3]}, "each given once"),
    ({"seeds": [-1]}, "non-negative"),
    ({"backend": "robot"}, "unknown backend"),
])
def test_bad_input_is_refused_before_any_hold(kwargs, message) -> None:
    args = {"estimators": ("relax",), "seeds": [0], **kwargs}
    with pytest.raises(InputError, match=message):
        survey_holds(args.pop("estimators"), args.pop("seeds"), **args)
