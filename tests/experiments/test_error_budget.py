"""``run_hold(budget=True)``: relax's estimate error split against the twin held at the onset."""

from __future__ import annotations

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import run_hold


@pytest.fixture(scope="module")
def budgeted():
    return run_hold("relax", duration_s=20.0, seed=2, budget=True)


def test_the_copy_starts_at_the_onset_and_relaxes_while_the_loop_closes(budgeted) -> None:
    fixed, truth = budgeted.fixed_aperture_n, budgeted.truth_n
    assert fixed is not None
    assert fixed.shape == truth.shape
    assert fixed[0] == truth[0]
    # The aperture held: the force relaxes.  It rises only where the copy's fingers cool a
    # step (a cooler finger is stiffer: 1e-4 N a step on this seed).  The loop closes to make
    # up for it.
    rises = np.diff(fixed) > 1e-9
    cooled = np.diff(budgeted.series("truth_temp_0_c") + budgeted.series("truth_temp_1_c")) < 0
    assert np.all(cooled[rises])
    assert np.all(np.diff(fixed)[rises] < 1e-3)
    assert fixed[-1] < fixed[0] - 0.05
    motor = budgeted.series("motor_mm")
    assert motor[-1] > motor[0] + 0.05
    assert truth[-1] > fixed[-1] + 0.05


def test_the_parts_add_up_to_the_mean_estimate_error(budgeted) -> None:
    parts = budgeted.error_budget()
    # The shipped models are calibrated: the calibration taken off is a part of its own,
    # and so is what the closed chain's reading added (from 5 s of the hold on).
    assert parts["calibration_n"] != 0.0
    assert parts["chain_n"] != 0.0
    assert list(parts) == ["onset_n", "relaxation_n", "closure_n", "calibration_n", "chain_n",
                           "total_n"]
    total = (parts["onset_n"] + parts["relaxation_n"] + parts["closure_n"]
             + parts["calibration_n"] + parts["chain_n"])
    assert parts["total_n"] == pytest.approx(total, abs=1e-12)
    assert total == pytest.approx(budgeted.metrics()["est_error_mean_n"], abs=1e-9)
    f_inst = budgeted.series("f_onset_n")[-1]
    assert parts["onset_n"] == pytest.approx(f_inst - budgeted.truth_n[0], abs=1e-12)
    assert budgeted.to_dict()["error_budget"] == parts


def test_the_copy_leaves_the_run_as_it_was(budgeted) -> None:
    plain = run_hold("relax", duration_s=20.0, seed=2)
    np.testing.assert_array_equal(plain.truth_n, budgeted.truth_n)
    np.testing.assert_array_equal(plain.estimate_n, budgeted.estimate_n)
    assert "error_budget" not in plain.to_dict()
    with pytest.raises(InputError, match="budget=True"):
        plain.error_budget()


@pytest.mark.parametrize(("estimator", "backend"), [("icfn", "twin"), ("relax", "emulator")])
def test_a_budget_is_relax_on_the_twin(estimator: str, backend: str) -> None:
    with pytest.raises(InputError, match="budget"):
        run_hold(estimator, duration_s=5.0, backend=backend, budget=True)


def test_the_onset_error_is_where_the_closing_stopped(budgeted) -> None:
    assert budgeted.metrics()["onset_error_n"] == budgeted.truth_n[0] - 5.0
    # A fixed aperture keeps what the onset left, less the finger's relaxation.
    fixed = run_hold("fixed", target_n=3.0, duration_s=20.0, seed=2).metrics()
    assert fixed["onset_error_n"] > fixed["mean_signed_error_n"] + 0.02


def test_a_push_on_the_object_pushes_the_copy_too() -> None:
    """The copy held at the onset's aperture feels the loop's push: what the loop's
    closure adds stays the closure (the push had counted as 0.44 N of it)."""
    from relaxgrip.experiments.profiles import parse_disturbance

    pushed = run_hold("relax", duration_s=20.0, seed=2, budget=True,
                      disturbance=parse_disturbance("push:2:10"))
    fixed = pushed.fixed_aperture_n
    assert fixed is not None
    before, after = np.searchsorted(pushed.t_s, [9.9, 11.0])
    assert fixed[after] < fixed[before] - 0.2  # the push unloads finger 0 in the copy
    assert abs(pushed.error_budget()["closure_n"]) < 0.05
