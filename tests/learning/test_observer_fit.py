"""Identifying the observer on a small twin dataset: physical parameters, spread, persistence."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.learning.build import build_dataset
from relaxgrip.learning.datasets import DatasetSpec
from relaxgrip.learning.datastore import load_dataset
from relaxgrip.learning.observer import ObserverModel, fit_observer, load_observer


@pytest.fixture(scope="module")
def holds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("data") / "holds"
    build_dataset(out, DatasetSpec(icfn_samples=0, rcfn_sequences=30, seed=3), jobs=2)
    return out


def test_fit_on_twin_holds_gives_physical_parameters_and_a_share_spread(holds: Path,
                                                                        tmp_path: Path) -> None:
    model = fit_observer(holds, tmp_path / "obs")
    assert model.identified_on_ == "train"
    temps = model.temps_c_
    assert np.all(np.diff(temps) > 0)
    _, k_cold, tau_cold = model.parameters(float(temps[0]))
    _, k_hot, tau_hot = model.parameters(float(temps[-1]))
    assert np.all(tau_hot < tau_cold)  # time-temperature superposition: hot relaxes faster
    assert np.all(model.branch_share_ >= 0)
    assert np.all(model.branch_share_.sum(axis=1) < 1)
    assert k_hot.sum() > 0
    assert k_cold.sum() > 0
    # The twin scatters the relaxing share between runs: the fit sees it, within reason.
    assert np.all(np.isfinite(model.share_spread_))
    assert np.all(model.share_spread_ >= 0)
    assert 0.01 < float(np.max(model.share_spread_)) < 0.5
    assert 0 < model.band_rel(100.0, 40.0) < 0.5
    back = load_observer(tmp_path / "obs")
    assert np.array_equal(back.share_spread_, model.share_spread_)
    assert back.band_drift_rel(45.0) == model.band_drift_rel(45.0)


def test_fit_refuses_hyperparameters_out_of_range(holds: Path) -> None:
    data = load_dataset(holds)
    with pytest.raises(InputError, match="n_terms"):
        ObserverModel(n_terms=0).fit(data)
    with pytest.raises(InputError, match="band_level"):
        ObserverModel(band_level=1.0).fit(data)
    with pytest.raises(InputError, match=r"band_scale must be > 0, .* got inf"):
        ObserverModel(band_scale=float("inf")).fit(data)  # a band that covers everything


def test_fitting_without_train_holds_says_so(holds: Path, tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    import pandas as pd

    from tests.clitools import run_main

    no_train = tmp_path / "no-train"
    shutil.copytree(holds, no_train)
    table = no_train / "rcfn_sequences.parquet"
    sequences = pd.read_parquet(table)
    sequences["split"] = "test"
    sequences.to_parquet(table, index=False)
    code, _, err = run_main(["fit-observer", "--data", no_train, "--out", tmp_path / "obs"],
                            monkeypatch, capsys)
    assert code == 0, err
    assert "has no RCFN train sequences: the observer was identified on all 30" in err


@pytest.mark.parametrize(("asked", "failed", "suggested"), [(5, 4, 3), (4, 4, 3), (3, 2, 1)])
def test_a_series_the_holds_cannot_tell_apart_names_the_terms_that_would_fit(
        holds: Path, monkeypatch: pytest.MonkeyPatch, asked: int, failed: int,
        suggested: int) -> None:
    # A fit of 5 terms that failed at 4 had suggested --terms 4, which failed the same way.
    import relaxgrip.learning.observer as observer_module
    from relaxgrip.physics.fitting import UnidentifiableError

    def failing(t: object, y: object, n_terms: int) -> None:
        raise UnidentifiableError(f"a {failed}-term Prony series is not identifiable", failed)

    monkeypatch.setattr(observer_module, "fit_prony", failing)
    with pytest.raises(InputError, match=rf"\(relaxgrip fit-observer --terms {suggested}\)$"):
        ObserverModel(n_terms=asked).fit(load_dataset(holds))
