"""The observer's calibration: the error model's fit, the split-conformal band, the record."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.learning.calibration import (
    BAND_FLOOR_N,
    COVERAGE,
    MIN_HOLDS,
    Calibration,
    CalibrationHold,
    fit_calibration,
)

COEF = (0.05, 0.01, -0.2)


def _hold(seed: int, f_onset: float, noise_n: float = 0.02) -> CalibrationHold:
    """A 280 s hold whose estimate errs by the model ``COEF`` plus a run offset; the force
    reference is the truth plus its own noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 280.0, 1.0 / 30.0)
    relaxed = 0.1 * f_onset * -np.expm1(-t / 60.0)
    truth = np.full(t.size, f_onset) - relaxed
    error = COEF[0] + COEF[1] * f_onset + COEF[2] * relaxed + rng.normal(0.0, 0.01)
    ref = truth + rng.normal(0.0, noise_n, t.size)
    ref[::7] = math.nan  # frames without a reading
    return CalibrationHold(f"hold {seed}", t, truth + error, f_onset, relaxed, ref,
                           (100.0, 280.0))


def test_the_fit_recovers_the_error_model_from_noisy_force_reference_readings() -> None:
    holds = [_hold(s, f) for s, f in enumerate((1.0, 5.0, 8.0) * 4)]
    cal = fit_calibration(holds, {"source": "test"})
    assert cal.coef == pytest.approx(COEF, abs=0.01)
    assert cal.record["source"] == "test"
    assert cal.record["band_rank"] == math.ceil((len(holds) + 1) / 2)
    assert len(cal.record["scores"]) == len(holds)


def test_the_band_is_the_median_holds_out_of_sample_95_percent_band() -> None:
    holds = [_hold(s, f) for s, f in enumerate((1.0, 5.0, 8.0) * 4)]
    cal = fit_calibration(holds)
    scores = sorted(cal.record["scores"])
    assert cal.band_rel == scores[cal.record["band_rank"] - 1]
    # Fresh holds: about half of them, or more, covered for 95 % of their window.
    covered = []
    for seed in range(100, 140):
        hold = _hold(seed, 5.0)
        lo = hold.window_s[0]
        keep = (hold.hold_s >= lo) & np.isfinite(hold.force_ref_n)
        est = hold.estimate_n - np.array([cal.error_n(hold.f_onset_n, r)
                                          for r in hold.relaxed_n])
        inside = np.abs(est - hold.force_ref_n)[keep] <= cal.half_width_n(hold.f_onset_n)
        covered.append(inside.mean() >= COVERAGE)
    assert np.mean(covered) >= 0.4
    assert cal.half_width_n(5.0) == pytest.approx(cal.band_rel * (BAND_FLOOR_N + 5.0))


def test_too_few_holds_or_no_force_reference_is_refused() -> None:
    with pytest.raises(InputError, match=f"at least {MIN_HOLDS}"):
        fit_calibration([_hold(s, 5.0) for s in range(MIN_HOLDS - 1)])
    blind = _hold(9, 5.0)
    blind = CalibrationHold(blind.name, blind.hold_s, blind.estimate_n, blind.f_onset_n,
                            blind.relaxed_n, np.full(blind.hold_s.size, math.nan),
                            blind.window_s)
    with pytest.raises(InputError, match="hold 9: 0 frames with a force reference"):
        fit_calibration([_hold(s, 5.0) for s in range(MIN_HOLDS)] + [blind])


def test_the_manifest_section_round_trips_and_other_versions_are_refused() -> None:
    cal = Calibration((0.1, 0.0, 0.3), 0.02, {"holds": ["a"]})
    again = Calibration.from_dict(cal.to_dict())
    assert again == cal
    old = {**cal.to_dict(), "version": "relaxgrip-calibration-v0"}
    with pytest.raises(InputError, match="recalibrate with relaxgrip calibrate"):
        Calibration.from_dict(old)
    with pytest.raises(InputError, match="coefficients"):
        Calibration((0.1, math.nan, 0.0), 0.02)
    with pytest.raises(InputError, match="band scale"):
        Calibration((0.1, 0.0, 0.0), -1.0)
