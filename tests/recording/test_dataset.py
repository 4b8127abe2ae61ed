"""Recordings of holds on the twin become a dataset that ``relaxgrip train`` trains on."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.learning import icfn as icfn_module
from relaxgrip.learning.datastore import load_dataset
from relaxgrip.learning.store import load_models
from relaxgrip.learning.training import train_models
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
from tests.clitools import assert_one_error_line, run_main


def test_from_recordings_then_train(fixed_holds: list[Path], tmp_path: Path,
                                    monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "data"
    code, stdout, err = run_main(["dataset", "from-recordings", *fixed_holds, "--out", out,
                                  "--json", "--icfn-every-s", "0.5"], monkeypatch, capsys)
    assert code == 0, err
    manifest = json.loads(stdout)
    assert manifest["counts"]["rcfn_sequences"] == 3  # every fixed-aperture hold
    data = load_dataset(out)
    assert (out / "README.md").is_file()
    assert set(data.icfn["split"]) == {"train", "val"}
    assert data.icfn.groupby("episode")["split"].nunique().max() == 1  # split by recording
    x, y = data.icfn_xy("all")
    assert x.shape[1] == len(ICFN_SCHEMA.names)
    assert np.isfinite(x).all()
    assert y.min() >= 0.0
    assert y.max() > 3.0  # labels from the twin's true force
    seqs = data.sequences
    assert (seqs["f0_n"] > seqs["f_end_n"]).all()  # the force relaxed at the fixed aperture
    assert ((seqs["tau_s"] > 0) & (seqs["k_n"] > 0)).all()
    r, k = data.rcfn_xy("all")
    assert r.shape[1] == len(RCFN_SCHEMA.names)
    assert len(r) >= 6
    assert np.isfinite(k).all()
    # A small training: the first two candidates of the ICFN grid (the full grid is the
    # same code, six times longer).
    monkeypatch.setattr(icfn_module, "ICFN_CANDIDATES", icfn_module.ICFN_CANDIDATES[:2])
    trained = train_models(data)
    assert len(trained.icfn_candidates) == 2
    models_dir = tmp_path / "models"
    trained.save(models_dir)
    bundle = load_models(models_dir, icfn_feature_schema=ICFN_SCHEMA,
                         rcfn_feature_schema=RCFN_SCHEMA)
    pred = bundle.icfn.predict(x)
    assert np.isfinite(pred).all()
    assert float(np.mean(np.abs(pred - y))) < float(np.mean(np.abs(y - y.mean())))
    assert np.isfinite(bundle.rcfn.predict(r)).all()


def test_from_recordings_splits_the_hold_recordings_apart(
        relax_hold: tuple[Path, object], fixed_holds: list[Path], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A regulated hold gives ICFN rows only; the two fixed-aperture holds go one to train,
    one to val, so `relaxgrip train` finds RCFN rows in both (the same file named twice
    counts once)."""
    out = tmp_path / "data"
    code, stdout, err = run_main(["dataset", "from-recordings", relax_hold[0], *fixed_holds[:2],
                                  fixed_holds[0], "--out", out, "--json"], monkeypatch, capsys)
    assert code == 0, err
    manifest = json.loads(stdout)
    assert len(manifest["spec"]["recordings"]) == 3
    splits = manifest["counts"]["splits"]
    assert splits["rcfn_sequences train"] == splits["rcfn_sequences val"] == 1
    assert manifest["warnings"] == []
    code, stdout, err = run_main(["dataset", "from-recordings", fixed_holds[0], "--out",
                                  tmp_path / "one"], monkeypatch, capsys)
    assert code == 0, err
    assert "warning: no rcfn_sequences val rows" in err


def test_from_recordings_never_writes_over_its_recordings(
        fixed_holds: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    folder = fixed_holds[0].parent
    before = sorted(p.name for p in folder.iterdir())
    code, _, err = run_main(["dataset", "from-recordings", folder, "--out", folder],
                            monkeypatch, capsys)
    assert code == 2
    assert "holds the recording" in err
    assert sorted(p.name for p in folder.iterdir()) == before
    dataset = tmp_path / "data"
    code, _, err = run_main(["dataset", "from-recordings", fixed_holds[0], "--out", dataset],
                            monkeypatch, capsys)
    assert code == 0, err
    (dataset / "notes.txt").write_text("mine", encoding="utf-8")
    code, _, err = run_main(["dataset", "from-recordings", fixed_holds[0], "--out", dataset],
                            monkeypatch, capsys)
    assert code == 2
    assert "holds files that are not the relaxgrip-dataset output's (notes.txt)" in err
    assert (dataset / "notes.txt").read_text(encoding="utf-8") == "mine"


@pytest.mark.parametrize(("every", "expected"), [
    ("inf", "--icfn-every-s must be a finite number, got inf"),
    ("nan", "--icfn-every-s must be a finite number, got nan"),
    ("0", "--icfn-every-s must be > 0, got 0.0"),
    ("-1", "--icfn-every-s must be > 0, got -1.0"),
])
def test_from_recordings_refuses_an_icfn_interval_that_is_not_finite_and_positive(
        every: str, expected: str, fixed_holds: list[Path], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "data"
    code, stdout, err = run_main(["dataset", "from-recordings", fixed_holds[0], "--out", out,
                                  "--icfn-every-s", every], monkeypatch, capsys)
    assert_one_error_line(code, stdout, err, expected)
    assert not out.exists()
