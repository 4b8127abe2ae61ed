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
    DEFAULT_SCENARIOS,
    BandCalibration,
    BandSamples,
    BandScales,
    calibrate_band,
    fit_scales,
    least_covering,
    measuring,
    quantile_floor,
    seed_intervals,
)
from relaxgrip.experiments.controlled_hold import HoldResult, run_hold
from relaxgrip.experiments.scenarios import scenario_hold
from relaxgrip.learning.observer import (
    ObserverFileError,
    default_observer_dir,
    load_default_observer,
    load_observer,
    set_band_scale,
)
from tests.clitools import assert_refused_unchanged, run_main

#: A drift scale for the tests that need the band's drift part: session 55's.  The shipped
#: one is 0 since the observer keeps the chain's reading after its share fit.
DRIFT_SCALE = 0.040


@pytest.fixture(scope="module")
def short_hold() -> HoldResult:
    return run_hold("observer", duration_s=8.0, seed=0)


def test_samples_do_not_depend_on_the_scales_the_observer_held_with(
        short_hold: HoldResult) -> None:
    """The same seed with the band's parts at other scales: the same samples (the loop is
    unchanged: the band is only reported), and the coverage of the recorded band is the
    samples' at the scales it had.  A short ramp, so that both parts are there (with
    :data:`DRIFT_SCALE`)."""
    model = load_default_observer()
    model.drift_scale = DRIFT_SCALE
    wide = load_default_observer()
    wide.band_scale = 2.0 * model.band_scale
    wide.drift_scale = 3.0 * model.drift_scale
    wide.band_floor_n = model.band_floor_n + 0.05
    ramp = scenario_hold("observer", "ramp", seed=1, duration_s=40.0, observer=model)
    other = scenario_hold("observer", "ramp", seed=1, duration_s=40.0, observer=wide)
    x = BandSamples.of(ramp, BandScales.of(model))
    assert x.size > 100
    assert np.count_nonzero(x.drift_n > 0) > 100
    y = BandSamples.of(other, BandScales.of(wide))
    for name in ("error_n", "onset_n", "drift_n"):
        np.testing.assert_allclose(getattr(y, name), getattr(x, name), rtol=1e-9, atol=1e-12)
    assert ramp.metrics()["band_coverage"] == pytest.approx(x.coverage(BandScales.of(model)))
    assert other.metrics()["band_coverage"] == pytest.approx(x.coverage(BandScales.of(wide)))
    np.testing.assert_array_equal(other.estimate_n, ramp.estimate_n)
    standard = BandSamples.of(short_hold, BandScales.of(model))
    assert short_hold.metrics()["band_coverage"] == pytest.approx(
        standard.coverage(BandScales.of(model)))


def test_the_drift_part_is_recorded_once_the_share_fit_ends() -> None:
    """A short ramp: zero while the share is fitted, then the relaxing share's part, the
    recorded half-width the sum of the floor, the onset part and it; before the hold, the
    floor and the ICFN's onset error."""
    model = load_default_observer()
    model.band_floor_n = 0.03
    model.drift_scale = DRIFT_SCALE
    model.band_temps_c, model.band_temp_factors = (), ()  # the ramp heats: 1 throughout
    hold = scenario_hold("observer", "ramp", seed=1, duration_s=40.0, observer=model)
    drift, hold_s = hold.series("band_drift_n"), hold.series("hold_s")
    assert np.all(drift[hold_s < 5.0] == 0.0)
    assert drift[-1] > 0.0
    half = 0.5 * (hold.series("band_hi_n") - hold.series("band_lo_n"))
    onset = np.array([model.band_rel(t, 40.0) for t in hold_s]) * hold.series("f_onset_n")
    started = np.isfinite(onset)  # the onset frame itself has the band of the closing
    assert started.mean() > 0.99
    np.testing.assert_allclose(half[started], (0.03 + onset + drift)[started], rtol=1e-9,
                               atol=1e-12)
    closing = np.isnan(hold_s) & np.isfinite(half)
    assert closing.any()
    est = hold.series("estimate_n")[closing]
    np.testing.assert_allclose(half[closing], 0.03 + model.onset_rel_ * model.band_scale * est,
                               rtol=1e-9, atol=1e-12)
    x = BandSamples.of(hold, BandScales.of(model))
    assert x.coverage(BandScales.of(model)._replace(drift_scale=0.0)) <= x.coverage(
        BandScales.of(model))


def test_the_least_covering_scale_by_hand() -> None:
    ratios = np.arange(1.0, 101.0)[::-1].copy()  # 100 ratios, 1 to 100
    assert least_covering(ratios, 0.95) == 95.0  # 95 of them are within 95
    assert least_covering(ratios, 0.951) == 96.0
    assert least_covering(np.array([3.0]), 0.95) == 3.0
    assert np.mean(ratios <= least_covering(ratios, 0.9)) >= 0.9
    with pytest.raises(InputError, match="no band"):
        least_covering(np.zeros(0), 0.95)


def _samples(rng: np.random.Generator, n: int, spread: float = 0.0,
             drift_share: float = 0.5) -> BandSamples:
    """Errors uniform in [0, 1) times a seed's offset; half of them with a drift part."""
    drift = np.where(rng.uniform(size=n) < drift_share, rng.uniform(0.5, 1.5, n), 0.0)
    error = rng.uniform(0, 1, n) * rng.lognormal(0, spread) + drift
    return BandSamples(error, np.ones(n), drift)


def test_fit_scales_by_hand() -> None:
    """The band scale is set where the drift part is not; the drift scale then covers what
    the band scale leaves of the others."""
    still = np.arange(1.0, 101.0)  # band scale: 95 of these within 95
    error = np.concatenate([still, 95.0 + 2.0 * np.arange(1.0, 21.0)])  # 20 over by 2..40
    onset = np.ones(120)
    drift = np.concatenate([np.zeros(100), np.ones(20)])
    (band, scale, floor, _, _), drift_set = fit_scales(BandSamples(error, onset, drift), 0.95)
    assert drift_set
    assert floor == 0.0  # one onset part for all: a floor is a scale
    assert band == 95.0
    assert scale == 38.0  # 19 of the 20 excesses (2, 4, .., 40) within 38
    x = BandSamples(error, onset, drift)
    assert x.coverage(BandScales(band, scale, 0.0)) == pytest.approx(114 / 120)  # 95 + 19
    assert x.coverage(BandScales(band, scale - 1e-9, 0.0)) < x.coverage(
        BandScales(band, scale, 0.0))  # the least such scale
    assert x.coverage(BandScales(band, 0.0, 0.0)) == pytest.approx(95 / 120)  # none of the 20
    # Covered by the onset part alone: no drift part needed.
    assert fit_scales(BandSamples(np.full(4, 0.5), np.ones(4), np.array([0, 0, 1, 1.0])),
                      0.95) == (BandScales(0.5, 0.0, 0.0), True)
    assert fit_scales(BandSamples(still, onset[:100], drift[:100]), 0.95, 0.7) == (
        BandScales(95.0, 0.7, 0.0), False)
    with pytest.raises(InputError, match="without its drift part"):
        fit_scales(BandSamples(still, onset[:100], np.ones(100)), 0.95)


def _two_forces(rng: np.random.Generator, floor: float, share: float,
                n: int = 4000) -> BandSamples:
    """Holds at 1 N and 8 N (onset parts 0.1 and 0.8 N): errors whose 95 % quantile is
    ``floor + share * onset``, a quarter of the samples at 1 N."""
    onset = np.where(rng.uniform(size=n) < 0.25, 0.1, 0.8)
    error = rng.uniform(0.0, 1.0, n) * (floor + share * onset) / 0.95
    return BandSamples(error, onset, np.zeros(n))


def test_the_floor_covers_each_force_where_a_share_covers_only_the_whole() -> None:
    """An error partly absolute: a share of the force alone covers 95 % of the samples, but
    at 1 N far fewer; the floor and the share cover each force.  An error in proportion to
    the force keeps no floor."""
    rng = np.random.default_rng(3)
    x = _two_forces(rng, floor=0.05, share=0.2)
    assert quantile_floor(x.error_n, x.onset_n, 0.95) == pytest.approx(0.05, abs=0.008)
    scales, _ = fit_scales(x, 0.95)
    assert scales.band_scale == pytest.approx(0.2, abs=0.02)
    assert x.coverage(scales) >= 0.95
    light = x.onset_n < 0.5
    for group in (light, ~light):
        part = BandSamples(x.error_n[group], x.onset_n[group], x.drift_n[group])
        assert part.coverage(scales) == pytest.approx(0.95, abs=0.015)
    share_only = BandScales(least_covering(x.error_n / x.onset_n, 0.95), 0.0, 0.0)
    light_part = BandSamples(x.error_n[light], x.onset_n[light], x.drift_n[light])
    assert light_part.coverage(share_only) < 0.85  # the share alone is too narrow at 1 N
    heavy_part = BandSamples(x.error_n[~light], x.onset_n[~light], x.drift_n[~light])
    assert heavy_part.coverage(share_only) == 1.0  # and wider than it need be at 8 N
    relative = _two_forces(rng, floor=0.0, share=0.3)
    assert quantile_floor(relative.error_n, relative.onset_n, 0.95) < 0.005
    assert quantile_floor(np.zeros(5), np.ones(5), 0.95) == 0.0
    with pytest.raises(InputError, match="no band"):
        quantile_floor(np.zeros(0), np.zeros(0), 0.95)


def test_seed_intervals_show_how_sure_the_scales_are() -> None:
    """Resampling seeds: alike seeds leave the scales sure, unlike ones do not, and more
    seeds narrow the intervals."""
    rng = np.random.default_rng(1)
    alike = [_samples(rng, 500) for _ in range(12)]
    (lo, hi), (dlo, dhi), _, _ = seed_intervals(alike, 0.95)
    (band, drift, _, _, _), drift_set = fit_scales(BandSamples.join(alike), 0.95)
    assert drift_set
    assert lo <= band <= hi
    assert dlo <= drift <= dhi
    assert hi - lo < 0.03
    offsets = [_samples(rng, 500, spread=0.5) for _ in range(36)]
    (lo12, hi12), _, _, _ = seed_intervals(offsets[:12], 0.95)
    (lo36, hi36), _, _, _ = seed_intervals(offsets, 0.95)
    assert hi12 - lo12 > 0.2
    assert hi36 - lo36 < hi12 - lo12
    one = seed_intervals([alike[0]], 0.95)
    assert one[0] == pytest.approx((fit_scales(alike[0], 0.95)[0].band_scale,) * 2)
    assert seed_intervals(offsets, 0.95)[0] == (lo36, hi36)  # reproducible
    # Thinned to every 4th frame (6000 of them to 1500): about the same intervals.
    (tlo, thi), _, _, _ = seed_intervals(alike, 0.95, frames=1500)
    assert (tlo, thi) != (lo, hi)
    assert (tlo, thi) == pytest.approx((lo, hi), abs=0.03)
    none = seed_intervals([_samples(rng, 50, drift_share=0.0)], 0.95)[1]
    assert all(math.isnan(v) for v in none)


def _held_at(rng: np.random.Generator, n: int, temp_c: float, spread_n: float,
             drift_n: float = 0.0) -> BandSamples:
    """Samples of holds at ``temp_c`` (read with 0.3 K of noise) whose errors spread by
    ``spread_n`` against an identified half-width of 0.1 N."""
    return BandSamples(np.abs(rng.normal(0.0, spread_n, n)), np.full(n, 0.1),
                       np.full(n, drift_n), temp_c + rng.normal(0.0, 0.3, n))


def test_holds_at_two_temperatures_set_a_factor_at_the_hotter() -> None:
    """Errors twice as wide at 55 °C: the factor there is 2 and each temperature is covered
    95 % of the time, where one factor for both covers the hot holds under 80 %."""
    rng = np.random.default_rng(3)
    warm, hot = _held_at(rng, 20000, 40.0, 0.05), _held_at(rng, 5000, 55.0, 0.10)
    both = BandSamples.join([warm, hot])
    scales, _ = fit_scales(both, 0.95, temps_c=[40.0, 55.0, 40.0])
    assert scales.temps_c == (40.0, 55.0)
    assert scales.temp_factors[0] == 1.0  # where most samples are
    assert scales.temp_factors[1] == pytest.approx(2.0, rel=0.05)
    assert warm.coverage(scales) == pytest.approx(0.95, abs=0.005)
    assert hot.coverage(scales) == pytest.approx(0.95, abs=0.005)
    one, _ = fit_scales(both, 0.95)
    assert one.temp_factors == ()
    assert hot.coverage(one) < 0.8
    # A ramp's samples with the drift part: the first part at its factor there.
    ramp = _held_at(rng, 2000, 55.0, 0.10, drift_n=0.05)
    scales, drift_set = fit_scales(BandSamples.join([both, ramp]), 0.95, temps_c=[40.0, 55.0])
    assert drift_set
    assert scales.drift_scale < 0.2  # the factor covers nearly all of it
    with pytest.raises(InputError, match="no hold sample at 70 °C"):
        fit_scales(both, 0.95, temps_c=[40.0, 70.0])
    # With one temperature the factors kept apply: the hot holds at the kept factor 2.
    kept = ((40.0, 55.0), (1.0, 2.0))
    scales, _ = fit_scales(hot, 0.95, temps_c=[55.0], kept=kept)
    assert (scales.temps_c, scales.temp_factors) == kept
    assert hot.coverage(scales) == pytest.approx(0.95, abs=0.005)
    (_, _, _, factors) = seed_intervals([BandSamples.join([_held_at(rng, 400, 40.0, 0.05),
                                                          _held_at(rng, 100, 55.0, 0.1)])
                                         for _ in range(12)], 0.95, resamples=40,
                                        temps_c=[40.0, 55.0])
    assert factors[0] == (1.0, 1.0)
    assert factors[1][0] < 2.0 < factors[1][1]


def test_samples_recover_the_identified_part_through_the_factors() -> None:
    """A band recorded with temperature factors gives back the part at factor 1; the
    observer the holds run with has none (and a drift scale), so that it is exact."""
    scales = BandScales(0.2, 1.0, 0.01, (40.0, 55.0), (1.0, 3.0))
    temp = np.array([40.0, 47.5, 55.0, math.nan])
    onset = np.array([0.1, 0.2, 0.3, 0.4])
    half = 0.01 + 0.2 * np.array([1.0, 2.0, 3.0, 1.0]) * onset
    x = BandSamples.of_series(np.zeros(4), np.zeros(4), -half, half, np.zeros(4), scales, temp)
    np.testing.assert_allclose(x.onset_n, onset)
    assert x.coverage(scales) == 1.0
    assert BandSamples(np.zeros(2), np.ones(2), np.zeros(2)).temp_c.shape == (2,)  # none read
    model = load_default_observer()
    model.band_temps_c, model.band_temp_factors, model.drift_scale = (40.0, 55.0), (1.0, 2.0), 0.0
    held = measuring(model)
    assert (held.band_temp_factors, held.drift_scale) == ((), 1.0)
    assert model.band_temp_factors == (1.0, 2.0)  # a copy


def test_calibration_sets_the_least_scales_that_cover_the_level() -> None:
    model = load_default_observer()
    result = calibrate_band(model, [0], ["standard"], duration_s=8.0)
    held = measuring(model)  # the band the holds ran with: no temperature factors
    hold = run_hold("observer", duration_s=8.0, seed=0, observer=held)
    x = BandSamples.of(hold, BandScales.of(held))
    # One temperature held: the shipped factors are kept and apply where the loop read it.
    onset = x.onset_n * BandScales.of(model).factor(x.temp_c)
    floor = quantile_floor(x.error_n, onset, 0.95)
    assert result.band_floor_n == pytest.approx(floor)
    assert result.band_scale == pytest.approx(least_covering((x.error_n - floor) / onset, 0.95))
    assert (result.band_temps_c, result.band_temp_factors) == (model.band_temps_c,
                                                               model.band_temp_factors)
    assert result.factor_intervals == []
    assert result.floor_interval == pytest.approx((floor,) * 2)
    assert result.scale_interval == pytest.approx((result.band_scale,) * 2)  # one seed
    assert result.record()["scale_interval_90"] == list(result.scale_interval)
    # The standard hold never ends its share fit: the drift scale is kept.
    assert result.drift_samples == 0
    assert result.drift_scale == model.drift_scale
    assert result.record()["drift_interval_90"] == [None, None]
    assert result.samples == x.size
    row = result.scenarios["standard"]["seeds"]["0"]
    assert row["coverage_after"] >= 0.95
    assert row["coverage_before"] == pytest.approx(hold.metrics()["band_coverage"])
    assert model.band_scale == load_default_observer().band_scale  # the model is not changed


def test_calibration_sets_the_drift_scale_where_the_drift_is() -> None:
    """A short ramp: both scales those of its samples, and an observer that held with no
    drift part calibrates it all the same."""
    model = load_default_observer()
    result = calibrate_band(model, [1, 2], ["ramp"], duration_s=40.0, n_jobs=2)
    assert result.drift_samples > 0
    held = measuring(model)
    holds = [scenario_hold("observer", "ramp", seed, 40.0, observer=held) for seed in (1, 2)]
    every = BandSamples.join([BandSamples.of(h, BandScales.of(held)) for h in holds])
    kept = (model.band_temps_c, model.band_temp_factors)
    expected = fit_scales(every, 0.95, temps_c=[40.0], kept=kept)[0]
    assert result.scales[:3] == pytest.approx(expected[:3])
    assert result.scales[3:] == expected[3:] == kept
    assert every.coverage(result.scales) >= 0.95
    silent = load_default_observer()
    silent.drift_scale = 0.0
    again = calibrate_band(silent, [1, 2], ["ramp"], duration_s=40.0, n_jobs=2)
    assert again.scales[:3] == pytest.approx(result.scales[:3])
    assert again.previous_drift_scale == 0.0


@pytest.mark.parametrize(("seeds", "scenarios", "match"), [([], ["standard"], "seed"),
                                                          ([0], ["warp"], "warp"),
                                                          ([0], [], "scenario"),
                                                          ([0], ["ramp", "ramp"], "repeat")])
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
    assert after.drift_scale == before.drift_scale  # kept without a new one
    assert after.band_floor_n == before.band_floor_n
    set_band_scale(directory, 0.42, {"method": "test"}, drift_scale=1.5, floor_n=0.02)
    assert load_observer(directory).drift_scale == 1.5
    assert load_observer(directory).band_floor_n == 0.02
    for bad in (-0.01, math.inf, math.nan):
        with pytest.raises(InputError, match="band floor"):
            set_band_scale(directory, 0.5, {}, floor_n=bad)
    for bad in (0.0, -1.0, math.nan):
        with pytest.raises(InputError, match="band scale"):
            set_band_scale(directory, bad, {})
    for bad in (-0.1, math.inf, math.nan):
        with pytest.raises(InputError, match="drift scale"):
            set_band_scale(directory, 0.5, {}, drift_scale=bad)
    assert load_observer(directory).band_scale == 0.42
    assert load_observer(directory).drift_scale == 1.5
    assert load_observer(directory).band_floor_n == 0.02
    set_band_scale(directory, 0.42, {}, temp_factors=([40.0, 55.0], [1.0, 1.8]))
    assert load_observer(directory).band_temp_factors == (1.0, 1.8)
    set_band_scale(directory, 0.42, {})  # kept without new ones
    assert load_observer(directory).band_temps_c == (40.0, 55.0)
    for temps, factors in (([40.0], [1.0, 2.0]), ([55.0, 40.0], [1.0, 2.0]), ([40.0], [-1.0])):
        with pytest.raises(InputError, match="band temperature factors"):
            set_band_scale(directory, 0.5, {}, temp_factors=(temps, factors))
    assert load_observer(directory).band_temp_factors == (1.0, 1.8)
    set_band_scale(directory, 0.42, {}, temp_factors=([], []))  # none: 1 everywhere
    assert load_observer(directory).band_temp_factors == ()
    with pytest.raises(ObserverFileError):
        set_band_scale(tmp_path / "missing", 0.5, {})
    with pytest.raises(InputError, match="band scale"):  # checked before the directory is read
        set_band_scale(tmp_path / "missing", 0.0, {})


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
    assert load_observer(directory).band_floor_n == pytest.approx(record["band_floor_n"])
    code, out, _ = run_main(["hold", "--estimator", "observer", "--observer", directory,
                             "--duration-s", "8", "--json"], monkeypatch, capsys)
    assert code == 0
    coverage = json.loads(out)["band_coverage"]
    # The same frames, the band's temperature factor at the temperature the observer read
    # (the calibration places samples by the temperature loop's reading): within a frame.
    assert coverage == pytest.approx(
        record["scenarios"]["standard"]["seeds"]["0"]["coverage_after"], abs=1 / 240)
    assert record["summary"]["standard"]["coverage_after"] == pytest.approx(
        record["scenarios"]["standard"]["seeds"]["0"]["coverage_after"])
    code, out, _ = run_main(["calibrate-band", directory, "--seeds", "1", "--scenarios",
                             "standard", "--duration-s", "8", "--jobs", "1", "--dry-run"],
                            monkeypatch, capsys)
    assert code == 0
    assert "measured (not written)" in out
    assert "90 % over resampled seeds" in out
    assert "band floor" in out
    assert "temperature factors kept" in out  # one temperature held
    assert "per scenario, mean over its holds" in out
    assert load_observer(directory).band_scale == pytest.approx(record["band_scale"])


def test_the_command_calibrates_at_three_forces_and_two_temperatures_by_default() -> None:
    """The command's default scenarios are the library's: holds at 1, 5 and 8 N, so that
    the floor is set where the band's absolute part shows."""
    from relaxgrip.cli.learning import _TWIN_BAND
    from relaxgrip.experiments.scenarios import SCENARIOS

    assert _TWIN_BAND["--scenarios"] == ",".join(DEFAULT_SCENARIOS)
    assert {SCENARIOS[name].target_n for name in DEFAULT_SCENARIOS} == {1.0, 5.0, 8.0}
    assert {SCENARIOS[name].temp_c for name in DEFAULT_SCENARIOS} == {40.0, 48.0, 55.0}


def test_summary_is_the_mean_over_each_scenarios_holds() -> None:
    rows = {"1": {"mae_n": 0.1, "coverage_before": 0.5, "coverage_after": 1.0},
            "2": {"mae_n": 0.3, "coverage_before": 0.7, "coverage_after": 0.9}}
    result = BandCalibration(0.2, (0.1, 0.3), 1.0, (0.8, 1.2), 0.01, (0.0, 0.02), 0.95, 10, 4,
                             [1, 2], 0.25, 0.25, 0.0, scenarios={"ramp": {"seeds": rows}})
    assert result.summary() == {"ramp": pytest.approx(
        {"mae_n": 0.2, "coverage_before": 0.6, "coverage_after": 0.95})}


@pytest.mark.parametrize(("args", "expected"), [
    (["calibrate-band", "{missing}"], "manifest.json"),
    (["calibrate-band", "{dir}", "--seeds", "5-2"], "5-2"),
    (["calibrate-band", "{dir}", "--scenarios", "warp"], "warp"),
    (["calibrate-band", "{dir}", "--scenarios", "standard,standard", "--dry-run"],
     "--scenarios repeats a name in 'standard,standard'"),
    (["calibrate-band", "{dir}", "--scenarios", "standard,,ramp", "--dry-run"],
     "--scenarios has an empty item"),
    (["calibrate-band", "{dir}", "--jobs", "0"], "--jobs"),
    (["calibrate-band", "{dir}", "--duration-s", "-1"], "--duration-s"),
    (["calibrate-band", "{dir}", "--duration-s", "1e5"], "--duration-s must be at most 3600 s"),
    (["hold", "--estimator", "relax", "--observer", "{dir}"], "--observer"),
    (["hold", "--estimator", "observer", "--observer", "{missing}"], "manifest.json"),
])
def test_cli_bad_input(args: list[str], expected: str, tmp_path: Path,
                       monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    assert_refused_unchanged(args, expected, default_observer_dir(), tmp_path, monkeypatch,
                             capsys)
