"""``calibrate-hold`` and ``calibrate-band --recordings``: calibrations on recorded holds."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.experiments.band_calibration import calibrate_band
from relaxgrip.experiments.controlled_hold import HoldResult, run_hold
from relaxgrip.experiments.hold_calibration import RECORDINGS_SOURCE, hold_row
from relaxgrip.experiments.recorded_calibration import (
    calibrate_band_on_recordings,
    calibration_from_recordings,
    recorded_hold,
)
from relaxgrip.learning.observer import (
    ObserverModel,
    default_observer_dir,
    load_default_observer,
    load_observer,
)
from relaxgrip.learning.store import MANIFEST_NAME, ModelBundle, load_models
from relaxgrip.learning.training import default_models_dir
from tests.clitools import assert_refused_unchanged, run_main
from tests.recording.conftest import HOLD_S, record_hold


@pytest.fixture(scope="module")
def second_hold(tmp_path_factory: pytest.TempPathFactory,
                models: ModelBundle) -> tuple[Path, HoldResult]:
    """Another seed of the shared relax hold (5 N, 40 °C, JPEG frames): a condition's pair."""
    return record_hold(tmp_path_factory.mktemp("second") / "relax-1.mcap", "relax", 5.0,
                       HOLD_S, 40.0, 1, models)


def test_a_recorded_hold_is_the_loops_hold(png_relax_hold: tuple[Path, HoldResult],
                                          uncalibrated: ModelBundle) -> None:
    """Lossless frames of an uncalibrated hold: the replayed series are the loop's, bit for bit,
    and the hold's row is the one a hold on the twin gives."""
    path, loop = png_relax_hold
    hold = recorded_hold(path, uncalibrated)
    n = loop.t_s.size
    assert (hold.target_n, hold.temp_c, hold.length_s) == (5.0, 40.0, 8.0)
    np.testing.assert_array_equal(hold.t_s[:n], loop.t_s)
    np.testing.assert_array_equal(hold.estimate_n[:n], loop.estimate_n)
    np.testing.assert_array_equal(hold.truth_n[:n], loop.truth_n)
    assert np.count_nonzero(np.isfinite(loop.series("chain_n"))) > 60
    np.testing.assert_array_equal(hold.f_onset_n[:n], loop.series("f_onset_n"))
    np.testing.assert_array_equal(hold.icfn_n[:n], loop.series("icfn_n"))
    assert 39.0 < np.mean(hold.temps_c) < 42.0
    row = hold.row(8.0)
    assert row == {**hold_row(loop.t_s, loop.estimate_n, loop.truth_n,
                              loop.series("f_onset_n"), hold.temps_c, 5.0, 8.0,
                              loop.series("icfn_n")),
                   "recording": path.name}
    assert math.isfinite(row["icfn_drift_n"])
    assert row["mae_n"] == loop.metrics()["mae_n"]
    assert row["est_error_mean_n"] == loop.metrics()["est_error_mean_n"]


def test_recordings_give_a_calibration_of_their_grid(relax_hold: tuple[Path, HoldResult],
                                                     second_hold: tuple[Path, HoldResult],
                                                     models: ModelBundle) -> None:
    result = calibration_from_recordings([relax_hold[0], second_hold[0]], models)
    assert (result.targets_n, result.temps_c, result.seeds) == ([5.0], [40.0], [0, 1])
    assert result.duration_s == HOLD_S
    assert result.twin_version == RECORDINGS_SOURCE
    assert "recorded holds" in result.record()["method"]
    rows = result.holds["5N 40C"]
    assert [r["recording"] for r in rows] == ["relax.mcap", "relax-1.mcap"]
    for row, (_, loop) in zip(rows, (relax_hold, second_hold), strict=True):
        # The force reference and the target are recorded as they were: the MAE is the loop's.
        assert row["mae_n"] == loop.metrics()["mae_n"]
        # The loop took its calibration off; the replay, uncalibrated, does not (JPEG frames
        # move the marker's corners a little).
        calibration = np.nanmean(loop.series("calibration_n")[loop._mask()])
        assert row["est_error_mean_n"] == pytest.approx(
            loop.metrics()["est_error_mean_n"] + calibration, abs=0.03)
    # One condition, its time bins' means as the grid stores them.
    means = np.nanmean([r["bins_n"] for r in rows], axis=0)
    assert np.all(np.abs(result.bias.values_n - means) < 0.03)


def test_cli_writes_the_recorded_calibration(relax_hold: tuple[Path, HoldResult],
                                             second_hold: tuple[Path, HoldResult], tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    before = (directory / MANIFEST_NAME).read_bytes()
    args: list[str | Path] = ["calibrate-hold", directory, "--recordings", relax_hold[0],
                              "--recordings", second_hold[0], "--jobs", "1"]
    code, out, err = run_main([*args, "--dry-run"], monkeypatch, capsys)
    assert code == 0, err
    assert "2 recorded holds of 6 s, measured (not written)" in " ".join(out.split())
    assert (directory / MANIFEST_NAME).read_bytes() == before
    code, out, err = run_main([*args, "--json"], monkeypatch, capsys)
    assert code == 0, err
    record = json.loads(out)
    assert record["written"] is True
    assert record["twin_version"] == RECORDINGS_SOURCE
    assert record["commands"] == [f"relaxgrip calibrate-hold {directory} --recordings "
                                  f"{relax_hold[0]} --recordings {second_hold[0]}"]
    bias = load_models(directory).hold_bias
    assert bias is not None
    assert bias.to_dict() == record["bias"]
    # A calibration on recordings is not grown by holds on the twin.
    code, out, err = run_main(["calibrate-hold", directory, "--add", "--targets", "5", "--temps",
                               "40", "--seeds", "7", "--duration-s", "6"], monkeypatch, capsys)
    assert code == 2
    assert "ran on recordings" in err


@pytest.mark.parametrize(("args", "expected"), [
    (["--recordings", "{relax}", "--recordings", "{second}", "--targets", "5"],
     "--targets sets the twin's holds"),
    (["--recordings", "{relax}", "--recordings", "{second}", "--duration-s", "6"],
     "--duration-s sets the twin's holds"),
    (["--recordings", "{relax}", "--recordings", "{second}", "--add"], "--add grows"),
    (["--recordings", "{relax}"], "hold 5 N at 40 °C 1 time(s)"),
    (["--recordings", "{relax}", "--recordings", "{second}", "--recordings", "{fixed}"],
     "a fixed hold; the calibrations take holds regulated by relax or observer"),
    (["--recordings", "{missing}"], "no such recording"),
])
def test_cli_refuses_what_cannot_calibrate(args: list[str], expected: str,
                                           relax_hold: tuple[Path, HoldResult],
                                           second_hold: tuple[Path, HoldResult],
                                           fixed_holds: list[Path], tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    paths = {"relax": relax_hold[0], "second": second_hold[0], "fixed": fixed_holds[0],
             "missing": tmp_path / "missing.mcap"}
    filled = [a.format(**paths) for a in args]
    assert_refused_unchanged(["calibrate-hold", "{dir}", *filled], expected,
                             default_models_dir(), tmp_path, monkeypatch, capsys)


@pytest.fixture(scope="module")
def png_observer_hold(tmp_path_factory: pytest.TempPathFactory, models: ModelBundle,
                      observer: ObserverModel) -> tuple[Path, HoldResult]:
    """An 8 s observer hold at 5 N, 40 °C (the standard scenario) with lossless frames."""
    return record_hold(tmp_path_factory.mktemp("observer") / "observer.mcap", "observer",
                       5.0, 8.0, 40.0, 3, models, rgb_format="png", observer=observer)


@pytest.fixture(scope="module")
def observer() -> ObserverModel:
    return load_default_observer()


def test_the_band_calibrated_on_a_recording_is_the_twins(
        png_observer_hold: tuple[Path, HoldResult], models: ModelBundle,
        observer: ObserverModel) -> None:
    """The observer replayed on lossless frames: the band's samples, scales and report are
    those of the same hold on the twin."""
    path, _ = png_observer_hold
    recorded = calibrate_band_on_recordings(observer, [path], models)
    twin = calibrate_band(observer, [3], ["standard"], 8.0, models)
    assert recorded.samples == twin.samples > 200
    assert (recorded.band_scale, recorded.drift_scale) == (twin.band_scale, twin.drift_scale)
    assert recorded.band_scale != observer.band_scale
    row = recorded.scenarios["recorded"]["seeds"]["0"]
    assert row == {"recording": path.name, **twin.scenarios["standard"]["seeds"]["3"]}
    assert recorded.scenarios["recorded"]["source"] == RECORDINGS_SOURCE
    assert "recorded holds replayed" in recorded.record()["method"]


def test_cli_calibrates_the_band_on_recordings(png_observer_hold: tuple[Path, HoldResult],
                                               relax_hold: tuple[Path, HoldResult],
                                               tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    directory = tmp_path / "observer"
    shutil.copytree(default_observer_dir(), directory)
    args: list[str | Path] = ["calibrate-band", directory, "--recordings", png_observer_hold[0],
                              "--recordings", relax_hold[0], "--jobs", "1"]
    code, out, err = run_main([*args, "--json"], monkeypatch, capsys)
    assert code == 0, err
    record = json.loads(out)
    assert record["written"] is True
    assert [row["recording"] for row in record["scenarios"]["recorded"]["seeds"].values()] == [
        "observer.mcap", "relax.mcap"]
    assert load_observer(directory).band_scale == record["band_scale"]
    before = (directory / MANIFEST_NAME).read_bytes()
    for extra, expected in ((["--seeds", "3"], "--seeds sets the twin's holds"),
                            (["--scenarios", "ramp"], "--scenarios sets the twin's holds")):
        code, out, err = run_main([*args, *extra], monkeypatch, capsys)
        assert code == 2
        assert expected in err
    assert (directory / MANIFEST_NAME).read_bytes() == before


def test_holds_that_change_target_or_temperature_are_not_calibrated_on(
        tmp_path: Path, models: ModelBundle) -> None:
    """A profiled hold was binned as one at its plan's target and temperature: a ramp to
    55 °C moved the 5 N, 40 °C row's mean error from -0.133 to -0.227 N."""
    from relaxgrip.errors import InputError
    from relaxgrip.experiments.profiles import parse_target_profile
    from relaxgrip.experiments.recorded_calibration import recorded_plan
    from relaxgrip.recording import McapRecorder

    # As `hold --record --target-profile` writes it: the scenario in the session.
    stepped = tmp_path / "stepped.mcap"
    with McapRecorder(stepped, scenario={"target_profile": "step:3:3"}) as rec:
        run_hold("relax", 5.0, HOLD_S, 40.0, 0, models, recorder=rec,
                 target_profile=parse_target_profile("step:3:3"))
    with pytest.raises(InputError, match="a hold with --target-profile step:3:3; the "
                                         "calibrations take holds at their plan's constant"):
        recorded_plan(stepped)
    # Changed by hand (the dashboard): seen in the periods themselves.
    with McapRecorder(tmp_path / "by-hand.mcap") as rec:
        run_hold("relax", 5.0, HOLD_S, 40.0, 0, models, recorder=rec,
                 target_profile=parse_target_profile("step:3:3"))
    with pytest.raises(InputError, match=r"the hold's target went from 5 to 3\.00 N 3\.0 s "
                                         "into it"):
        recorded_hold(tmp_path / "by-hand.mcap", models)
