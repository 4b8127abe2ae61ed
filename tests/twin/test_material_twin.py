"""A twin whose SMP comes from a material file (docs/material.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments.characterization import characterize
from relaxgrip.hardware.material_file import load_material_file
from relaxgrip.physics.material import Material, ShiftLaw
from relaxgrip.physics.smp import SMPParams, branch_shares, storage_modulus_pa
from relaxgrip.twin import GripperTwin, TwinConfig

MAT = Material("E", 12e6, (200e6, 300e6, 400e6, 250e6), (1e-3, 1e0, 1e2, 1e4),
               ShiftLaw("two_regime", (10.0, 50.0, 48.0, 2.5e5), 40.0), (20.0, 70.0),
               json.dumps({"made_by": "test"}))


def test_default_twin_has_no_material() -> None:
    cfg = TwinConfig()
    assert cfg.finger.smp.material is None
    assert cfg.material_provenance is None


def test_material_sets_modulus_shift_and_branches() -> None:
    smp = SMPParams.from_material(MAT)
    temps = np.linspace(20.0, 70.0, 11)
    assert np.allclose(storage_modulus_pa(temps, smp), MAT.relaxation_modulus_pa(1.0, temps))
    shares = branch_shares(temps, smp)
    assert shares.shape == (11, 4)
    assert np.all(shares >= 0)
    assert np.all(shares.sum(axis=1) < 1)
    assert 20.0 <= smp.tg_c <= 70.0


def test_material_twin_runs_and_records_provenance(tmp_path: Path) -> None:
    path = tmp_path / "m.json"
    path.write_text(json.dumps(MAT.to_dict()))
    cfg = TwinConfig().with_material(load_material_file(path))
    assert cfg.material_provenance is not None
    assert cfg.material_provenance["file"] == "m.json"
    assert len(cfg.relax.tau_ref_s) == 4
    twin = GripperTwin(cfg, seed=1)
    twin.reset(1)
    result = characterize(cfg.finger)
    assert result.to_dict()["material"]["file"] == "m.json"
    assert np.all(result.k80_drop_pct > 0)


def test_bad_material_file_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "m.json"
    path.write_text("{not json")
    with pytest.raises(InputError, match="not a JSON material file"):
        load_material_file(path)
