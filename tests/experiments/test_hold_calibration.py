"""Calibrating relax's closed-loop error on holds (``relaxgrip calibrate-hold``)."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path
from typing import cast

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments import hold_calibration
from relaxgrip.experiments.controlled_hold import HoldResult, run_hold
from relaxgrip.experiments.hold_calibration import (
    calibrate_hold,
    calibration_from_holds,
    calibration_record,
    drift_line,
    hidden_note,
    hold_drift_windows,
    icfn_drift_n,
    smooth_bias,
    time_bins,
)
from relaxgrip.learning.hold_bias import HoldBias, IcfnDrift
from relaxgrip.learning.store import ModelBundle, load_models
from relaxgrip.learning.training import default_models_dir, load_default_models
from relaxgrip.twin import TWIN_VERSION
from tests.clitools import assert_refused_unchanged, run_main

DURATION_S = 12.0


@pytest.fixture(scope="module")
def uncalibrated() -> ModelBundle:
    return replace(load_default_models(), hold_bias=None)


@pytest.fixture(scope="module")
def plain_hold(uncalibrated: ModelBundle) -> HoldResult:
    return run_hold("relax", 5.0, DURATION_S, 40.0, seed=1000, models=uncalibrated)


def constant(value_n: float) -> HoldBias:
    return HoldBias(np.array([5.0]), np.array([40.0]), np.array([1.0]), np.full((1, 1, 1), value_n))


def test_time_bins_reach_the_hold_and_no_further() -> None:
    assert time_bins(280.0)[-1] == (190.0, 280.0)
    assert time_bins(280.02)[-1] == (190.0, 280.02)  # no sliver of a bin without frames
    assert time_bins(1.01) == [(0.0, 1.01)]
    assert time_bins(12.0) == [(0.0, 1.0), (1.0, 3.0), (3.0, 10.0), (10.0, 12.0)]
    assert time_bins(400.0)[-2:] == [(190.0, 280.0), (280.0, 400.0)]
    assert time_bins(0.5) == [(0.0, 0.5)]


def test_the_estimator_takes_the_calibration_off_and_the_loop_holds_the_difference(
        uncalibrated: ModelBundle, plain_hold: HoldResult) -> None:
    """A calibration of +0.3 N says the estimate reads 0.3 N high: the controller then holds
    the estimate 0.3 N under the target, and the true force rises by about that much."""
    models = replace(uncalibrated, hold_bias=constant(0.3))
    hold = run_hold("relax", 5.0, DURATION_S, 40.0, seed=1000, models=models)
    calibration = hold.series("calibration_n")
    during = hold.t_s > 0.1  # the onset's own frame is the ICFN's
    assert np.all(calibration[during] == pytest.approx(0.3))
    assert np.all(np.isnan(plain_hold.series("calibration_n")))
    before = hold.loop["hold_s"]
    assert np.all(np.isnan(hold.loop["calibration_n"][~np.isfinite(before)]))
    steady = hold.t_s > 6.0
    shift = float(np.mean(hold.truth_n[steady]) - np.mean(plain_hold.truth_n[steady]))
    assert shift == pytest.approx(0.3, abs=0.08)
    budget = run_hold("relax", 5.0, DURATION_S, 40.0, seed=1000, models=models,
                      budget=True).error_budget()
    assert budget["calibration_n"] == pytest.approx(-0.3)
    assert budget["total_n"] == pytest.approx(sum(v for k, v in budget.items() if k != "total_n"))


def test_the_lookup_follows_the_onset_force_and_the_hold_time(uncalibrated: ModelBundle,
                                                               monkeypatch: pytest.MonkeyPatch,
                                                               ) -> None:
    """Every hold frame takes off the grid's value at its F_inst and hold time, also on frames
    whose infrared shows no finger beam (the last temperature read stands)."""
    import relaxgrip.control.estimators as estimators

    real = estimators.finger_temperature_c  # type: ignore[attr-defined]
    calls = {"n": 0}

    def sometimes_blind(thermal: object) -> float:
        calls["n"] += 1
        return float("nan") if calls["n"] % 3 == 0 else real(thermal)  # type: ignore[arg-type]

    monkeypatch.setattr(estimators, "finger_temperature_c", sometimes_blind)
    values = np.array([[[0.05, 0.10, 0.20]], [[0.25, 0.30, 0.40]]])
    bias = HoldBias(np.array([4.0, 6.0]), np.array([40.0]), np.array([1.0, 3.0, 9.0]), values)
    hold = run_hold("relax", 5.0, DURATION_S, 40.0, seed=1000,
                    models=replace(uncalibrated, hold_bias=bias))
    rows = hold.t_s > 0.1
    onset, held = hold.series("f_onset_n")[rows], hold.series("hold_s")[rows]
    expected = np.array([bias.at(f, 40.0, h) for f, h in zip(onset, held, strict=True)])
    np.testing.assert_allclose(hold.series("calibration_n")[rows], expected, rtol=1e-9)
    assert calls["n"] > 3
    assert np.ptp(expected) > 0.1


def test_the_drift_line_is_taken_off_from_the_end_of_its_window(uncalibrated: ModelBundle,
                                                                 plain_hold: HoldResult) -> None:
    """Before the drift is read only the table's value is taken off; from then on the line's
    too, on the drift the calibration would read of the same hold."""
    early, late = hold_drift_windows(DURATION_S)
    assert late[1] == pytest.approx(100.0 * DURATION_S / 280.0)
    line = IcfnDrift(np.array([5.0]), np.array([40.0]), early, late, np.full((1, 1), 0.05),
                     np.full((1, 1), 0.5))
    bias = HoldBias(np.array([5.0]), np.array([40.0]), np.array([1.0]), np.full((1, 1, 1), 0.01),
                    line)
    hold = run_hold("relax", 5.0, DURATION_S, 40.0, seed=1000,
                    models=replace(uncalibrated, hold_bias=bias))
    # Until the drift is read the hold is the uncalibrated one held 0.01 N lower: its
    # ICFN drifts alike.
    windows = hold_drift_windows(DURATION_S)
    drift = icfn_drift_n(hold.t_s, hold.series("icfn_n"), windows)
    assert drift == pytest.approx(icfn_drift_n(plain_hold.t_s, plain_hold.series("icfn_n"),
                                               windows), abs=0.02)
    calibration = hold.series("calibration_n")
    before = (hold.t_s > 0.1) & (hold.t_s < late[1] - 1e-6)
    after = hold.t_s >= late[1]
    assert np.all(calibration[before] == pytest.approx(0.01))
    np.testing.assert_allclose(calibration[after], 0.01 + 0.5 * (drift - 0.05), rtol=1e-9)
    assert abs(drift - 0.05) > 0.01  # the line did take something off


def test_a_drift_line_recovers_its_slope_and_says_what_it_does_not_know() -> None:
    drifts = np.array([0.1, 0.2, 0.3, 0.4])
    exact = drift_line(drifts, 0.02 + 0.5 * (drifts - 0.25))
    assert exact["slope"] == pytest.approx(0.5)
    assert exact["slope_se"] == pytest.approx(0.0, abs=1e-9)
    assert exact["r"] == pytest.approx(1.0)
    assert exact["mean_n"] == pytest.approx(0.25)
    two = drift_line(drifts[:2], np.array([0.0, 0.1]))
    assert two["slope"] == pytest.approx(1.0)
    assert two["slope_se"] == 10.0
    flat = drift_line(np.full(4, 0.3), np.array([0.0, 0.1, 0.0, 0.1]))
    assert flat["slope"] == 0.0
    assert flat["slope_se"] == 10.0
    assert np.isnan(flat["r"])


def test_calibration_fits_the_drift_line_and_leaves_it_out_without_drifts() -> None:
    """Holds whose error follows their drift at 0.5 N/N about a mean drift of 0.06 F: the
    table's line has that slope and mean at the conditions; a hold without a drift (one
    stored before the line) leaves the line out."""
    rng = np.random.default_rng(3)
    holds = {}
    for force in (3.0, 5.0):
        rows = []
        for seed in range(12):
            drift = 0.06 * force + rng.normal(0.0, 0.05)
            error = 0.02 + 0.5 * (drift - 0.06 * force) + rng.normal(0.0, 0.005)
            rows.append({**_row(seed, [error] * 3), "f_inst_n": force, "icfn_drift_n": drift})
        holds[f"{force:g}N 40C"] = rows
    result = calibration_from_holds([3.0, 5.0], [40.0], list(range(12)), 4.0, holds)
    line = result.bias.drift
    assert line is not None
    for i, force in ((0, 3.0), (2, 5.0)):
        assert line.slope[i, 0] == pytest.approx(0.5, abs=0.05)
        assert line.mean_n[i, 0] == pytest.approx(0.06 * force, abs=0.03)
    assert line.late_s == hold_drift_windows(4.0)[1]
    assert "ICFN's drift" in result.record()["method"]
    fit = json.loads(json.dumps(result.record()))["icfn_drift"]
    assert fit["conditions"]["5N 40C"]["holds"] == 12
    assert fit["conditions"]["5N 40C"]["r"] > 0.9
    del holds["3N 40C"][0]["icfn_drift_n"]
    result = calibration_from_holds([3.0, 5.0], [40.0], list(range(12)), 4.0, holds)
    assert result.bias.drift is None
    assert result.record()["icfn_drift"] is None
    assert "drift" not in result.record()["method"]


def test_the_observer_takes_the_calibration_off_and_fits_its_share_without_it(
        uncalibrated: ModelBundle) -> None:
    """The share is fitted to Eq. 10's relaxation: a calibration does not move it (fitted
    against the calibrated estimate, 0.3 N over the hold would have read as relaxation).
    The calibration grows slowly (0 N at 1 s, 0.3 N at 12 s), as the shipped table does:
    one applied at once moves the motor at the onset, which ends the fit there."""
    from relaxgrip.control import GraspController
    from relaxgrip.control.observer import ObserverEstimator

    shares: dict[str, float] = {}

    class ShareTap:
        def __init__(self, key: str) -> None:
            self.key = key

        def start(self, *args: object) -> None:
            pass

        def step(self, obs: object, controller: GraspController, command: object) -> None:
            assert isinstance(controller.estimator, ObserverEstimator)
            shares[self.key] = controller.estimator.share

    growing = HoldBias(np.array([5.0]), np.array([40.0]), np.array([1.0, DURATION_S]),
                       np.array([[[0.0, 0.3]]]))
    plain = run_hold("observer", 5.0, DURATION_S, 40.0, seed=1000, models=uncalibrated,
                     recorder=ShareTap("plain"))
    calibrated = run_hold("observer", 5.0, DURATION_S, 40.0, seed=1000,
                          models=replace(uncalibrated, hold_bias=growing),
                          recorder=ShareTap("calibrated"))
    assert shares["plain"] != 1.0  # the fit ran
    assert shares["calibrated"] == pytest.approx(shares["plain"], abs=0.03)
    assert calibrated.series("calibration_n")[-1] == pytest.approx(0.3, abs=0.01)
    late = calibrated.t_s > DURATION_S - 1.0
    shift = float(np.mean(calibrated.truth_n[late]) - np.mean(plain.truth_n[late]))
    assert shift == pytest.approx(0.3, abs=0.08)


def test_calibration_keeps_each_conditions_mean_error_and_smooths_them(
        uncalibrated: ModelBundle, plain_hold: HoldResult) -> None:
    result = calibrate_hold([5.0, 3.0], [40.0], [1000, 1001], DURATION_S, models=uncalibrated)
    bias = result.bias
    assert result.targets_n == [3.0, 5.0]
    bins = time_bins(DURATION_S)
    assert bias.times_s.size == len(bins)
    assert len(result.kernels) == len(bins)
    first = result.holds["5N 40C"][0]
    assert first["seed"] == 1000
    # The error of the estimate the controller is given, the closed chain's reading in it
    # (with the other finger read in the infrared frame, the whole estimate from 5 s on).
    chain = plain_hold.series("chain_n")
    assert np.isfinite(chain).any()
    err = plain_hold.estimate_n - plain_hold.truth_n
    for k, (lo, hi) in enumerate(bins):
        rows = (plain_hold.t_s >= lo) & (plain_hold.t_s <= hi) & np.isfinite(err)
        assert first["bins_n"][k] == pytest.approx(float(np.mean(err[rows])))
    # The grid: each condition's readings and the midpoint between; F_inst near each
    # target, the fingers near 40 °C.
    assert bias.forces_n.size == 3
    assert bias.forces_n[[0, 2]] == pytest.approx([3.0, 5.0], abs=0.3)
    assert bias.temps_c == pytest.approx([40.0], abs=2.0)
    # Smoothing shrinks a condition's mean towards none, never past it.
    raw = np.array([[np.mean([r["bins_n"][k] for r in result.holds[name]])
                     for k in range(len(bins))] for name in ("3N 40C", "5N 40C")])
    assert np.all(np.abs(bias.values_n[[0, 2], 0]) <= np.abs(raw).max() + 1e-9)
    # Each hold's ICFN drift, as the estimator would read it.
    assert first["icfn_drift_n"] == pytest.approx(
        icfn_drift_n(plain_hold.t_s, plain_hold.series("icfn_n"),
                     hold_drift_windows(DURATION_S)))
    assert bias.drift is not None
    assert set(result.drift_fit["conditions"]) == {"3N 40C", "5N 40C"}
    summary = result.summary()["5N 40C"]
    assert summary["est_error_mean_n"] == pytest.approx(np.mean(
        [r["est_error_mean_n"] for r in result.holds["5N 40C"]]))
    assert summary["se_n"] > 0
    assert json.loads(json.dumps(result.record()))["seeds"] == [1000, 1001]


def test_smoothing_recovers_a_smooth_error_and_fades_where_nothing_was_measured() -> None:
    rng = np.random.default_rng(0)
    forces, temps = np.arange(1.0, 9.0), np.arange(30.0, 56.0, 5.0)
    points = np.array([(f, t) for f in forces for t in temps])
    smooth = 0.02 * (points[:, 0] - 4.5) - 0.004 * (points[:, 1] - 42.0)
    se = np.full(len(points), 0.01)
    at_f, at_t = np.array([2.5, 6.5]), np.array([37.5, 52.5])
    values, kernel = smooth_bias(points, smooth + rng.normal(0, 0.01, len(points)), se,
                                 at_f, at_t)
    truth = np.array([[0.02 * (f - 4.5) - 0.004 * (t - 42.0) for t in at_t] for f in at_f])
    np.testing.assert_allclose(values, truth, atol=0.012)
    assert "RBF" in kernel
    # Scatter no larger than each mean's own uncertainty: hardly any correction.
    noise, _ = smooth_bias(points, rng.normal(0, 0.01, len(points)), se, forces, temps)
    assert np.abs(noise).max() < 0.01
    # One condition measured well: its mean there.
    lone, _ = smooth_bias(np.array([[5.0, 40.0]]), np.array([0.08]), np.array([0.002]),
                          np.array([5.0]), np.array([40.0]))
    assert lone[0, 0] == pytest.approx(0.08, abs=0.01)


def test_calibrating_a_calibrated_bundle_measures_it_without_its_calibration(
        uncalibrated: ModelBundle) -> None:
    once = calibrate_hold([5.0], [40.0], [1000, 1001], 4.0, models=uncalibrated)
    again = calibrate_hold([5.0], [40.0], [1000, 1001], 4.0,
                           models=replace(uncalibrated, hold_bias=constant(0.3)))
    np.testing.assert_array_equal(again.bias.values_n, once.bias.values_n)


def test_a_condition_needs_two_seeds() -> None:
    with pytest.raises(InputError, match="5N 40C needs holds on at least two seeds"):
        calibration_from_holds([5.0], [40.0], [1], 4.0, {"5N 40C": [{"seed": 1}]})


def _row(seed: int, bins: list[float]) -> dict[str, float | int | list[float]]:
    return {"seed": seed, "bins_n": bins, "f_inst_n": 5.0, "temp_c": 40.0, "mae_n": 0.05,
            "est_error_mean_n": bins[-1]}


def test_a_bin_one_seed_missed_is_the_mean_of_the_others() -> None:
    nan = float("nan")
    holds = {"5N 40C": [_row(1, [0.1, 0.2, 0.3]), _row(2, [0.1, nan, 0.1]),
                        _row(3, [0.1, 0.4, 0.2])]}
    result = calibration_from_holds([5.0], [40.0], [1, 2, 3], 4.0, holds)
    assert np.all(np.isfinite(result.bias.values_n))
    assert abs(result.bias.values_n[0, 0, 1]) <= 0.3 + 1e-9  # shrunk from the mean of 0.2, 0.4
    holds["5N 40C"] = holds["5N 40C"][:2]
    with pytest.raises(InputError, match="fewer than two seeds gave an estimate"):
        calibration_from_holds([5.0], [40.0], [1, 2], 4.0, holds)


def _holds(count: int, mean_n: float, sd_n: float, force_n: float = 5.0,
           ) -> list[dict[str, float | int | list[float]]]:
    """``count`` holds whose error is ``mean_n`` on average with sample SD ``sd_n``, every bin."""
    x = np.arange(count, dtype=np.float64)
    errors = mean_n + sd_n * (x - x.mean()) / x.std(ddof=1)
    return [{**_row(seed, [float(e)] * 3), "f_inst_n": force_n}
            for seed, e in enumerate(errors)]


def test_too_few_seeds_keep_too_little_and_the_seeds_said_keep_half() -> None:
    """A lone condition of mean m and SE se keeps 1 - se²/m² of m: two holds at SE 0.045 N
    keep 19 % of 0.05 N, and the note's "about 4 seeds" keep half at the same scatter;
    three still do not."""
    sd = 0.045 * np.sqrt(2.0)
    two = calibration_from_holds([5.0], [40.0], [0, 1], 4.0, {"5N 40C": _holds(2, 0.05, sd)})
    kept = two.kept()
    assert kept["steady_state_s"] == pytest.approx([100 / 280 * 4.0, 4.0])
    condition = kept["conditions"]["5N 40C"]
    assert condition["error_n"] == pytest.approx(0.05)
    assert condition["se_n"] == pytest.approx(0.045)
    assert condition["correction_n"] == pytest.approx(two.bias.values_n.max())
    assert condition["correction_n"] == pytest.approx(0.05 * (1 - 0.9**2), abs=1e-3)
    assert kept["hidden"] == ["5N 40C"]
    assert condition["seeds_to_keep_half"] == 4
    note = hidden_note(kept)
    assert "1 of 1 conditions" in note
    assert "+0.0095 N at 5N 40C" in note
    assert "+0.050 N, hidden by their scatter (SE 0.045 N over 2 seeds)" in note
    assert "about 4 seeds per condition would keep half" in note
    assert "--add" in note
    assert "record more holds" in hidden_note(kept, recorded=True)
    for count, hidden in ((3, True), (4, False)):
        more = calibration_from_holds([5.0], [40.0], list(range(count)), 4.0,
                                      {"5N 40C": _holds(count, 0.05, sd)}).kept()
        assert bool(more["hidden"]) is hidden, count
        assert (more["conditions"]["5N 40C"]["correction_n"] >= 0.025) is not hidden



def test_the_warning_says_which_error_it_gives_beside_the_tables_mean() -> None:
    """The table's mean is each hold's estimate − true force; the correction is for that
    less the closed chain's addition.  The warning gave the latter alone (-0.040 N against
    the table's -0.028 N at 280 s): it names it, and gives the table's beside it."""
    sd = 0.045 * np.sqrt(2.0)
    holds = [{**r, "est_error_mean_n": cast(list[float], r["bins_n"])[-1] + 0.012}
             for r in _holds(2, 0.05, sd)]
    result = calibration_from_holds([5.0], [40.0], [0, 1], 4.0, {"5N 40C": holds})
    kept = result.kept()
    condition = kept["conditions"]["5N 40C"]
    assert condition["error_n"] == pytest.approx(0.05)
    assert condition["est_error_mean_n"] == result.summary()["5N 40C"]["est_error_mean_n"]
    assert condition["est_error_mean_n"] == pytest.approx(0.062)
    note = hidden_note(kept)
    assert ("the holds' error without the closed chain's addition (the part it corrects; "
            "the table's mean, with it: +0.062 N) averaged +0.050 N") in note

def test_a_condition_shrunk_with_the_others_is_told_so() -> None:
    """A mean twice its SE, among conditions measured to have none: the fit takes the size of
    the error from all of them, and keeps nothing of it; its own scatter is not why."""
    forces = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    holds = {f"{f:g}N 40C": _holds(2, 0.05, 0.03 * np.sqrt(2.0), f) if f == 3.0
             else _holds(2, 0.0, 0.005 * np.sqrt(2.0), f) for f in forces}
    kept = calibration_from_holds(forces, [40.0], [0, 1], 4.0, holds).kept()
    assert kept["hidden"] == ["3N 40C"]
    assert kept["conditions"]["3N 40C"]["seeds_to_keep_half"] <= 2
    note = hidden_note(kept)
    assert "1 of 6 conditions" in note
    assert "shrunk with the other conditions" in note
    assert "about" not in note


def test_well_measured_conditions_hide_nothing(uncalibrated: ModelBundle) -> None:
    kept = calibrate_hold([5.0], [40.0], [1000, 1001], DURATION_S, models=uncalibrated).kept()
    condition = kept["conditions"]["5N 40C"]
    assert kept["hidden"] == []
    assert abs(condition["correction_n"]) >= 0.5 * abs(condition["error_n"]) > 0.005


@pytest.mark.parametrize(("args", "match"), [
    (([], [40.0], [0, 1]), "target"),
    (([5.0], [], [0, 1]), "temperature"),
    (([5.0], [40.0], [0]), "two seeds"),
    (([5.0], [40.0], [-1, 0]), ">= 0"),
    # One hold counted twice: an SE of 0, and the correction kept all of its mean.
    (([5.0], [40.0], [1000, 1000]), "seeds repeat"),
    (([12.0], [40.0], [0, 1]), "target"),
    (([5.0], [90.0], [0, 1]), "temperature"),
])
def test_calibration_refuses_what_cannot_run(args: tuple[list[float], list[float], list[int]],
                                             match: str) -> None:
    with pytest.raises(InputError, match=match):
        calibrate_hold(*args, duration_s=4.0)


def test_cli_calibrates_and_hold_uses_the_result(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    args: list[str | Path] = ["calibrate-hold", directory, "--targets", "5", "--temps", "40",
                              "--seeds", "1000,1001", "--duration-s", "6", "--jobs", "1"]
    code, out, _ = run_main([*args, "--dry-run"], monkeypatch, capsys)
    assert code == 0, out
    assert "measured (not written)" in out
    assert "10.00" in out  # the slope's SE, the line in the ICFN's drift: two holds, no slope known
    before = load_models(directory).hold_bias
    code, out, _ = run_main([*args, "--json"], monkeypatch, capsys)
    assert code == 0
    record = json.loads(out)
    assert record["written"] is True
    bias = load_models(directory).hold_bias
    assert bias is not None
    assert bias.to_dict() == record["bias"]
    assert before is None or before.to_dict() != bias.to_dict()
    # Two holds a condition establish no slope: the line takes next to nothing off.
    assert bias.drift is not None
    assert np.abs(bias.drift.slope).max() < 0.01
    code, out, _ = run_main(["hold", "--models", directory, "--duration-s", "6", "--json",
                             "--budget"], monkeypatch, capsys)
    assert code == 0
    held = json.loads(out)
    taken = -held["error_budget"]["calibration_n"]
    assert taken != 0.0
    assert bias.values_n.min() - 1e-9 <= taken <= bias.values_n.max() + 1e-9


def test_cli_says_when_the_holds_scatter_hides_the_error(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Two 6 s holds on seeds 1008 and 1009 keep less than half of their mean: the command
    says so in one line beside the table and "written", and its JSON has the figures."""
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    args: list[str | Path] = ["calibrate-hold", directory, "--targets", "5", "--temps", "40",
                              "--seeds", "1008,1009", "--duration-s", "6", "--jobs", "1"]
    code, out, err = run_main(args, monkeypatch, capsys)
    assert code == 0, err
    assert "written to" in out
    warnings = [line for line in err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1
    assert "keeps less than half of the error at 1 of 1 conditions" in warnings[0]
    assert "hidden by their scatter" in warnings[0]
    assert "seeds per condition" in warnings[0]
    code, out, _ = run_main([*args, "--json", "--dry-run"], monkeypatch, capsys)
    assert code == 0
    record = json.loads(out)
    kept = record["kept"]
    assert kept["hidden"] == ["5N 40C"]
    assert kept["note"] == warnings[0].removeprefix("warning: ")
    condition = kept["conditions"]["5N 40C"]
    # The table's mean is in the warning too, named as such.
    table_mean = record["summary"]["5N 40C"]["est_error_mean_n"]
    assert f"the table's mean, with it: {table_mean:+.3f} N" in warnings[0]
    assert abs(condition["correction_n"]) < 0.5 * abs(condition["error_n"])
    assert condition["seeds_to_keep_half"] > 2


@pytest.mark.parametrize(("args", "expected"), [
    (["calibrate-hold", "{missing}"], "missing"),
    (["calibrate-hold", "{dir}", "--targets", "1,x"], "--targets"),
    (["calibrate-hold", "{dir}", "--targets", "5,5"], "--targets"),
    (["calibrate-hold", "{dir}", "--temps", "nan"], "--temps"),
    (["calibrate-hold", "{dir}", "--targets", "11"], "target"),
    (["calibrate-hold", "{dir}", "--seeds", "5-2"], "5-2"),
    (["calibrate-hold", "{dir}", "--seeds", "3"], "two seeds"),
    (["calibrate-hold", "{dir}", "--jobs", "0"], "--jobs"),
    (["calibrate-hold", "{dir}", "--duration-s", "0"], "--duration-s"),
    (["calibrate-hold", "{dir}", "--duration-s", "4000"], "--duration-s must be at most 3600 s"),
    (["calibrate-hold", "{dir}", "--add", "--duration-s", "6"], "held 280 s"),
    (["calibrate-hold", "{dir}", "--add", "--targets", "5", "--temps", "40", "--seeds", "1003"],
     "already has seed 1003"),
    (["calibrate-hold", "{dir}", "--add", "--targets", "5", "--temps", "41", "--seeds", "7"],
     "lack the condition"),
])
def test_cli_bad_input(args: list[str], expected: str, tmp_path: Path,
                       monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    assert_refused_unchanged(args, expected, default_models_dir(), tmp_path, monkeypatch, capsys)


def test_holds_added_to_a_calibration_are_as_if_run_together(
        uncalibrated: ModelBundle, monkeypatch: pytest.MonkeyPatch) -> None:
    """Seeds added at a condition give the calibration of all of them at once; a condition
    added widens the grid; the earlier holds are kept as they were."""
    first = calibrate_hold([5.0], [40.0], [1000, 1001], 4.0, models=uncalibrated)
    grown = calibrate_hold([5.0], [40.0], [1002], 4.0, models=uncalibrated,
                           add_to=first.record())
    together = calibrate_hold([5.0], [40.0], [1000, 1001, 1002], 4.0, models=uncalibrated)
    assert grown.seeds == [1000, 1001, 1002]
    assert grown.holds == together.holds
    np.testing.assert_allclose(grown.bias.values_n, together.bias.values_n, atol=1e-9)
    assert grown.holds["5N 40C"][:2] == first.holds["5N 40C"]
    wider = calibrate_hold([3.0], [40.0], [1000, 1001], 4.0, models=uncalibrated,
                           add_to=grown.record())
    assert wider.targets_n == [3.0, 5.0]
    assert [len(wider.holds[c]) for c in ("3N 40C", "5N 40C")] == [2, 3]
    # A calibration of an earlier twin whose holds this one runs bit for bit can be added to.
    older = {**first.record(), "twin_version": "relaxgrip-twin-v0"}
    monkeypatch.setattr(hold_calibration, "SAME_RUNS_AS", ("relaxgrip-twin-v0",))
    assert calibrate_hold([5.0], [40.0], [1002], 4.0, models=uncalibrated,
                          add_to=older).holds == grown.holds


def _record(**changes: object) -> dict[str, object]:
    base: dict[str, object] = {"targets_n": [5.0], "temps_c": [40.0], "duration_s": 4.0,
                               "twin_version": TWIN_VERSION,
                               "holds": {"5N 40C": [_row(1000, [0.1]), _row(1001, [0.2])]}}
    return {**base, **changes}


@pytest.mark.parametrize(("grid", "record", "match"), [
    (([5.0], [40.0], [1001]), _record(), "5N 40C already has seed 1001"),
    (([5.0], [40.0], [1002]), _record(duration_s=280.0), "held 280 s, not 4 s"),
    (([5.0], [40.0], [1002]), _record(twin_version="relaxgrip-twin-v1"), "calibrate anew"),
    (([3.0], [45.0], [1002]), _record(), "lack the condition 3N 40C"),
    (([5.0], [40.0], []), _record(), "at least one seed"),
    (([3.0, 5.0], [40.0], [1002]), _record(), "3N 40C would have holds on one seed"),
])
def test_adding_refuses_holds_that_do_not_fit_before_running_any(
        grid: tuple[list[float], list[float], list[int]], record: dict[str, object],
        match: str, monkeypatch: pytest.MonkeyPatch) -> None:
    import relaxgrip.experiments.hold_calibration as module

    def no_holds(*_: object) -> None:
        raise AssertionError("a hold ran")

    monkeypatch.setattr(module, "map_holds", no_holds)
    with pytest.raises(InputError, match=match):
        calibrate_hold(*grid, duration_s=4.0, add_to=record)


def test_the_record_to_add_to_is_the_one_of_these_models(tmp_path: Path) -> None:
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    manifest = load_models(directory).manifest
    record = calibration_record(manifest)
    assert record["holds"]["5N 40C"][0]["seed"] == 1000
    with pytest.raises(InputError, match="no hold calibration to add to"):
        calibration_record({k: v for k, v in manifest.items() if k != "hold_bias"})
    other = json.loads(json.dumps(manifest))
    other["hold_bias"]["record"]["model_sha256"]["icfn"] = "0" * 64
    with pytest.raises(InputError, match="measured on other models"):
        calibration_record(other)
    other = json.loads(json.dumps(manifest))
    del other["hold_bias"]["record"]["holds"]["5N 40C"][0]["bins_n"]
    with pytest.raises(InputError, match="lacks its holds"):
        calibration_record(other)


def test_a_stored_null_is_read_back_as_nan(uncalibrated: ModelBundle) -> None:
    """JSON keeps a nan as null: an earlier hold's null onset force or bin is a missing
    value when holds are added, not a crash."""
    first = calibrate_hold([5.0], [40.0], [1000, 1001, 1002], 4.0, models=uncalibrated)
    record = json.loads(json.dumps(first.record()))
    record["holds"]["5N 40C"][0]["f_inst_n"] = None
    record["holds"]["5N 40C"][1]["bins_n"][0] = None
    grown = calibrate_hold([5.0], [40.0], [1003], 4.0, models=uncalibrated, add_to=record)
    rows = grown.holds["5N 40C"]
    assert np.isnan(rows[0]["f_inst_n"])
    assert np.isnan(rows[1]["bins_n"][0])
    assert np.all(np.isfinite(grown.bias.values_n))


@pytest.mark.parametrize("change", [
    {"targets_n": ["5"]}, {"duration_s": "280"}, {"holds": {"5N 40C": [{"seed": 1}]}},
    {"holds": {"5N 40C": [{**_row(1000, [0.1]), "bins_n": [0.1, 0.2]}]}},
])
def test_a_malformed_record_is_refused(change: dict[str, object]) -> None:
    manifest = json.loads(json.dumps(load_default_models().manifest))
    manifest["hold_bias"]["record"].update(_record(**change))
    with pytest.raises(InputError, match="malformed"):
        calibration_record(manifest)


def test_cli_adds_seeds_and_records_every_command(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """Each --add appends its command; a record from before the list gets its first one
    rebuilt from what it stores, the hold length exact."""
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    grid: list[str | Path] = ["calibrate-hold", directory, "--targets", "5", "--temps", "40",
                              "--duration-s", "4.25", "--jobs", "1"]
    code, _, _ = run_main([*grid, "--seeds", "1000,1001"], monkeypatch, capsys)
    assert code == 0
    code, out, _ = run_main([*grid, "--seeds", "1002", "--add"], monkeypatch, capsys)
    assert code == 0, out
    assert "1 holds added to 2" in out
    record = load_models(directory).manifest["hold_bias"]["record"]
    assert [r["seed"] for r in record["holds"]["5N 40C"]] == [1000, 1001, 1002]
    assert len(record["commands"]) == 2
    assert record["commands"][1].endswith("--seeds 1002 --duration-s 4.25 --add")
    path = directory / "manifest.json"
    manifest = json.loads(path.read_text())
    del manifest["hold_bias"]["record"]["commands"]
    path.write_text(json.dumps(manifest))
    code, out, _ = run_main([*grid, "--seeds", "1003", "--add"], monkeypatch, capsys)
    assert code == 0, out
    commands = load_models(directory).manifest["hold_bias"]["record"]["commands"]
    assert commands[0].endswith(
        "--targets 5 --temps 40 --seeds 1000,1001,1002 --duration-s 4.25")
    assert commands[1].endswith("--seeds 1003 --duration-s 4.25 --add")
