"""Train the ICFN and the RCFN on a dataset, select them on its validation split, save them."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from relaxgrip.errors import InputError
from relaxgrip.fileio import json_digest
from relaxgrip.learning.datastore import Dataset
from relaxgrip.learning.history import (
    UNRELAXED_FEATURES,
    UnrelaxedIcfn,
    features_deflection_m,
    retained_shares,
)
from relaxgrip.learning.icfn import ICFN, select_icfn
from relaxgrip.learning.icfn import MIN_SAMPLES as ICFN_MIN_SAMPLES
from relaxgrip.learning.observer import ObserverModel
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
    unrelaxed : UnrelaxedIcfn or None
        The ICFN on unrelaxed forces (:mod:`relaxgrip.learning.history`), when
        branch parameters were given.
    """

    icfn: ICFN
    rcfn: RCFN
    icfn_candidates: list[dict[str, Any]]
    rcfn_candidates: list[dict[str, Any]]
    training: dict[str, Any]
    unrelaxed: UnrelaxedIcfn | None = None

    def save(self, directory: Path) -> Path:
        """Write the models (no pickle) with their manifest."""
        return save_models(
            Path(directory), self.icfn, self.rcfn, icfn_feature_schema=ICFN_SCHEMA,
            rcfn_feature_schema=RCFN_SCHEMA, twin_version=TWIN_VERSION,
            training=self.training, unrelaxed=self.unrelaxed,
        )


#: Rows retaining less of their unrelaxed force than this are not unrelaxed-ICFN labels.
MIN_RETAINED_SHARE = 0.3
#: Members of the unrelaxed ICFN (:class:`relaxgrip.learning.history.UnrelaxedIcfn`).
UNRELAXED_MEMBERS = 5


#: Manifest entries that report on a build rather than define its data.
_NOT_THE_DATA = frozenset({"build", "warnings"})


def dataset_fingerprint(data: Dataset) -> str:
    """Short hash of a dataset's manifest: which data a model was trained on.

    Two builds of one spec by the same twin and schemas have the same
    fingerprint, whatever the build's time, workers or warnings.
    """
    return json_digest({k: v for k, v in data.manifest.items() if k not in _NOT_THE_DATA})


def train_models(data: Dataset, random_state: int = 0,
                 history: ObserverModel | None = None,
                 unrelaxed_features: Sequence[str] = UNRELAXED_FEATURES) -> TrainedModels:
    """Fit both models on the training split and select them on the validation split.

    With ``history`` (branch parameters, normally the shipped observer's), a
    second ICFN is fitted the same way on each sample's force over its
    retained share (:func:`relaxgrip.learning.history.retained_shares`): the
    force the finger would carry had it not relaxed while closing, which
    ``relax`` and ``observer`` read at run time times the share their
    loading history retains.  It reads ``unrelaxed_features`` of the ICFN's
    (by default the pose and each finger's warmest beam:
    :data:`relaxgrip.learning.history.UNRELAXED_FEATURES`).  The first ICFN
    stays the paper's, on every feature, for the baselines.

    The RCFN's training frames whose label has no relaxation (``kappa <= 0``: a
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
    # The RCFN fits log kappa: a frame of a hold whose force rose (a recording's whole-hold
    # fit with K <= 0, where the force rises at that frame too) has no label it can take.
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
    rcfn, rcfn_table = select_rcfn(r_train, k_train, r_val, k_val,
                                   time_column=RCFN_SCHEMA.names.index("hold_time_s"))
    rcfn_s = time.perf_counter() - start - icfn_s
    val = icfn.predict(x_val) - y_val
    unrelaxed, unrelaxed_record = (None, None) if history is None else _fit_unrelaxed(
        data, history, random_state, tuple(unrelaxed_features))
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
    if unrelaxed_record is not None:
        training["icfn_unrelaxed"] = unrelaxed_record
    return TrainedModels(icfn, rcfn, icfn_table, rcfn_table, training, unrelaxed)


def _fit_unrelaxed(data: Dataset, history: ObserverModel, random_state: int,
                   features: tuple[str, ...]) -> tuple[UnrelaxedIcfn, dict[str, Any]]:
    """The ICFN on unrelaxed forces and its training record.

    The hyperparameters are selected like the paper's ICFN's (seed
    ``random_state``); the other members are the selected network refitted with
    the next seeds.
    """
    unknown = [f for f in features if f not in ICFN_SCHEMA.names]
    if unknown or not features:
        raise InputError("the unrelaxed ICFN must read some of the ICFN's features, got "
                         f"{', '.join(unknown) or 'none'}")
    start = time.perf_counter()
    rows = data.icfn
    shares = retained_shares(rows, history)
    x = rows[list(features)].to_numpy(np.float64)
    y = rows["force_n"].to_numpy(np.float64) / shares
    split = rows["split"].to_numpy()
    # Where the finger retains little of its unrelaxed force (unloading after a long
    # hold, in recordings) the label divides by almost nothing: those rows are left out.
    kept = shares >= MIN_RETAINED_SHARE
    train, val = kept & (split == "train"), kept & (split == "val")
    if train.sum() < ICFN_MIN_SAMPLES or not val.any():
        raise InputError(f"{int(train.sum())} ICFN train and {int(val.sum())} val rows retain "
                         f"enough of their unrelaxed force (share >= {MIN_RETAINED_SHARE}); "
                         f"the unrelaxed ICFN needs {ICFN_MIN_SAMPLES} and 1: "
                         "train with --no-unrelaxed")
    first, table = select_icfn(x[train], y[train], x[val], y[val], random_state=random_state)
    members = [first]
    for seed in range(random_state + 1, random_state + UNRELAXED_MEMBERS):
        members.append(ICFN(**{**first.get_params(), "random_state": seed}).fit(
            x[train], y[train]))
    unrelaxed = UnrelaxedIcfn(tuple(members), history, features)
    every = rows[list(ICFN_SCHEMA.names)].to_numpy(np.float64)
    contact = features_deflection_m(every) > 0
    record = {
        "train_rows": int(train.sum()), "val_rows": int(val.sum()), "members": len(members),
        "rows_left_out": int((~kept).sum()),
        "features": list(features),
        "val_mae_n": float(np.mean(np.abs(unrelaxed.predict(every[val]) - y[val]))),
        "member_val_mae_n": [float(np.mean(np.abs(m.predict(x[val]) - y[val])))
                             for m in members],
        "retained_share_percentiles": dict(zip(
            ("p1", "p50", "p99"),
            np.percentile(shares[contact], [1, 50, 99]).tolist() if contact.any()
            else [1.0, 1.0, 1.0], strict=True)),
        "candidates": table, "fit_s": time.perf_counter() - start,
    }
    return unrelaxed, record


def default_models_dir() -> Path:
    """Where the shipped models live (inside the package)."""
    return Path(str(resources.files("relaxgrip") / "models" / "default"))


def load_default_models() -> ModelBundle:
    """The shipped models, checked against the feature schemas this code computes."""
    return load_models(default_models_dir(), icfn_feature_schema=ICFN_SCHEMA,
                       rcfn_feature_schema=RCFN_SCHEMA)
