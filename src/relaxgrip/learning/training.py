"""Train the ICFN and the RCFN on a dataset, select them on its validation split, save them."""

from __future__ import annotations

import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from relaxgrip.errors import InputError
from relaxgrip.fileio import json_digest
from relaxgrip.learning.datastore import Dataset
from relaxgrip.learning.icfn import ICFN, select_icfn
from relaxgrip.learning.icfn import MIN_SAMPLES as ICFN_MIN_SAMPLES
from relaxgrip.learning.rcfn import MIN_SAMPLES as RCFN_MIN_SAMPLES
from relaxgrip.learning.rcfn import RCFN, select_rcfn
from relaxgrip.learning.store import ModelBundle, load_models, save_models
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
from relaxgrip.twin import TWIN_VERSION

__all__ = [
    "TrainedModels", "dataset_fingerprint", "default_models_dir", "load_default_models",
    "train_models",
]


@dataclass(frozen=True)
class TrainedModels:
    """Models fitted on a dataset, with how they were chosen.

    Attributes
    ----------
    icfn, rcfn : ICFN, RCFN
        The selected estimators.
    icfn_candidates, rcfn_candidates : list of dict
        Validation scores of every candidate.
    training : dict
        Metadata saved into the model manifest.
    """

    icfn: ICFN
    rcfn: RCFN
    icfn_candidates: list[dict[str, Any]]
    rcfn_candidates: list[dict[str, Any]]
    training: dict[str, Any]

    def save(self, directory: Path) -> Path:
        """Write the models (no pickle) with their manifest."""
        return save_models(
            Path(directory), self.icfn, self.rcfn, icfn_feature_schema=ICFN_SCHEMA,
            rcfn_feature_schema=RCFN_SCHEMA, twin_version=TWIN_VERSION,
            training=self.training,
        )


#: Manifest entries that report on a build rather than define its data.
_NOT_THE_DATA = frozenset({"build", "warnings"})


def dataset_fingerprint(data: Dataset) -> str:
    """Short hash of a dataset's manifest: which data a model was trained on.

    Two builds of one spec by the same twin and schemas have the same
    fingerprint, whatever the build's time, workers or warnings.
    """
    return json_digest({k: v for k, v in data.manifest.items() if k not in _NOT_THE_DATA})


def train_models(data: Dataset, random_state: int = 0) -> TrainedModels:
    """Fit both models on the training split and select them on the validation split.

    The RCFN's training frames whose label has no relaxation (``K <= 0``: a
    hold whose force rose) are left out; the training record counts them.

    Raises
    ------
    InputError
        If a split the training needs is empty, or has fewer rows than its fit
        takes (:data:`relaxgrip.learning.icfn.MIN_SAMPLES` ICFN train rows).
    """
    x_train, y_train = data.icfn_xy("train")
    x_val, y_val = data.icfn_xy("val")
    r_train, k_train = data.rcfn_xy("train")
    r_val, k_val = data.rcfn_xy("val")
    # A frame of a hold whose force rose (a recording's whole-hold fit with K <= 0, where
    # the force rises at that frame too) has no relaxation to learn.
    relaxing = k_train[:, 0] > 0
    r_train, k_train = r_train[relaxing], k_train[relaxing]
    for name, rows, least in (("ICFN train", x_train, ICFN_MIN_SAMPLES), ("ICFN val", x_val, 1),
                              ("RCFN train", r_train, RCFN_MIN_SAMPLES), ("RCFN val", r_val, 1)):
        if len(rows) == 0:
            raise InputError(f"the dataset has no {name} rows: build a larger one")
        if len(rows) < least:
            raise InputError(f"the dataset has {len(rows)} {name} rows, the fit needs at least "
                             f"{least}: build a larger one")
    start = time.perf_counter()
    icfn, icfn_table = select_icfn(x_train, y_train, x_val, y_val, random_state=random_state)
    icfn_s = time.perf_counter() - start
    rcfn, rcfn_table = select_rcfn(r_train, k_train, r_val, k_val)
    rcfn_s = time.perf_counter() - start - icfn_s
    val = icfn.predict(x_val) - y_val
    training = {
        "dataset": {"fingerprint": dataset_fingerprint(data), "seed": data.manifest["spec"]["seed"],
                    "twin_version": data.manifest["twin_version"],
                    "counts": data.manifest["counts"]},
        "icfn": {"train_rows": len(y_train), "val_rows": len(y_val),
                 "val_mae_n": float(np.mean(np.abs(val))),
                 "candidates": icfn_table, "fit_s": icfn_s},
        "rcfn": {"train_rows": len(k_train), "val_rows": len(k_val),
                 "rows_left_out": int((~relaxing).sum()),
                 "candidates": rcfn_table, "fit_s": rcfn_s},
        "random_state": random_state,
    }
    return TrainedModels(icfn, rcfn, icfn_table, rcfn_table, training)


def default_models_dir() -> Path:
    """Where the shipped models live (inside the package)."""
    return Path(str(resources.files("relaxgrip") / "models" / "default"))


def load_default_models() -> ModelBundle:
    """The shipped models, checked against the feature schemas this code computes."""
    return load_models(default_models_dir(), icfn_feature_schema=ICFN_SCHEMA,
                       rcfn_feature_schema=RCFN_SCHEMA)
