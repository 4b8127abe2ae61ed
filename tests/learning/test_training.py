"""Training on datasets at the edge of what it can take: a lab's few or odd holds."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.errors import InputError
from relaxgrip.learning.datastore import Dataset, load_dataset
from relaxgrip.learning.training import train_models
from tests.rigs import twin_of


def _split(tiny: Path, icfn_train_rows: int) -> Dataset:
    """The tiny dataset re-split: ``icfn_train_rows`` ICFN train rows, the next 10 val;
    holds 0 and 1 train, 2 val, 3 test."""
    data = load_dataset(tiny)
    icfn = data.icfn.copy()
    icfn["split"] = "test"
    icfn.loc[icfn.index[:icfn_train_rows], "split"] = "train"
    icfn.loc[icfn.index[icfn_train_rows:icfn_train_rows + 10], "split"] = "val"
    sequences = data.sequences.copy()
    sequences["split"] = ["train", "train", "val", "test"]
    return replace(data, icfn=icfn, sequences=sequences)


def test_too_few_icfn_train_rows_is_one_line_not_a_traceback(tiny: Path) -> None:
    """Ten ICFN train rows: the ICFN's fit takes 20 (it had raised a bare ValueError)."""
    with pytest.raises(InputError, match="10 ICFN train rows, the fit needs at least 20"):
        train_models(_split(tiny, 10))


def test_a_hold_whose_force_rose_is_left_out_of_the_rcfn(tiny: Path) -> None:
    """A recorded hold whose force rose has a whole-hold fit with K < 0, and its frames
    no relaxing label: the RCFN (log kappa) leaves them out instead of failing."""
    data = _split(tiny, 20)
    sequences, curves = data.sequences.copy(), data.curves.copy()
    rising = curves["sequence"] == 0
    f0 = float(sequences.loc[sequences["sequence"] == 0, "f0_n"].iloc[0])
    t = curves.loc[rising, "t_s"]
    curves.loc[rising, "force_n"] = f0 * (1.0 + 0.01 * t / t.max())
    sequences.loc[sequences["sequence"] == 0, "kappa"] = -0.01
    trained = train_models(replace(data, sequences=sequences, curves=curves))
    frames = int((data.rcfn_features["sequence"] == 0).sum())
    record = trained.training["rcfn"]
    assert record["rows_left_out"] == frames > 0
    assert record["train_rows"] == int((data.rcfn_features["sequence"] == 1).sum())
    assert np.isfinite(trained.rcfn.predict(data.rcfn_xy("val")[0])).all()


def test_a_dataset_of_another_rigs_twin_builds_and_trains(tiny: Path, lab_tiny: Path) -> None:
    """On the second example rig's twin: contacts along its 125 mm finger, its gripper in the
    manifest, and the models train (how well is bring-up's question, on more data)."""
    ours, lab = json.loads((tiny / "manifest.json").read_text()), json.loads(
        (lab_tiny / "manifest.json").read_text())
    assert lab["gripper"]["digest"] != ours["gripper"]["digest"]
    assert lab["gripper"]["finger_length_m"] == 0.125
    assert lab["gripper"]["marker"] == {"dictionary": "4X4_50", "id": 7}
    assert ours["gripper"]["marker"]["id"] == 0
    data = load_dataset(lab_tiny)
    cfg = twin_of("lab")
    # The repeatability holds at the paper's 80 mm, at its share of this finger.
    assert set(data.sequences["contact_set_m"]) == {cfg.paper_position_m(0.080)}
    assert len(data.sequences) == 4
    assert (data.sequences["k_n"] > 0).all()
    assert data.icfn["force_n"].max() > 1.0
    assert np.isfinite(data.icfn_xy("train")[0]).all()
    trained = train_models(_split(lab_tiny, 20))
    assert np.isfinite(trained.icfn.predict(data.icfn_xy("test")[0])).all()
    assert np.isfinite(trained.rcfn.predict(data.rcfn_xy("test")[0])).all()
