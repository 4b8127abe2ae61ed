"""Fig. "grasp" on the twin: single-finger contacts at three stiffnesses, closed-loop grasps."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from relaxgrip.backend import Command
from relaxgrip.clock import VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.experiments import stiffness_modulation as sm
from relaxgrip.experiments.tasks import run_task
from relaxgrip.learning.training import load_default_models
from relaxgrip.plots.stiffness_modulation import plot_stiffness_modulation
from relaxgrip.twin import GripperTwin, TwinConfig, get_object
from tests.rigs import twin_of


@pytest.fixture(scope="module")
def models():
    return load_default_models()


@pytest.fixture(scope="module")
def wrench_runs(models):
    return sm.run_contacts("wrench", seed=0, models=models)


@pytest.fixture(scope="module")
def balloon_run(models):
    return sm.run_grasp_task(sm.GRASP_TASKS["balloon"], seed=0, models=models, quick=True)


def test_rigid_finger_leaves_the_stroke_to_the_other_finger():
    """The indenter jaw never bends: the soft finger and the object take the whole travel."""
    cfg = TwinConfig(object_name="wrench", rigid_finger=1).without_sensors()
    wrench = get_object("wrench")
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    touch_mm = (cfg.rig.open_aperture_m - wrench.width_m) * 1e3
    twin.act(Command(20.0))
    clock.sleep_until((touch_mm + 2.0) / 20.0)
    twin.act(Command())
    clock.sleep_until(clock.now() + 0.5)
    truth = twin.observe().truth
    assert truth is not None
    assert truth.finger_deflection_m[1] == 0.0
    squeeze_m = wrench.width_m - truth.aperture_m
    x0 = truth.finger_deflection_m[0]
    assert 0.0 < x0 < squeeze_m
    assert x0 + truth.contact_force_n / wrench.stiffness_n_per_m == pytest.approx(squeeze_m,
                                                                                 rel=1e-6)
    assert TwinConfig().rigid_finger is None
    with pytest.raises(InputError):
        TwinConfig(rigid_finger=2)


def test_rate_is_the_slope_of_a_ramp():
    t = np.arange(60) / 30.0
    rate = sm.rate_n_per_s(t, 3.0 * t + 1.0)
    assert np.allclose(rate[np.isfinite(rate)], 3.0)
    assert np.isnan(rate[0])
    assert np.isnan(rate[-1])


def test_stiffer_finger_gives_larger_steeper_wrench_transients(wrench_runs):
    figs = [r.figures() for r in wrench_runs]
    assert [r.mode for r in wrench_runs] == ["stiff", "medium", "compliant"]
    for key in ("peak_true_n", "peak_true_rate_n_per_s", "peak_est_n", "peak_est_rate_n_per_s"):
        values = [f[key] for f in figs]
        assert values[0] > values[1] > values[2], key
    assert figs[0]["peak_true_n"] > 1.4 * figs[2]["peak_true_n"]
    # The states are the paper's: ≈22, 40, 58 °C read by the infrared camera.
    assert [f["temp_c"] for f in figs] == pytest.approx([22.5, 40.0, 58.0], abs=1.5)
    result = sm.contact_task_result("wrench", 0, wrench_runs)
    assert result.success, result.criteria


def test_scoring_fails_when_the_stiffness_effect_is_reversed(wrench_runs):
    """Relabel the compliant run as stiff and vice versa: the contrasts must fail."""
    swapped = (replace(wrench_runs[2], mode="stiff"), wrench_runs[1],
               replace(wrench_runs[0], mode="compliant"))
    result = sm.contact_task_result("wrench", 0, swapped)
    assert not result.success
    assert not result.criteria["stiffer_larger_peak_true_n"]
    assert not result.criteria["stiffer_larger_peak_est_n"]


@pytest.mark.parametrize(("name", "seed", "rig"), [("feather", 1, "ours"), ("brush", 0, "ours"),
                                                 ("feather", 1, "lab")])
def test_weak_contacts_are_detected_and_amplified_when_compliant(name, seed, rig):
    result = run_task(name, seed, twin_of(rig))
    assert result.success, result.criteria
    f = result.figures
    for mode in ("stiff", "medium", "compliant"):
        assert f[f"{mode}_deflection_snr"] >= sm.DETECTION_SNR
    assert f["deflection_gain_compliant_over_stiff"] > 1.5
    assert f["stiff_peak_true_n"] >= f["compliant_peak_true_n"]
    if name == "brush":  # 0.5 N: the estimate itself rises clearly above its floor
        assert min(f[f"{m}_est_snr"] for m in ("stiff", "medium", "compliant")) > 10.0


@pytest.mark.parametrize(("name", "seed"), [("hammer", 1), ("orange", 2), ("balloon", 1)])
def test_grasp_tasks_succeed(name, seed):
    result = run_task(name, seed)
    assert result.success, result.criteria
    task = sm.GRASP_TASKS[name]
    assert abs(result.figures["sustain_mean_true_n"] - task.target_n) <= sm.force_band_n(
        task.target_n)
    assert result.figures["arm_height_mm"] >= 29.5
    assert json.dumps(result.to_dict(), allow_nan=False)


def test_balloon_grasp_is_held_gently(balloon_run):
    c = balloon_run.criteria()
    assert all(c.values()), c
    f = balloon_run.figures()
    assert f["window_max_abs_error_n"] <= 0.1
    assert f["peak_true_n"] < 0.5  # far below its 3 N yield
    assert f["temp_c"] == pytest.approx(58.0, abs=1.5)


def test_grasp_criteria_catch_a_dropped_object(balloon_run):
    lifted = balloon_run.loop.series["truth_lifted"].copy()
    lifted[-1] = 0.0
    series = {**balloon_run.loop.series, "truth_lifted": lifted}
    dropped = replace(balloon_run, loop=replace(balloon_run.loop, series=series),
                      slipping=np.ones_like(balloon_run.slipping))
    c = dropped.criteria()
    assert not c["lifted_and_held"]
    assert not c["no_slip"]


def test_result_to_dict_and_plot(tmp_path, wrench_runs, balloon_run):
    result = sm.StiffnessModulationResult(0, True, wrench_runs, {"balloon": balloon_run})
    d = result.to_dict()
    json.dumps(d, allow_nan=False)
    assert d["tasks"]["wrench"]["success"]
    assert d["tasks"]["balloon"]["success"]
    out = plot_stiffness_modulation(result, tmp_path / "grasp.png")
    assert out.stat().st_size > 10_000
