"""Fig. "modes" b on the twin: each stiffness mode's trade-off, from the contact physics."""

from __future__ import annotations

import json

import pytest

from relaxgrip.experiments import multimode as mm
from relaxgrip.experiments.tasks import run_task
from relaxgrip.learning.training import load_default_models
from relaxgrip.plots.multimode import plot_multimode
from tests.rigs import twin_of


@pytest.fixture(scope="module")
def result():
    return mm.run_multimode(seed=0, quick=True, models=load_default_models())


def test_stiff_pinch_lifts_1kg_and_compliant_cannot(result):
    stiff, soft = result.pinch["stiff"], result.pinch["compliant"]
    assert all(stiff.criteria().values()), stiff.criteria()
    assert soft.slipping.any()
    assert not soft.criteria()["lifted_and_held"]
    # Both squeezed to the same force target: the difference is the finger, not the force.
    assert stiff.target_n == soft.target_n == mm.PINCH_TARGET_N


def test_same_closure_crushes_the_can_only_when_stiff(result):
    stiff, soft = result.can["stiff"], result.can["compliant"]
    assert stiff.aperture_mm == soft.aperture_mm
    assert stiff.is_crushed
    assert stiff.figures()["plastic_mm"] > 1.0
    assert not soft.is_crushed
    assert soft.held
    # The physics behind it: the stiffer chain takes more force from the same closure.
    assert stiff.figures()["peak_true_n"] > 1.15 * soft.figures()["peak_true_n"]
    assert soft.figures()["peak_true_n"] < soft.figures()["yield_n"]


def test_adhesive_mode_holds_the_flat_box_force_closure_drops_it(result):
    adhesive, closure = result.adhesive["adhesive"], result.adhesive["stiff"]
    assert all(adhesive.criteria().values()), adhesive.criteria()
    assert closure.slipping.any()
    assert not closure.criteria()["lifted_and_held"]


def test_contrasts_fail_when_the_modes_are_swapped(result):
    """Scoring the modes the other way round must not pass: the effect has a direction."""
    assert not mm.pinch_result(0, result.pinch["compliant"], result.pinch["stiff"]).success
    assert not mm.can_result(0, result.can["compliant"], result.can["stiff"]).success
    assert not mm.adhesive_result(0, result.adhesive["stiff"], result.adhesive["adhesive"]).success


def test_to_dict_and_plot(result, tmp_path):
    d = result.to_dict()
    json.dumps(d, allow_nan=False)
    assert all(t["success"] for t in d["tasks"].values())
    out = plot_multimode(result, tmp_path / "modes.png")
    assert out.stat().st_size > 10_000


@pytest.mark.parametrize(("name", "rig"), [("pinch-1kg", "ours"), ("can", "ours"),
                                         ("adhesive", "ours"), ("can", "lab")])
def test_tasks_succeed_on_another_seed(name, rig):
    task = run_task(name, seed=1, config=twin_of(rig))
    assert task.success, task.criteria
    assert len(task.criteria) >= 2  # both outcomes of the contrast are in the criteria
    json.dumps(task.to_dict(), allow_nan=False)


def test_squeeze_rejects_a_bad_aperture():
    from relaxgrip.errors import InputError

    with pytest.raises(InputError):
        mm.run_squeeze("aluminium_can", "stiff", aperture_share=1.2)
