"""Identifying a material: shift factors, shift laws, Prony selection, the synthetic round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments.material_fit import fit_material, load_measurements
from relaxgrip.physics.material import Material, ShiftLaw
from relaxgrip.physics.material_fit import (
    MeasuredSet,
    Measurements,
    pair_shift,
    select_terms,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "pyvisco"
TRUE = Material("E", 15e6, (300e6, 250e6, 200e6, 150e6, 100e6, 60e6),
                tuple(10.0 ** np.arange(-3, 6, 1.5)),
                ShiftLaw("two_regime", (12.0, 60.0, 45.0, 2.5e5), 40.0), (20.0, 70.0))


def synthetic(domain: str, seed: int, noise: float = 0.005) -> Measurements:
    rng = np.random.default_rng(seed)
    x = np.logspace(-1, 3, 13) if domain == "time" else 2 * np.pi * np.logspace(-1, 2, 10)
    sets = []
    for temp in np.arange(20.0, 71.0, 5.0):
        if domain == "time":
            y, y2 = TRUE.relaxation_modulus_pa(x, temp), None
        else:
            y, y2 = TRUE.storage_modulus_pa(x, temp), TRUE.loss_modulus_pa(x, temp)
            y2 = y2 * np.exp(noise * rng.standard_normal(x.size))
        y = y * np.exp(noise * rng.standard_normal(x.size))
        sets.append(MeasuredSet(float(temp), x, y, y2, f"set {temp:g}"))
    return Measurements(domain, "E", tuple(sets))


@pytest.mark.parametrize("domain", ["time", "freq"])
def test_pair_shift_finds_a_known_shift(domain: str) -> None:
    meas = synthetic(domain, seed=11, noise=0.0)
    cold, warm = meas.sets[4], meas.sets[5]  # 40 and 45 °C
    d, sigma = pair_shift(cold, warm, meas.sign)
    truth = float(TRUE.shift.log10_at(45.0) - TRUE.shift.log10_at(40.0))
    assert d == pytest.approx(truth, abs=0.02)
    assert 0 < sigma < 0.05


def test_sets_that_do_not_overlap_are_refused() -> None:
    x = np.logspace(-1, 1, 5)
    cold = MeasuredSet(20.0, x, np.full(5, 1e9) * (1 + 0.01 * np.arange(5)), None, "a.csv, set 0")
    warm = MeasuredSet(30.0, x, np.full(5, 1e7) * (1 + 0.01 * np.arange(5)), None, "a.csv, set 1")
    with pytest.raises(InputError, match=r"a.csv, set 0 .* a.csv, set 1 .*do not overlap"):
        pair_shift(cold, warm, -1.0)


def test_selection_takes_the_fewest_terms_reaching_the_target() -> None:
    u = np.linspace(-3, 3, 60)
    y = np.asarray(TRUE.relaxation_modulus_pa(10.0**u, 40.0))
    loose = select_terms("time", u, y, None, 0.02, 12)
    tight = select_terms("time", u, y, None, 0.002, 12)
    assert loose.table[-1]["rms_log10_master"] <= 0.02
    assert all(row["rms_log10_master"] > 0.02 for row in loose.table[:-1])
    assert len(loose.taus) < len(tight.taus)
    assert np.all(loose.moduli > 0)
    assert loose.e_inf >= 0


@pytest.mark.parametrize("domain", ["time", "freq"])
def test_synthetic_round_trip_recovers_the_shift_law(domain: str) -> None:
    result = fit_material(synthetic(domain, seed=17), ref_temp_c=40.0)
    law = result.material.shift
    assert law.model == "two_regime"
    for got, sigma, true in zip(law.params, result.law_sigma, TRUE.shift.params, strict=True):
        assert abs(got - true) <= 1.96 * sigma + 1e-9 * abs(true), (got, sigma, true)
    assert result.rms_log10 < 0.01
    temps = result.measurements.temps_c
    assert np.allclose(result.log_at_ref, TRUE.shift.log10_at(temps), atol=0.05)


def test_default_reference_is_a_measured_temperature_near_the_middle() -> None:
    meas = synthetic("time", seed=3)
    result = fit_material(meas, max_terms=4)
    assert result.material.ref_temp_c == pytest.approx(45.0)
    d = result.to_dict()
    assert d["log_aT"]["45"] == 0.0
    assert set(d["log_aT"]) == {f"{t:d}" for t in range(20, 71, 5)}


@pytest.mark.slow
def test_pyvisco_time_domain_example_meets_the_goal() -> None:
    meas = load_measurements([DATA / "time_user_raw.csv"])
    result = fit_material(meas, max_terms=12)
    assert len(result.material.tau_s) <= 12
    assert result.rms_log10 <= 0.012
    ref = np.loadtxt(DATA / "time_user_raw__shift_factors.csv", delimiter=",", skiprows=2)
    theirs = dict(zip(ref[:, 0], ref[:, 1], strict=True))
    mine = result.to_dict()["log_aT"]
    offset = theirs[25.0]
    for temp, value in theirs.items():
        diff = abs(mine[f"{round(temp):d}"] - (value - offset))
        assert diff <= (0.3 if temp >= 32 else 1.0), (temp, diff)
