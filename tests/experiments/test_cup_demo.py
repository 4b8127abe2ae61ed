"""The integrated cup demonstration: every stage, the task criteria, the figure, the twin hooks."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.backend import Command, Truth
from relaxgrip.clock import VirtualClock
from relaxgrip.control.phases import PHASES, GraspPhase
from relaxgrip.errors import InputError
from relaxgrip.experiments.cup_demo import (
    CupDemoResult,
    CupDemoSettings,
    run_cup_demo,
    score_cup_demo,
)
from relaxgrip.experiments.tasks import run_task
from relaxgrip.twin import GripperTwin, TwinConfig


@pytest.fixture(scope="module")
def hot_left() -> CupDemoResult:
    return run_cup_demo(seed=0, quick=True, hot_side="left")


@pytest.fixture(scope="module")
def hot_right() -> CupDemoResult:
    return run_cup_demo(seed=1, quick=True, hot_side="right")


@pytest.mark.parametrize("name", ["hot_left", "hot_right"])
def test_every_criterion_holds(name: str, request: pytest.FixtureRequest) -> None:
    result: CupDemoResult = request.getfixturevalue(name)
    task = score_cup_demo(result)
    failed = [k for k, ok in task.criteria.items() if not ok]
    assert task.success, f"failed: {failed}; figures {dict(task.figures)}"
    json.dumps(task.to_dict())


def test_the_hot_cup_is_never_chosen(hot_left: CupDemoResult, hot_right: CupDemoResult) -> None:
    assert hot_left.chosen_side == "right"
    assert hot_right.chosen_side == "left"
    for r in (hot_left, hot_right):
        hot, cool = r.ir_cup_temps_c[r.hot_side], r.ir_cup_temps_c[r.chosen_side]
        assert hot > r.ir_background_c + 20.0
        assert abs(cool - r.ir_background_c) < 3.0


def test_paper_cup_not_crushed_and_force_held(hot_left: CupDemoResult) -> None:
    f = hot_left.figures
    assert f["s3_max_force_n"] < f["cup_yield_n"]
    assert f["cup_plastic_mm"] == 0.0
    # Untared, the 29-feature unrelaxed ICFN read the freshly heated fingers 0.25 N high
    # at rest, and the cup was held 0.22 N under 1 N (the tare has taken that off since).
    # The shipped one reads the pose and the warmest beams: within the tare's 0.15 N at
    # rest, and the cup held 0.039 N off 1 N (seed 0).
    assert f["s3_force_mae_n"] < 0.1
    assert f["s5_force_mae_n"] < 0.5
    assert f["mass_poured_kg"] == pytest.approx(
        hot_left.settings.fill_kg - hot_left.settings.empty_kg)


def test_an_arm_stopped_by_the_cup_has_approached_whatever_the_cue_reads() -> None:
    """On seed 3 the cue read 15.9 mm (the stop is at 15) with the cup between the fingers."""
    result = run_cup_demo(seed=3, quick=True)
    assert any(e["event"] == "approached" and e["stage"] == "S2" for e in result.events)
    assert score_cup_demo(result).success


def test_stage_order_and_series(hot_left: CupDemoResult) -> None:
    bounds = hot_left.stages_s
    assert len(bounds) == 5
    assert all(a <= b for a, b in bounds)
    assert all(bounds[k][1] == bounds[k + 1][0] for k in range(4))
    t = hot_left["t_s"]
    assert np.all(np.diff(t) > 0)
    # Compliant in S3 (above Tg), stiff again before the glass: the modulus follows.
    s3 = (t >= bounds[2][0]) & (t < bounds[2][1])
    assert np.nanmin(hot_left["ir_mean_0_c"][s3]) > 48.0
    assert hot_left.figures["modulus_s5_pa"] > 5 * np.nanmin(hot_left["modulus_0_pa"][s3])
    assert hot_left.figures["cooling_s"] > 30.0
    d = hot_left.to_dict(series=True)
    json.dumps(d)
    assert set(d["series"]) == set(hot_left.series)


def test_an_overfilled_cup_slips_and_the_task_says_so() -> None:
    # 200 g of water is more than friction at 1 N can carry: S3 must not pass.
    heavy = replace(CupDemoSettings.for_run(True), fill_kg=0.2, stiff_temp_c=50.0)
    result = run_cup_demo(seed=2, hot_side="left", settings=heavy)
    task = score_cup_demo(result)
    assert not task.success
    assert not (task.criteria["poured"] and task.criteria["no_slip"])
    assert task.criteria["right_cup_identified"]


def test_scoring_catches_a_crushing_force(hot_left: CupDemoResult) -> None:
    series = dict(hot_left.series)
    t = series["t_s"]
    lo, hi = hot_left.stages_s[2]
    force = series["truth_force_n"].copy()
    force[(t >= lo) & (t < hi) & (force > 0.3)] = 4.5
    series["truth_force_n"] = force
    figures = dict(hot_left.figures, s3_max_force_n=4.5)
    crushed = replace(hot_left, series=series, figures=figures)
    task = score_cup_demo(crushed)
    assert not task.criteria["cup_not_crushed"]
    assert not task.criteria["force_within_band_s3"]


def test_s3_band_covers_the_hold_on_the_table(hot_left: CupDemoResult) -> None:
    """The S3 band holds through the hold before the lift, not only once the cup is up."""
    series = dict(hot_left.series)
    t = series["t_s"]
    lo, hi = hot_left.stages_s[2]
    on_table = ((t >= lo) & (t < hi) & (series["phase"] == PHASES.index(GraspPhase.HOLD))
                & (series["arm_mm"] == 0.0))
    assert on_table.sum() > 20
    force = series["truth_force_n"].copy()
    force[on_table] = 2.0  # twice the 1 N target
    series["truth_force_n"] = force
    task = score_cup_demo(replace(hot_left, series=series))
    assert not task.criteria["force_within_band_s3"]
    assert score_cup_demo(hot_left).criteria["force_within_band_s3"]


def test_a_glass_never_let_go_is_not_released(monkeypatch: pytest.MonkeyPatch) -> None:
    """Once the hand has the glass the twin holds no object: the force before that decides."""
    from relaxgrip.control import GraspController

    release = GraspController.release
    calls: list[float] = []

    def release_the_cup_only(self: GraspController, t_s: float) -> None:
        calls.append(t_s)
        if len(calls) == 1:  # S3's cup; S5's glass stays gripped
            release(self, t_s)

    monkeypatch.setattr(GraspController, "release", release_the_cup_only)
    task = score_cup_demo(run_cup_demo(seed=0, quick=True, hot_side="left"))
    assert len(calls) == 2
    assert task.criteria["handover_detected"]
    assert not task.criteria["released"]
    assert task.figures["final_force_n"] > 4.0


def test_plot_writes_a_png(hot_left: CupDemoResult, tmp_path: Path) -> None:
    from relaxgrip.plots.cup_demo import plot_cup_demo

    out = plot_cup_demo(hot_left, tmp_path / "cup.png")
    assert out.stat().st_size > 10_000


def test_task_registry_knows_the_cup() -> None:
    from relaxgrip.experiments.tasks import task_function

    assert task_function("cup").__name__ == "cup_task"
    assert callable(run_task)


def test_bad_arguments() -> None:
    with pytest.raises(InputError, match="seed"):
        run_cup_demo(seed=-1)
    with pytest.raises(InputError, match="hot_side"):
        run_cup_demo(seed=0, hot_side="middle")  # type: ignore[arg-type]


# -- the twin's scenario hooks ------------------------------------------------------------

def _glass_twin() -> tuple[GripperTwin, VirtualClock]:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(object_name="glass").without_sensors(), seed=0, clock=clock)
    twin.act(Command(motor_velocity_mm_s=20.0))
    clock.advance(4.5)
    twin.act(Command())
    clock.advance(0.5)
    return twin, clock


def _truth(twin: GripperTwin) -> Truth:
    truth = twin.observe().truth
    assert truth is not None
    return truth


def test_a_push_moves_load_from_finger_0_to_finger_1() -> None:
    twin, clock = _glass_twin()
    before = _truth(twin)
    assert before.contact_force_n > 1.0
    twin.set_external_force(1.0)
    clock.advance(0.1)
    after = _truth(twin)
    assert after.contact_force_n < before.contact_force_n - 0.3
    assert after.finger_deflection_m[0] < before.finger_deflection_m[0]
    assert after.finger_deflection_m[1] > before.finger_deflection_m[1]
    twin.set_external_force(0.0)
    clock.advance(0.1)
    assert _truth(twin).contact_force_n == pytest.approx(before.contact_force_n, rel=0.05)


def test_object_ahead_mass_and_scene_hooks() -> None:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(object_name=None).without_sensors(), seed=0, clock=clock)
    twin.set_object("paper_cup", ahead_m=0.05)
    assert twin.object_ahead_m == pytest.approx(0.05)
    assert not math.isnan(twin.truth().object_ahead_m)
    twin.set_object_mass(0.05)
    with pytest.raises(InputError):
        twin.set_object_mass(-1.0)
    with pytest.raises(InputError):
        twin.set_object("glass", ahead_m=-0.1)
    twin.set_object(None)
    with pytest.raises(InputError):
        twin.set_object_mass(0.1)
