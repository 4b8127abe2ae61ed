"""The models shipped in the package load, and hold their accuracy on freshly generated data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relaxgrip.learning.build import build_dataset
from relaxgrip.learning.datasets import ICFN_SAMPLES, DatasetSpec
from relaxgrip.learning.datastore import load_dataset
from relaxgrip.learning.evaluation import evaluate
from relaxgrip.learning.history import UNRELAXED_FEATURES
from relaxgrip.learning.observer import load_default_observer
from relaxgrip.learning.training import (
    UNRELAXED_MEMBERS,
    default_models_dir,
    load_default_models,
)
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
from relaxgrip.twin import MODELS_FROM, SAME_RUNS_AS, TWIN_VERSION


def test_shipped_models_load_with_the_current_schemas() -> None:
    bundle = load_default_models()
    # Trained on this twin, on one whose dataset runs this one repeats bit for bit, or on
    # one whose frames differ from this one's only where that was measured (MODELS_FROM).
    assert bundle.manifest["twin_version"] in (TWIN_VERSION, *SAME_RUNS_AS, *MODELS_FROM)
    assert bundle.icfn.n_features_in_ == len(ICFN_SCHEMA)
    assert bundle.rcfn.n_features_in_ == len(RCFN_SCHEMA)
    assert bundle.manifest["training"]["dataset"]["counts"]["icfn_samples"] == ICFN_SAMPLES
    assert (default_models_dir() / "manifest.json").is_file()


def test_shipped_models_read_the_loading_history_with_the_shipped_observers_branches() -> None:
    bundle = load_default_models()
    assert bundle.unrelaxed is not None
    assert len(bundle.unrelaxed.members) == UNRELAXED_MEMBERS
    # As relaxgrip train fits it: the pose and the warmest beams, which the object leaves clear.
    assert bundle.unrelaxed.features == UNRELAXED_FEATURES
    assert bundle.manifest["icfn_unrelaxed"]["features"] == list(UNRELAXED_FEATURES)
    observer = load_default_observer()
    for temp_c in (25.0, 40.0, 58.0):
        got_e, got_i, got_tau = bundle.unrelaxed.model.parameters(temp_c)
        want_e, want_i, want_tau = observer.parameters(temp_c)
        assert got_e == want_e
        np.testing.assert_array_equal(got_i, want_i)
        np.testing.assert_array_equal(got_tau, want_tau)


def test_shipped_models_meet_their_accuracy_on_a_fresh_dataset(tmp_path: Path) -> None:
    # A seed the shipped models never saw: every split of it is new to them.
    out = tmp_path / "fresh"
    build_dataset(out, DatasetSpec(icfn_samples=400, rcfn_sequences=40, seed=2026), jobs=2)
    result = evaluate(load_dataset(out), load_default_models(), split="all")
    summary = result.to_dict()
    icfn, rcfn = summary["icfn"], summary["rcfn"]
    # The goals: ICFN MAE <= 0.30 N, R^2 >= 0.95; RCFN NRMSE median <= 0.08, AUC_rel
    # median <= 0.03, mean correlation >= 0.99 (this set: 0.072, 0.011, 0.996).
    assert icfn["mae_n"] <= 0.30
    assert icfn["r2"] >= 0.95
    assert rcfn["nrmse_median"] <= 0.08
    assert rcfn["auc_rel_median"] <= 0.03
    assert rcfn["corr_mean"] >= 0.99
    assert summary["repeatability"]["40"]["sequences"] == 6
