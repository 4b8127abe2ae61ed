"""Scenarios beyond Eq. 10: definitions, time scaling, the comparison and its figure."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments.scenarios import (
    SCENARIOS,
    check_scenarios,
    compare_scenarios,
    scenario_hold,
)
from relaxgrip.plots.scenarios import plot_scenarios


def test_profiles_scale_with_the_hold_and_describe_it() -> None:
    ramp = SCENARIOS["ramp"]
    full, half = ramp.profiles(280.0)["temp_profile"], ramp.profiles(140.0)["temp_profile"]
    assert full is not None
    assert half is not None
    assert (full.start_s, full.over_s) == (150.0, 30.0)
    assert (half.start_s, half.over_s, half.after) == (75.0, 15.0, 55.0)
    assert ramp.describe(140.0) == "stiffness switch: 40 → 55 °C over 15 s from 75 s"
    assert SCENARIOS["push"].describe() == "push on the object: 2 N from 200 s"
    assert SCENARIOS["standard"].profiles(280.0) == {
        "temp_profile": None, "target_profile": None, "disturbance": None}
    assert SCENARIOS["step"].describe() == "new target: 5 → 3 N at 150 s"
    assert [SCENARIOS[n].target_n for n in ("standard", "light", "firm")] == [5.0, 1.0, 8.0]
    assert SCENARIOS["light"].describe() == "light hold, 1 N at 40 °C"
    assert SCENARIOS["firm"].to_dict()["target_n"] == 8.0
    assert [SCENARIOS[n].temp_c for n in ("standard", "firm", "hot")] == [40.0, 40.0, 55.0]
    assert SCENARIOS["hot"].to_dict()["temp_c"] == 55.0


def test_a_scenario_holds_its_own_target() -> None:
    hold = scenario_hold("observer", "light", seed=0, duration_s=8.0)
    assert np.all(hold.target_t_n == 1.0)
    assert hold.metrics()["mae_n"] < 0.3  # closed on 1 N, not 5


def test_a_scenario_holds_at_its_own_temperature() -> None:
    hold = scenario_hold("observer", "hot", seed=0, duration_s=8.0)
    assert hold.temp_c == 55.0
    assert hold.to_dict()["temp_c"] == 55.0


@pytest.mark.parametrize("names", [[], ["warp"], ["ramp", "warp"]])
def test_unknown_scenarios_are_refused(names: list[str]) -> None:
    with pytest.raises(InputError, match="unknown scenario"):
        check_scenarios(names)
    with pytest.raises(InputError, match="unknown scenario"):
        compare_scenarios(names, duration_s=5.0)


def test_a_short_comparison_runs_both_estimators_and_draws_them(tmp_path: Path) -> None:
    result = compare_scenarios(("step",), seed=0, duration_s=14.0)
    runs = result.holds["step"]
    assert set(runs) == {"relax", "observer"}
    hold = runs["observer"]
    # The new target acts at 150/280 of the hold: 7.5 s into 14 s.
    assert np.all(hold.target_t_n[hold.t_s < 7.4] == 5.0)
    assert np.all(hold.target_t_n[hold.t_s > 7.6] == 3.0)
    d = result.to_dict()["scenarios"]["step"]
    assert d["target_profile"] == "step:3:150"
    assert math.isfinite(d["relax_over_observer"])
    assert d["relax_over_observer"] > 0
    assert "band_coverage" in d["holds"]["observer"]
    assert "band_coverage" not in d["holds"]["relax"]
    assert result.degradation("step") == pytest.approx(
        result.mae_n("step", "relax") / result.mae_n("step", "observer"))
    png = plot_scenarios(result, tmp_path / "scenarios.png")
    assert png.stat().st_size > 10_000


def test_scenario_hold_is_run_hold_with_the_profiles() -> None:
    from relaxgrip.experiments.controlled_hold import run_hold

    a = scenario_hold("relax", "push", seed=1, duration_s=6.0)
    p = SCENARIOS["push"].profiles(6.0)
    b = run_hold("relax", duration_s=6.0, seed=1, disturbance=p["disturbance"])
    np.testing.assert_array_equal(a.truth_n, b.truth_n)


def test_a_push_on_the_emulator_is_refused_before_it_opens() -> None:
    """The push needs the twin: refused before the emulator starts, nothing left open."""
    import os
    import threading

    from relaxgrip.experiments.controlled_hold import run_hold
    from relaxgrip.experiments.profiles import parse_disturbance

    def open_fds() -> int:
        return len(os.listdir("/proc/self/fd"))

    threads, fds = {t.name for t in threading.enumerate()}, open_fds()
    with pytest.raises(InputError, match=r"a disturbance .* needs the twin backend"):
        run_hold("relax", duration_s=10.0, backend="emulator",
                 disturbance=parse_disturbance("push:1:5"))
    assert {t.name for t in threading.enumerate()} == threads
    assert open_fds() == fds


@pytest.mark.parametrize(("profile", "message"), [
    ({"temp_profile": "ramp:40:55:10:5"}, "--temp-profile starts at 10 s, not before the 10 s"),
    ({"disturbance": "push:1:12"}, "--disturbance starts at 12 s"),
])
def test_a_profile_that_starts_after_the_hold_is_refused(profile: dict[str, str],
                                                         message: str) -> None:
    """A scenario past the hold's end would change nothing: refused before the twin runs."""
    from relaxgrip.experiments.controlled_hold import run_hold
    from relaxgrip.experiments.profiles import parse_disturbance, parse_temp_profile

    parse = {"temp_profile": parse_temp_profile, "disturbance": parse_disturbance}
    given = {name: parse[name](text) for name, text in profile.items()}
    with pytest.raises(InputError, match=message):
        run_hold("relax", duration_s=10.0, temp_profile=given.get("temp_profile"),
                 disturbance=given.get("disturbance"))


def test_a_hold_longer_than_an_hour_is_refused() -> None:
    from relaxgrip.experiments.controlled_hold import run_hold

    with pytest.raises(InputError, match="at most 3600 s"):
        run_hold("relax", duration_s=3600.5)
