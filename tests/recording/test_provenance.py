"""A recording names the models it ran with; replay and the calibrations use them.

Before, a recording did not name its models: ``replay`` and ``calibrate-band
--recordings`` without ``--models`` fell back to the shipped ones, and a lab's
band calibrated on its own recordings with the shipped models came out at a
third of its scale, written without a word.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.learning.observer import ObserverModel, default_observer_dir, load_observer
from relaxgrip.learning.rcfn import RCFN
from relaxgrip.learning.store import ModelBundle, load_models, save_models
from relaxgrip.learning.training import default_models_dir
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
from relaxgrip.recording import read_session
from relaxgrip.recording.provenance import model_differences, recorded_models
from relaxgrip.twin import TWIN_VERSION
from tests.clitools import assert_one_error_line, run_main
from tests.recording.conftest import damage_first_chunk, record_hold

HOLD_S = 3.0


def _lab_models(directory: Path, models: ModelBundle) -> ModelBundle:
    """A model directory of its own: the shipped ICFN, an RCFN a little off, no calibration."""
    arrays = models.rcfn.to_arrays()
    name = next(k for k, v in arrays.items() if np.asarray(v).dtype.kind == "f")
    arrays[name] = np.asarray(arrays[name]) * 1.01
    rcfn = RCFN.from_arrays(arrays, models.rcfn.get_params())
    save_models(directory, models.icfn, rcfn, icfn_feature_schema=ICFN_SCHEMA,
                rcfn_feature_schema=RCFN_SCHEMA, twin_version=TWIN_VERSION,
                training={"test": "lab models"}, unrelaxed=models.unrelaxed)
    return load_models(directory, icfn_feature_schema=ICFN_SCHEMA,
                       rcfn_feature_schema=RCFN_SCHEMA)


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory, models: ModelBundle
        ) -> tuple[ModelBundle, ObserverModel, Path]:
    """A lab's models and observer in directories of their own, and an observer hold
    recorded with them."""
    root = tmp_path_factory.mktemp("lab")
    bundle = _lab_models(root / "models", models)
    shutil.copytree(default_observer_dir(), root / "observer")
    observer = load_observer(root / "observer")
    path, _ = record_hold(root / "observer.mcap", "observer", 5.0, HOLD_S, 40.0, 1, bundle,
                          observer=observer)
    return bundle, observer, path


def test_a_recording_names_its_models_and_observer(
        lab: tuple[ModelBundle, ObserverModel, Path]) -> None:
    bundle, observer, path = lab
    named = read_session(path)["models"]
    assert named["directory"] == str(bundle.directory)
    assert named["sha256"] == bundle.provenance()["sha256"]
    assert named["hold_bias_sha256"] is None  # the lab's models are not calibrated
    assert named["observer"]["directory"] == str(observer.source[0] if observer.source else "")
    assert model_differences(named, {**bundle.provenance(),
                                     "observer": observer.provenance()}) == []


def test_replay_runs_the_recorded_models_without_being_told(
        lab: tuple[ModelBundle, ObserverModel, Path], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    _, _, path = lab
    code, out, err = run_main(["replay", path, "--json"], monkeypatch, capsys)
    assert code == 0, err
    own = json.loads(out)
    assert own["models_differ"] == []
    code, out, err = run_main(["replay", path, "--json", "--models", default_models_dir(),
                               "--observer", default_observer_dir()], monkeypatch, capsys)
    assert code == 0, err
    shipped = json.loads(out)
    assert shipped["models_differ"] == ["rcfn", "calibration"]
    # The shipped models take their calibration off the estimate; the lab's, as recorded, none.
    assert own["calibration_valid_agreement"] == 1.0
    assert shipped["calibration_valid_agreement"] < 1.0
    code, out, err = run_main(["replay", path, "--models", default_models_dir()],
                              monkeypatch, capsys)
    assert code == 0, err
    assert "replayed with other models than the recording ran with (rcfn differ)" in out


def test_replay_refuses_models_that_are_gone(
        tmp_path: Path, lab: tuple[ModelBundle, ObserverModel, Path], models: ModelBundle,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    moved = tmp_path / "models"
    _lab_models(moved, models)
    path, _ = record_hold(tmp_path / "relax.mcap", "relax", 5.0, HOLD_S, 40.0, 2,
                          load_models(moved, icfn_feature_schema=ICFN_SCHEMA,
                                      rcfn_feature_schema=RCFN_SCHEMA))
    shutil.rmtree(moved)
    code, out, err = run_main(["replay", path], monkeypatch, capsys)
    assert_one_error_line(code, out, err, f"it ran with the models in {moved}")
    assert "give a copy of them with --models" in err
    # A copy elsewhere, given, replays.
    code, out, err = run_main(["replay", path, "--json", "--models", lab[0].directory or ""],
                              monkeypatch, capsys)
    assert code == 0, err
    assert json.loads(out)["models_differ"] == []


def test_recordings_of_different_models_need_models_given(
        tmp_path: Path, lab: tuple[ModelBundle, ObserverModel, Path],
        relax_hold: tuple[Path, object]) -> None:
    with pytest.raises(Exception, match="the recordings ran with different models: give "
                                        "the ones to use with --models"):
        recorded_models([lab[2], relax_hold[0]])
    # The shipped models are found from any install: by their checksums.
    assert recorded_models([relax_hold[0]]) is not None


def test_band_calibration_on_recordings_takes_their_models(
        lab: tuple[ModelBundle, ObserverModel, Path], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    _, _, path = lab
    observer = tmp_path / "observer"
    shutil.copytree(default_observer_dir(), observer)
    args: list[str | Path] = ["calibrate-band", observer, "--recordings", path, "--dry-run",
                              "--jobs", "1", "--json"]
    code, out, err = run_main(args, monkeypatch, capsys)
    assert code == 0, err
    own = json.loads(out)
    assert own["models_note"] is None
    code, out, err = run_main([*args[:-1], "--models", default_models_dir()], monkeypatch,
                              capsys)
    assert code == 0, err
    assert f"note: {path} ran with other models than these (rcfn differ)" in err


def test_differences_name_the_calibration_and_the_band() -> None:
    recorded = {"sha256": {"icfn": "a", "rcfn": "b"}, "hold_bias_sha256": "c",
                "observer": {"sha256": "d", "band_scale": 0.25, "drift_scale": 1.0}}
    same = json.loads(json.dumps(recorded))
    assert model_differences(recorded, same) == []
    same["observer"]["band_floor_n"] = 0.0  # recorded before the band had a floor: none
    assert model_differences(recorded, same) == []
    same["observer"]["band_floor_n"] = 0.02
    assert model_differences(recorded, same) == ["observer band"]
    same["observer"]["band_floor_n"] = 0.0
    # Recorded before the band had temperature factors: none.
    same["observer"].update(band_temps_c=[], band_temp_factors=[])
    assert model_differences(recorded, same) == []
    same["observer"].update(band_temps_c=[40.0, 55.0], band_temp_factors=[1.0, 1.5])
    assert model_differences(recorded, same) == ["observer band"]
    same["observer"].update(band_temps_c=[], band_temp_factors=[])
    same["hold_bias_sha256"] = None
    same["observer"]["band_scale"] = 0.3
    assert model_differences(recorded, same) == ["calibration", "observer band"]
    same["observer"]["sha256"] = "e"
    same["sha256"]["icfn"] = "f"
    assert model_differences(recorded, same) == ["icfn", "calibration", "observer"]
    assert model_differences(None, same) == []  # recorded before sessions named models


def test_hold_calibration_on_recordings_says_when_they_ran_other_models(
        lab: tuple[ModelBundle, ObserverModel, Path], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    bundle = lab[0]
    for seed in (3, 4):
        record_hold(tmp_path / f"relax-{seed}.mcap", "relax", 5.0, HOLD_S, 40.0, seed, bundle)
    shipped = tmp_path / "shipped"
    shutil.copytree(default_models_dir(), shipped)
    for directory, note in ((bundle.directory, None), (shipped, "(rcfn differ)")):
        code, out, err = run_main(["calibrate-hold", directory or "", "--recordings", tmp_path,
                                   "--dry-run", "--jobs", "1", "--json"], monkeypatch, capsys)
        assert code == 0, err
        said = json.loads(out)["models_note"]
        assert said is None if note is None else note in said


def test_replay_says_what_became_of_the_recorded_models(
        tmp_path: Path, models: ModelBundle, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Their directory there but a file of it damaged in a copy, or trained anew, replay said
    the models were "not there now" (of a directory the user sees there); and a recording it
    cannot replay (recovered without its start) it sent for models first, to refuse after."""
    from relaxgrip.recording import recover

    directory = tmp_path / "models"
    path, _ = record_hold(tmp_path / "relax.mcap", "relax", 5.0, HOLD_S, 40.0, 2,
                          _lab_models(directory, models))
    npz = directory / "rcfn.npz"
    intact = npz.read_bytes()
    npz.write_bytes(intact[:-10] + bytes([intact[-10] ^ 1]) + intact[-9:])
    code, out, err = run_main(["replay", path], monkeypatch, capsys)
    assert_one_error_line(code, out, err, f"which are not there now ({npz}: truncated or "
                                          "modified (sha256 differs from the manifest)): give "
                                          "a copy of them with --models")
    save_models(directory, models.icfn, models.rcfn, icfn_feature_schema=ICFN_SCHEMA,
                rcfn_feature_schema=RCFN_SCHEMA, twin_version=TWIN_VERSION,
                training={"test": "trained anew"})
    code, out, err = run_main(["replay", path], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "which are not there now (it holds others now)")

    damaged = tmp_path / "damaged.mcap"
    damage_first_chunk(path, damaged)
    recovered = tmp_path / "recovered.mcap"
    assert recover(damaged, recovered).lost_start_s is not None
    code, out, err = run_main(["replay", recovered], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "recovered without its start")
