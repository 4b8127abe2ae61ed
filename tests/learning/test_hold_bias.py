"""The calibrated closed-loop error: its grid, its lookup, and its place in a model directory."""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.learning.hold_bias import HoldBias, IcfnDrift, drift_windows
from relaxgrip.learning.store import ModelFileError, load_models, save_models, set_hold_bias
from relaxgrip.learning.training import default_models_dir
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA


def grid() -> HoldBias:
    """Values that are a known function of the knots: 0.1 F - 0.01 T + 0.001 i_t."""
    forces, temps, times = np.array([1.0, 5.0]), np.array([30.0, 40.0, 50.0]), np.array([1.0, 9.0])
    values = (0.1 * forces[:, None, None] - 0.01 * temps[None, :, None]
              + 0.001 * np.arange(2)[None, None, :])
    return HoldBias(forces, temps, times, values)


def test_lookup_is_exact_at_the_knots_linear_between_and_fades_outside() -> None:
    bias = grid()
    assert bias.at(5.0, 40.0, 1.0) == pytest.approx(0.5 - 0.4)
    assert bias.at(5.0, 40.0, 9.0) == pytest.approx(0.5 - 0.4 + 0.001)
    assert bias.at(3.0, 35.0, 1.0) == pytest.approx(0.3 - 0.35)  # linear in force and temperature
    # Time is linear on log(1 + t): halfway between log 2 and log 10 is t = sqrt(20) - 1.
    assert bias.at(1.0, 30.0, math.sqrt(20.0) - 1.0) == pytest.approx(0.1 - 0.3 + 0.0005)
    # Time is held before the first knot and after the last.
    assert bias.at(1.0, 30.0, 0.0) == pytest.approx(bias.at(1.0, 30.0, 1.0))
    assert bias.at(5.0, 50.0, 500.0) == pytest.approx(bias.at(5.0, 50.0, 9.0))
    # Force and temperature fade to none over one end spacing (4 N, 10 K) beyond the grid.
    assert bias.at(7.0, 50.0, 9.0) == pytest.approx(0.5 * bias.at(5.0, 50.0, 9.0))
    assert bias.at(5.0, 25.0, 1.0) == pytest.approx(0.5 * bias.at(5.0, 30.0, 1.0))
    assert bias.at(0.0, 30.0, 1.0) == pytest.approx(0.75 * bias.at(1.0, 30.0, 1.0))
    assert bias.at(9.0, 50.0, 9.0) == 0.0
    assert bias.at(5.0, 61.0, 9.0) == 0.0
    for bad in ((math.nan, 40.0, 1.0), (5.0, math.nan, 1.0), (5.0, 40.0, math.inf)):
        assert bias.at(*bad) == 0.0


def test_a_single_knot_is_a_constant() -> None:
    bias = HoldBias(np.array([5.0]), np.array([40.0]), np.array([100.0]), np.full((1, 1, 1), 0.05))
    assert bias.at(1.0, 30.0, 0.0) == pytest.approx(0.05)
    assert bias.at(8.0, 55.0, 280.0) == pytest.approx(0.05)


@pytest.mark.parametrize(("change", "match"), [
    ({"forces_n": [5.0, 1.0]}, "strictly increasing"),
    ({"temps_c": []}, "non-empty"),
    ({"times_s": [-1.0, 9.0]}, ">= 0 s"),
    ({"values_n": np.zeros((2, 3, 3)).tolist()}, "shape"),
    ({"values_n": np.full((2, 3, 2), np.nan).tolist()}, "not finite"),
    ({"forces_n": ["a", "b"]}, "numbers"),
    ({"forces_n": None}, "non-empty"),
    ({"values_n": np.full((2, 3, 2), 1e6).tolist()}, "1e.06 N, more than any force of the grid"),
])
def test_a_grid_that_is_not_one_is_refused(change: dict[str, object], match: str) -> None:
    entry = {**grid().to_dict(), **change}
    with pytest.raises(InputError, match=match):
        HoldBias.from_dict(entry)


def test_the_dict_form_round_trips_and_names_what_is_missing() -> None:
    bias = grid()
    again = HoldBias.from_dict(json.loads(json.dumps(bias.to_dict())))
    assert again.at(3.3, 44.0, 5.0) == bias.at(3.3, 44.0, 5.0)
    with pytest.raises(InputError, match="missing times_s"):
        HoldBias.from_dict({k: v for k, v in bias.to_dict().items() if k != "times_s"})


def drift() -> IcfnDrift:
    """A line whose slope is 0.5 at 5 N and 0.1 at 1 N, about a mean drift of 0.1 F N."""
    forces, temps = np.array([1.0, 5.0]), np.array([30.0, 50.0])
    return IcfnDrift(forces, temps, (1.0, 4.0), (95.0, 100.0),
                     np.repeat(0.1 * forces[:, None], 2, axis=1),
                     np.repeat(0.1 * forces[:, None], 2, axis=1))


def test_the_drift_line_reads_a_run_against_the_calibration_mean() -> None:
    line = drift()
    assert line.at(5.0, 40.0, 0.5) == 0.0  # the calibration holds' mean drift
    assert line.at(5.0, 40.0, 0.7) == pytest.approx(0.5 * 0.2)
    assert line.at(3.0, 30.0, 0.1) == pytest.approx(0.3 * (0.1 - 0.3))  # linear between knots
    # Beyond the grid the slope fades (4 N, 20 K end spacings); the mean is held.
    assert line.at(7.0, 40.0, 0.7) == pytest.approx(0.5 * 0.5 * 0.2)
    assert line.at(5.0, 60.0, 0.7) == pytest.approx(0.5 * 0.5 * 0.2)
    assert line.at(9.0, 40.0, 0.7) == 0.0
    for bad in ((math.nan, 40.0, 0.5), (5.0, math.nan, 0.5), (5.0, 40.0, math.nan)):
        assert line.at(*bad) == 0.0


def test_the_drift_windows_scale_with_a_short_hold() -> None:
    assert drift_windows(100.0) == ((1.0, 4.0), (95.0, 100.0))
    early, late = drift_windows(5.0, 0.05)
    assert early == pytest.approx((0.05, 0.2))
    assert late == pytest.approx((4.75, 5.0))
    early, late = drift_windows(0.3571, 1.0 / 280.0)  # three frames at least
    assert early[1] - early[0] == pytest.approx(0.1)
    assert late[1] - late[0] == pytest.approx(0.1)


def test_a_bias_with_its_drift_round_trips_and_one_without_it_still_loads() -> None:
    plain = grid()
    bias = HoldBias(plain.forces_n, plain.temps_c, plain.times_s, plain.values_n, drift())
    again = HoldBias.from_dict(json.loads(json.dumps(bias.to_dict())))
    assert again.drift is not None
    assert again.drift.at(3.3, 44.0, 0.9) == bias.drift.at(3.3, 44.0, 0.9)  # type: ignore[union-attr]
    assert again.drift.late_s == (95.0, 100.0)
    assert HoldBias.from_dict(grid().to_dict()).drift is None


@pytest.mark.parametrize(("change", "match"), [
    ({"slope": [[0.1]]}, "slope must have shape"),
    ({"mean_n": [[0.1, math.nan], [0.5, 0.5]]}, "mean_n has a value that is not finite"),
    ({"slope": [[0.1, 0.1], [0.5, 3.0]]}, "beyond ±2 N per N"),
    ({"early_s": [4.0, 1.0]}, "early_s must be a window"),
    ({"late_s": [2.0, 100.0]}, "starts before its early one"),
    ({"late_s": [95.0]}, "late_s must be two numbers"),
    ({"early_s": ["a", "b"]}, "numbers"),
])
def test_a_drift_line_that_is_not_one_is_refused(change: dict[str, object], match: str) -> None:
    entry = {**grid().to_dict(), "icfn_drift": {**drift().to_dict(), **change}}
    with pytest.raises(InputError, match=match):
        HoldBias.from_dict(entry)
    with pytest.raises(InputError, match="icfn_drift lacks slope"):
        HoldBias.from_dict({**grid().to_dict(), "icfn_drift": {
            k: v for k, v in drift().to_dict().items() if k != "slope"}})


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_set_hold_bias_rewrites_only_the_manifest(tmp_path: Path) -> None:
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    files = {p.name: sha(p) for p in directory.glob("*.npz")}
    training = json.loads((directory / "manifest.json").read_text())["training"]
    set_hold_bias(directory, grid(), {"seeds": [7]})
    bundle = load_models(directory, icfn_feature_schema=ICFN_SCHEMA,
                         rcfn_feature_schema=RCFN_SCHEMA)
    assert bundle.hold_bias is not None
    assert bundle.hold_bias.at(3.0, 35.0, 1.0) == pytest.approx(grid().at(3.0, 35.0, 1.0))
    assert {p.name: sha(p) for p in directory.glob("*.npz")} == files
    manifest = json.loads((directory / "manifest.json").read_text())
    assert manifest["training"] == training
    assert manifest["hold_bias"]["record"]["seeds"] == [7]
    # New models trained into the directory carry no calibration of the old ones.
    save_models(directory, bundle.icfn, bundle.rcfn, icfn_feature_schema=ICFN_SCHEMA,
                rcfn_feature_schema=RCFN_SCHEMA, twin_version="test", training={},
                unrelaxed=bundle.unrelaxed)
    assert load_models(directory).hold_bias is None


@pytest.mark.parametrize(("section", "match"), [
    ({"record": {}}, "lacks its 'relax' grid"),
    ([1, 2], "lacks its 'relax' grid"),
    ({"relax": {"forces_n": [1.0]}}, "missing temps_c"),
])
def test_a_damaged_calibration_is_a_one_line_model_error(tmp_path: Path, section: object,
                                                         match: str) -> None:
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    path = directory / "manifest.json"
    manifest = json.loads(path.read_text())
    manifest["hold_bias"] = section
    path.write_text(json.dumps(manifest))
    with pytest.raises(ModelFileError, match=match) as info:
        load_models(directory)
    assert "manifest.json" in str(info.value)
    assert "\n" not in str(info.value)


def test_set_hold_bias_refuses_a_directory_that_is_not_models(tmp_path: Path) -> None:
    with pytest.raises(ModelFileError):
        set_hold_bias(tmp_path / "missing", grid(), {})
    assert not (tmp_path / "missing").exists()


def test_set_hold_bias_refuses_models_that_changed_while_it_measured(tmp_path: Path) -> None:
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    measured = load_models(directory).manifest
    changed = json.loads(json.dumps(measured))
    changed["icfn"]["sha256"] = "0" * 64
    before = (directory / "manifest.json").read_bytes()
    with pytest.raises(InputError, match="models changed while the calibration ran"):
        set_hold_bias(directory, grid(), {}, measured_on=changed)
    assert (directory / "manifest.json").read_bytes() == before
    set_hold_bias(directory, grid(), {}, measured_on=measured)
    record = json.loads((directory / "manifest.json").read_text())["hold_bias"]["record"]
    assert record["model_sha256"]["icfn"] == measured["icfn"]["sha256"]
