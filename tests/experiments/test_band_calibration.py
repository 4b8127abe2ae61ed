"""Recalibrating the observer's band on closed-loop holds (``relaxgrip calibrate-band``)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments.band_calibration import (
    BandCalibration,
    band_ratios,
    calibrate_band,
    least_covering,
    seed_interval,
)
from relaxgrip.experiments.controlled_hold import HoldResult, run_hold
from relaxgrip.learning.observer import (
    ObserverFileError,
    default_observer_dir,
    load_default_observer,
    load_observer,
    set_band_scale,
)
from tests.clitools import assert_refused_unchanged, run_main


@pytest.fixture(scope="module")
def short_hold() -> HoldResult:
    return run_hold("observer", duration_s=8.0, seed=0)


def test_ratios_do_not_depend_on_the_scale_the_observer_held_with(short_hold: HoldResult) -> None:
    """The same seed with the band twice as wide: the same ratios (the loop is unchanged:
    the band is only reported), and the coverage of the recorded band is the share of
    ratios within the scale it had."""
    model = load_default_observer()
    wide = load_default_observer()
    wide.band_scale = 2.0 * model.band_scale
    other = run_hold("observer", duration_s=8.0, seed=0, observer=wide)
    r = band_ratios(short_hold, model.band_scale)
    assert r.size > 100
    np.testing.assert_allclose(band_ratios(other, wide.band_scale), r, rtol=1e-9)
    assert short_hold.metrics()["band_coverage"] == pytest.approx(
        float(np.mean(r <= model.band_scale)))
    np.testing.assert_array_equal(other.estimate_n, short_hold.estimate_n)


def test_the_least_covering_scale_by_hand() -> None:
    ratios = np.arange(1.0, 101.0)[::-1].copy()  # 100 ratios, 1 to 100
    assert least_covering(ratios, 0.95) == 95.0  # 95 of them are within 95
    assert least_covering(ratios, 0.951) == 96.0
    assert least_covering(np.array([3.0]), 0.95) == 3.0
    assert np.mean(ratios <= least_covering(ratios, 0.9)) >= 0.9
    with pytest.raises(InputError, match="no band"):
        least_covering(np.zeros(0), 0.95)


def test_seed_interval_shows_how_sure_the_scale_is() -> None:
    """Resampling seeds: alike seeds leave the scale sure, unlike ones do not, and more
    seeds narrow the interval."""
    rng = np.random.default_rng(1)
    alike = [rng.uniform(0, 1, 500) for _ in range(12)]
    lo, hi = seed_interval(alike, 0.95)
    assert lo <= least_covering(np.concatenate(alike), 0.95) <= hi
    assert hi - lo < 0.03
    offsets = [rng.uniform(0, 1, 500) * rng.lognormal(0, 0.5) for _ in range(36)]
    lo12, hi12 = seed_interval(offsets[:12], 0.95)
    lo36, hi36 = seed_interval(offsets, 0.95)
    assert hi12 - lo12 > 0.2
    assert hi36 - lo36 < hi12 - lo12
    assert seed_interval([alike[0]], 0.95) == pytest.approx((least_covering(alike[0], 0.95),) * 2)
    assert seed_interval(offsets, 0.95) == (lo36, hi36)  # reproducible


def test_calibration_sets_the_least_scale_that_covers_the_level() -> None:
    model = load_default_observer()
    result = calibrate_band(model, [0], ["standard"], duration_s=8.0)
    hold = run_hold("observer", duration_s=8.0, seed=0)
    r = band_ratios(hold, model.band_scale)
    assert result.band_scale == pytest.approx(least_covering(r, 0.95))
    assert result.scale_interval == pytest.approx((result.band_scale,) * 2)  # one seed
    assert result.record()["scale_interval_90"] == list(result.scale_interval)
    assert result.samples == r.size
    row = result.scenarios["standard"]["seeds"]["0"]
    assert row["coverage_after"] >= 0.95
    assert row["coverage_before"] == pytest.approx(hold.metrics()["band_coverage"])
    assert model.band_scale == load_default_observer().band_scale  # the model is not changed


@pytest.mark.parametrize(("seeds", "scenarios", "match"), [([], ["standard"], "seed"),
                                                          ([0], ["warp"], "warp"),
                                                          ([0], [], "scenario")])
def test_calibration_refuses_what_cannot_run(seeds: list[int], scenarios: list[str],
                                             match: str) -> None:
    with pytest.raises(InputError, match=match):
        calibrate_band(load_default_observer(), seeds, scenarios)


def test_set_band_scale_keeps_the_parameters_and_records_how(tmp_path: Path) -> None:
    directory = tmp_path / "obs"
    shutil.copytree(default_observer_dir(), directory)
    before = load_observer(directory)
    shipped = json.loads((directory / "manifest.json").read_text())["training"]
    set_band_scale(directory, 0.42, {"method": "test", "seeds": [1]})
    after = load_observer(directory)
    assert after.band_scale == 0.42
    for name in ("tau_ref_s_", "log_shift_", "branch_share_", "band_rel_"):
        np.testing.assert_array_equal(getattr(after, name), getattr(before, name))
    manifest = json.loads((directory / "manifest.json").read_text())
    assert manifest["training"]["band_recalibration"] == {"method": "test", "seeds": [1]}
    assert manifest["training"]["n_sequences"] == shipped["n_sequences"]  # the record is kept
    assert manifest["training"]["dataset"] == shipped["dataset"]
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(InputError, match="band scale"):
            set_band_scale(directory, bad, {})
    assert load_observer(directory).band_scale == 0.42
    with pytest.raises(ObserverFileError):
        set_band_scale(tmp_path / "missing", 0.5, {})


def test_cli_calibrates_and_hold_uses_the_result(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    directory = tmp_path / "obs"
    shutil.copytree(default_observer_dir(), directory)
    code, out, _ = run_main(["calibrate-band", directory, "--seeds", "0", "--scenarios",
                             "standard", "--duration-s", "8", "--jobs", "1", "--json"],
                            monkeypatch, capsys)
    assert code == 0
    record = json.loads(out)
    assert record["written"] is True
    lo, hi = record["scale_interval_90"]
    assert lo <= record["band_scale"] <= hi
    assert load_observer(directory).band_scale == pytest.approx(record["band_scale"])
    code, out, _ = run_main(["hold", "--estimator", "observer", "--observer", directory,
                             "--duration-s", "8", "--json"], monkeypatch, capsys)
    assert code == 0
    coverage = json.loads(out)["band_coverage"]
    assert coverage == pytest.approx(
        record["scenarios"]["standard"]["seeds"]["0"]["coverage_after"])
    assert record["summary"]["standard"]["coverage_after"] == pytest.approx(
        record["scenarios"]["standard"]["seeds"]["0"]["coverage_after"])
    code, out, _ = run_main(["calibrate-band", directory, "--seeds", "1", "--scenarios",
                             "standard", "--duration-s", "8", "--jobs", "1", "--dry-run"],
                            monkeypatch, capsys)
    assert code == 0
    assert "measured (not written)" in out
    assert "90 % over resampled seeds" in out
    assert "per scenario, mean over its holds" in out
    assert load_observer(directory).band_scale == pytest.approx(record["band_scale"])


def test_summary_is_the_mean_over_each_scenarios_holds() -> None:
    rows = {"1": {"mae_n": 0.1, "coverage_before": 0.5, "coverage_after": 1.0},
            "2": {"mae_n": 0.3, "coverage_before": 0.7, "coverage_after": 0.9}}
    result = BandCalibration(0.2, (0.1, 0.3), 0.95, 10, [1, 2], 0.25,
                             {"ramp": {"seeds": rows}})
    assert result.summary() == {"ramp": pytest.approx(
        {"mae_n": 0.2, "coverage_before": 0.6, "coverage_after": 0.95})}


@pytest.mark.parametrize(("args", "expected"), [
    (["calibrate-band", "{missing}"], "manifest.json"),
    (["calibrate-band", "{dir}", "--seeds", "5-2"], "5-2"),
    (["calibrate-band", "{dir}", "--scenarios", "warp"], "warp"),
    (["calibrate-band", "{dir}", "--jobs", "0"], "--jobs"),
    (["calibrate-band", "{dir}", "--duration-s", "-1"], "--duration-s"),
    (["hold", "--estimator", "relax", "--observer", "{dir}"], "--observer"),
    (["hold", "--estimator", "observer", "--observer", "{missing}"], "manifest.json"),
])
def test_cli_bad_input(args: list[str], expected: str, tmp_path: Path,
                       monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    assert_refused_unchanged(args, expected, default_observer_dir(), tmp_path, monkeypatch,
                             capsys)
