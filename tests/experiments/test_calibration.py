"""``calibrate`` on twin holds: fitted against the force reference, written atomically."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.experiments import calibration as calibration_module
from relaxgrip.experiments.ablation import paired_interval
from relaxgrip.experiments.calibration import calibrate
from relaxgrip.learning.store import MANIFEST_NAME, load_models
from relaxgrip.learning.training import default_models_dir


@pytest.fixture
def models_dir(tmp_path: Path) -> Path:
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    return directory


def test_calibrate_fits_the_force_reference_not_the_truth_and_writes_the_manifest(
        models_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    read: list[str] = []
    real = calibration_module.calibration_hold

    def spy(name: str, *args: object, **kwargs: object):  # type: ignore[no-untyped-def]
        hold = real(name, *args, **kwargs)  # type: ignore[arg-type]
        read.append(name)
        return hold

    monkeypatch.setattr(calibration_module, "calibration_hold", spy)
    bundle = load_models(models_dir)
    run = calibrate(models_dir, bundle, seeds=(1000, 1001, 1002, 1003), duration_s=8.0)
    assert len(read) == 4
    assert run.written == models_dir / MANIFEST_NAME
    again = load_models(models_dir)
    assert again.calibration == run.calibration
    assert again.calibration is not None
    assert again.calibration.record["seeds"] == [1000, 1001, 1002, 1003]
    for hold in run.holds:
        # The force reference is noisy: it is not the truth the metrics read.
        assert np.isfinite(hold.force_ref_n).sum() > 100


def test_a_dry_run_writes_nothing_and_too_many_holds_are_refused(models_dir: Path) -> None:
    before = (models_dir / MANIFEST_NAME).read_bytes()
    bundle = load_models(models_dir)
    run = calibrate(models_dir, bundle, seeds=(1000, 1001, 1002, 1003), duration_s=6.0,
                    dry_run=True)
    assert run.written is None
    assert (models_dir / MANIFEST_NAME).read_bytes() == before
    with pytest.raises(InputError, match="at most 12 holds"):
        calibrate(models_dir, bundle, seeds=tuple(range(13)))


def test_the_ablations_interval_is_paired_over_seeds() -> None:
    mean, lo, hi = paired_interval([1.0, 2.0, 3.0], [0.5, 1.5, 2.5])
    assert (mean, lo, hi) == pytest.approx((0.5, 0.5, 0.5))
    mean, lo, hi = paired_interval([1.0, 2.0, 3.5, 2.0], [1.0, 1.0, 1.0, 1.5])
    assert lo < mean < hi
    assert np.isnan(paired_interval([1.0], [0.5])[1])
