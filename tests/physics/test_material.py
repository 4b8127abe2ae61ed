"""The material model: shift laws, Prony series in reduced time, the material file's JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.physics.material import (
    MATERIAL_SCHEMA_VERSION,
    SHIFT_MODELS,
    Material,
    ShiftLaw,
    log10_shift,
)

PARAMS = {"wlf": (12.0, 80.0), "arrhenius": (2.0e5,), "two_regime": (12.0, 60.0, 45.0, 2.5e5),
          "poly": (-0.2, 1e-3, 0.0, 0.0)}


def material(model: str = "two_regime") -> Material:
    return Material("E", 15e6, (300e6, 200e6, 100e6), (1e-2, 1.0, 1e2),
                    ShiftLaw(model, PARAMS[model], 40.0), (20.0, 70.0),
                    json.dumps({"made_by": "test"}))


@pytest.mark.parametrize("model", SHIFT_MODELS)
def test_shift_is_zero_at_the_reference_and_falls_with_temperature(model: str) -> None:
    law = ShiftLaw(model, PARAMS[model], 40.0)
    assert float(law.log10_at(40.0)) == pytest.approx(0.0, abs=1e-12)
    values = law.log10_at(np.linspace(20.0, 70.0, 26))
    assert np.all(np.diff(values) < 0)


def test_two_regime_is_continuous_at_tg_and_arrhenius_below() -> None:
    _, _, tg, ea = PARAMS["two_regime"]
    below = log10_shift("two_regime", PARAMS["two_regime"], tg - 1e-9, 40.0)
    above = log10_shift("two_regime", PARAMS["two_regime"], tg + 1e-9, 40.0)
    assert float(below) == pytest.approx(float(above), abs=1e-8)
    # Below Tg the difference between two temperatures is the Arrhenius one.
    d = log10_shift("two_regime", PARAMS["two_regime"], [20.0, 30.0], 40.0)
    arr = log10_shift("arrhenius", (ea,), [20.0, 30.0], 40.0)
    assert d[0] - d[1] == pytest.approx(arr[0] - arr[1], rel=1e-12)


def test_wlf_refuses_its_pole() -> None:
    with pytest.raises(ValueError, match="pole"):
        log10_shift("wlf", (10.0, 30.0), -5.0, 40.0)


def test_moduli_limits_and_signs() -> None:
    m = material()
    assert float(m.relaxation_modulus_pa(0.0, 40.0)) == pytest.approx(m.e_instant_pa)
    assert float(m.relaxation_modulus_pa(1e12, 40.0)) == pytest.approx(m.e_inf_pa)
    assert float(m.storage_modulus_pa(1e-12, 40.0)) == pytest.approx(m.e_inf_pa, rel=1e-6)
    assert float(m.storage_modulus_pa(1e12, 40.0)) == pytest.approx(m.e_instant_pa, rel=1e-6)
    w = np.logspace(-4, 4, 50)
    assert np.all(m.loss_modulus_pa(w, 40.0) > 0)
    # Warmer is faster: at a fixed time the modulus is lower.
    assert float(m.relaxation_modulus_pa(1.0, 60.0)) < float(m.relaxation_modulus_pa(1.0, 30.0))
    # Time-temperature superposition: (t, T) and (t / a_T, T_ref) are the same state.
    a = 10 ** float(m.shift.log10_at(55.0))
    assert float(m.relaxation_modulus_pa(3.0, 55.0)) == pytest.approx(
        float(m.relaxation_modulus_pa(3.0 / a, 40.0)), rel=1e-12)
    assert np.allclose(m.taus_at(55.0), np.array(m.tau_s) * a)


@pytest.mark.parametrize("model", SHIFT_MODELS)
def test_json_round_trip(model: str) -> None:
    m = material(model)
    text = json.dumps(m.to_dict())
    back = Material.from_dict(json.loads(text))
    assert back == m
    assert back.to_dict()["schema_version"] == MATERIAL_SCHEMA_VERSION


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d.update(schema="other"), "not a material file"),
    (lambda d: d.update(schema_version=MATERIAL_SCHEMA_VERSION + 1), "newer"),
    (lambda d: d.pop("prony"), "missing field 'prony'"),
    (lambda d: d["prony"]["terms"][0].update(modulus_pa=-1.0), "> 0"),
    (lambda d: d["prony"]["terms"][0].update(tau_s=float("nan")), "finite"),
    (lambda d: d["shift"].update(model="vft"), "unknown shift model"),
    (lambda d: d["shift"]["params"].pop("c1"), "missing field 'c1'"),
    (lambda d: d["prony"].update(terms=[]), "non-empty"),
    (lambda d: d.update(modulus="K"), "modulus"),
])
def test_bad_material_files_are_one_line_errors(edit: object, message: str) -> None:
    d = material().to_dict()
    edit(d)  # type: ignore[operator]
    with pytest.raises(InputError, match=message) as info:
        Material.from_dict(d, "m.json")
    assert str(info.value).startswith("m.json: ")
    assert "\n" not in str(info.value)
