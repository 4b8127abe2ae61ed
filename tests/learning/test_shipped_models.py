"""The models shipped in the package load, and hold their accuracy on freshly generated data."""

from __future__ import annotations

from pathlib import Path

from relaxgrip.learning.build import build_dataset
from relaxgrip.learning.datasets import ICFN_SAMPLES, DatasetSpec
from relaxgrip.learning.datastore import load_dataset
from relaxgrip.learning.evaluation import evaluate
from relaxgrip.learning.training import default_models_dir, load_default_models
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


def test_shipped_models_carry_the_observers_calibration() -> None:
    bundle = load_default_models()
    assert bundle.calibration is not None
    assert bundle.calibration.record["source"] == "twin"
    assert len(bundle.calibration.record["holds"]) <= 12


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
