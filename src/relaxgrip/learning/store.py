"""Trained ICFN and RCFN on disk: arrays and a JSON manifest, no pickle.

A model directory holds three files::

    icfn.npz        the ICFN's learned arrays (ICFN.to_arrays)
    rcfn.npz        the RCFN's learned arrays (RCFN.to_arrays)
    manifest.json   format and version, hyperparameters, the feature schemas
                    the models read, each npz file's size and sha256, software
                    versions, twin version, creation time, training record

:func:`save_models` writes every file to a temporary name in the directory
first and renames them into place only when all are written (manifest last),
so an interrupted save leaves the previous model untouched; a crash between
the renames leaves files whose checksums disagree with the manifest, which
:func:`load_models` rejects instead of mixing two models.
:func:`load_models` reports every problem as a one-line :class:`ModelFileError`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import sklearn  # type: ignore[import-untyped]

import relaxgrip
from relaxgrip.errors import InputError
from relaxgrip.fileio import (
    check_input_dir,
    check_output_dir,
    check_writable,
    file_entry,
    json_digest,
    made_directory,
    npz_bytes,
    one_line,
    read_manifest,
    read_npz_entry,
    write_files_atomically,
)
from relaxgrip.learning.history import UnrelaxedIcfn
from relaxgrip.learning.hold_bias import HoldBias
from relaxgrip.learning.icfn import ICFN
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.rcfn import RCFN
from relaxgrip.perception.features import FeatureSchema

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MANIFEST_NAME",
    "ModelBundle",
    "ModelFileError",
    "load_models",
    "model_checksums",
    "save_models",
    "set_hold_bias",
]

#: Written as the manifest's ``format``; a manifest without it is not ours.
FORMAT_NAME = "relaxgrip-models"
#: Newest layout this code reads and the one it writes.
FORMAT_VERSION = 1
#: File names inside a model directory.
MANIFEST_NAME = "manifest.json"
ICFN_FILE = "icfn.npz"
RCFN_FILE = "rcfn.npz"
UNRELAXED_FILE = "icfn_unrelaxed.npz"
HISTORY_FILE = "history.npz"


class ModelFileError(InputError):
    """A model directory that cannot be loaded; the message names the file and the problem."""


@dataclass(frozen=True)
class ModelBundle:
    """The two estimators of a model directory and its manifest.

    Attributes
    ----------
    icfn : ICFN
        Fitted instantaneous force model.
    rcfn : RCFN
        Fitted relaxation model.
    manifest : dict
        The parsed ``manifest.json``.
    unrelaxed : UnrelaxedIcfn or None
        The ICFN ensemble on unrelaxed forces and the branch parameters of its labels
        (:mod:`relaxgrip.learning.history`); None in directories without them,
        where every estimator reads the paper's ICFN.
    hold_bias : HoldBias or None
        ``relax``'s closed-loop error as ``relaxgrip calibrate-hold`` measured
        it with these models (:mod:`relaxgrip.learning.hold_bias`); None in
        directories not calibrated, where ``relax`` is the paper's Eq. 10.
    directory : Path or None
        Where they were loaded from (absolute); None for models built in memory.
    """

    icfn: ICFN
    rcfn: RCFN
    manifest: dict[str, Any]
    unrelaxed: UnrelaxedIcfn | None = None
    hold_bias: HoldBias | None = None
    directory: Path | None = None

    def provenance(self) -> dict[str, Any]:
        """What a recording says of these models: where they were loaded from, the sha256
        of each model file, and a digest of the calibration taken off the estimate (None
        when there is none: :attr:`hold_bias`, not the manifest's, which a bundle built
        without it still holds)."""
        bias = self.hold_bias
        return {"directory": None if self.directory is None else str(self.directory),
                "sha256": model_checksums(self.manifest),
                "hold_bias_sha256": None if bias is None else json_digest(bias.to_dict())}

    @property
    def icfn_feature_schema(self) -> FeatureSchema:
        """The feature schema the ICFN was trained on."""
        schema = self.manifest["icfn"]["feature_schema"]
        return FeatureSchema(schema["version"], tuple(schema["names"]), tuple(schema["units"]))

    @property
    def rcfn_feature_schema(self) -> FeatureSchema:
        """The feature schema the RCFN was trained on."""
        schema = self.manifest["rcfn"]["feature_schema"]
        return FeatureSchema(schema["version"], tuple(schema["names"]), tuple(schema["units"]))


def _json_default(value: object) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def _manifest_bytes(manifest: Mapping[str, Any], record: str) -> bytes:
    """The manifest as ``manifest.json`` holds it; ValueError naming ``record`` if it cannot be."""
    try:
        text = json.dumps(manifest, indent=2, allow_nan=False, default=_json_default)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{record} record is not JSON-serialisable: {exc}") from exc
    return (text + "\n").encode()


def check_models_out(directory: Path) -> Path:
    """Check that models can be written at ``directory`` (before training them).

    Raises
    ------
    InputError
        A file there, a directory of something else (a dataset), one of
        earlier models with files that are not theirs, or not writable.
    """
    own = (ICFN_FILE, RCFN_FILE, UNRELAXED_FILE, HISTORY_FILE, MANIFEST_NAME)
    return check_output_dir(Path(directory), FORMAT_NAME, own, InputError)


def save_models(
    directory: Path,
    icfn: ICFN,
    rcfn: RCFN,
    *,
    icfn_feature_schema: FeatureSchema,
    rcfn_feature_schema: FeatureSchema,
    twin_version: str,
    training: Mapping[str, Any],
    unrelaxed: UnrelaxedIcfn | None = None,
) -> Path:
    """Save both fitted estimators and their manifest to ``directory``.

    Parameters
    ----------
    directory : Path
        Model directory; created if missing.  Existing model files in it are
        replaced atomically, as a whole.
    icfn, rcfn : ICFN, RCFN
        Fitted estimators.
    icfn_feature_schema : FeatureSchema
        The schema of the ICFN's features (its length must match the ICFN).
    rcfn_feature_schema : FeatureSchema
        The schema of the RCFN's features (its length must match the RCFN).
    twin_version : str
        Version of the twin that generated the training data
        (:data:`relaxgrip.twin.config.TWIN_VERSION`).
    training : mapping
        JSON-serialisable record of the training: metrics, dataset sizes and
        seeds, selection tables (NumPy scalars and arrays are converted; NaN
        and infinity are not allowed).
    unrelaxed : UnrelaxedIcfn, optional
        The ICFN on unrelaxed forces (reading the ICFN's feature vector, all of
        it or the features it names) and its branch parameters, saved beside
        them.

    Returns
    -------
    Path
        The manifest's path.

    Raises
    ------
    sklearn.exceptions.NotFittedError
        An estimator is not fitted.
    ValueError
        Feature counts that do not match the estimators, or a ``training``
        record that is not JSON-serialisable.
    """
    directory = check_models_out(directory)
    icfn_arrays = icfn.to_arrays()
    rcfn_arrays = rcfn.to_arrays()
    if len(icfn_feature_schema) != icfn.n_features_in_:
        raise ValueError(
            f"the ICFN feature schema has {len(icfn_feature_schema)} entries "
            f"but the ICFN was fitted on {icfn.n_features_in_} features"
        )
    if len(rcfn_feature_schema) != rcfn.n_features_in_:
        raise ValueError(
            f"the RCFN feature schema has {len(rcfn_feature_schema)} entries "
            f"but the RCFN was fitted on {rcfn.n_features_in_} features"
        )
    icfn_data = npz_bytes(icfn_arrays)
    rcfn_data = npz_bytes(rcfn_arrays)
    extra: list[tuple[str, bytes]] = []
    sections: dict[str, Any] = {}
    if unrelaxed is not None:
        missing = [f for f in unrelaxed.features if f not in icfn_feature_schema.names]
        if missing:
            raise ValueError(f"the unrelaxed ICFN reads features the ICFN schema does not "
                             f"have: {', '.join(missing)}")
        unrelaxed_data = npz_bytes({f"member{i}/{name}": value
                                    for i, member in enumerate(unrelaxed.members)
                                    for name, value in member.to_arrays().items()})
        history_data = npz_bytes(unrelaxed.model.to_arrays())
        sections = {
            "icfn_unrelaxed": {"estimator": "ICFN ensemble", "params": {
                "members": [member.get_params() for member in unrelaxed.members]},
                               "feature_schema": icfn_feature_schema.to_dict(),
                               "features": list(unrelaxed.features),
                               **file_entry(UNRELAXED_FILE, unrelaxed_data)},
            "history": {"estimator": "ObserverModel", "params": unrelaxed.model.get_params(),
                        **file_entry(HISTORY_FILE, history_data)},
        }
        extra = [(UNRELAXED_FILE, unrelaxed_data), (HISTORY_FILE, history_data)]
    manifest = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "relaxgrip_version": relaxgrip.__version__,
        "numpy_version": np.__version__,
        "sklearn_version": sklearn.__version__,
        "twin_version": twin_version,
        "icfn": {
            "estimator": "ICFN",
            "params": icfn.get_params(),
            "feature_schema": icfn_feature_schema.to_dict(),
            **file_entry(ICFN_FILE, icfn_data),
        },
        "rcfn": {
            "estimator": "RCFN",
            "params": rcfn.get_params(),
            "feature_schema": rcfn_feature_schema.to_dict(),
            **file_entry(RCFN_FILE, rcfn_data),
        },
        **sections,
        "training": dict(training),
    }
    text = _manifest_bytes(manifest, "training")
    with made_directory(directory):
        write_files_atomically(
            directory,
            [(ICFN_FILE, icfn_data), (RCFN_FILE, rcfn_data), *extra, (MANIFEST_NAME, text)],
        )
    return directory / MANIFEST_NAME


def _read_manifest(path: Path) -> dict[str, Any]:
    manifest = read_manifest(path, FORMAT_NAME, FORMAT_VERSION, ModelFileError,
                             "a relaxgrip model directory")
    for key in ("icfn", "rcfn"):
        section = manifest.get(key)
        if not isinstance(section, dict):
            raise ModelFileError(f"{path}: manifest lacks the {key!r} section")
        if key == "rcfn" and "feature_schema" not in section and "feature_names" in section:
            raise ModelFileError(f"{path}: RCFN trained on unversioned features (before "
                                 "relaxgrip-rcfn-features-v3); retrain with relaxgrip train")
        for field in ("params", "feature_schema", "file", "bytes", "sha256"):
            if field not in section:
                raise ModelFileError(f"{path}: manifest lacks '{key}.{field}'")
        if not isinstance(section["params"], dict):
            raise ModelFileError(f"{path}: manifest '{key}.params' is not an object")
        schema = section["feature_schema"]
        if not (
            isinstance(schema, dict)
            and isinstance(schema.get("version"), str)
            and isinstance(schema.get("names"), list)
            and isinstance(schema.get("units"), list)
            and len(schema["names"]) == len(schema["units"])
        ):
            raise ModelFileError(f"{path}: manifest '{key}.feature_schema' is malformed")
    if ("icfn_unrelaxed" in manifest) != ("history" in manifest):
        raise ModelFileError(f"{path}: manifest has one of 'icfn_unrelaxed' and 'history' "
                             "but not the other")
    for key in ("icfn_unrelaxed", "history"):
        section = manifest.get(key)
        if section is None:
            continue
        if not (isinstance(section, dict) and isinstance(section.get("params"), dict)):
            raise ModelFileError(f"{path}: manifest '{key}' lacks its params")
        for field in ("file", "bytes", "sha256"):
            if field not in section:
                raise ModelFileError(f"{path}: manifest lacks '{key}.{field}'")
    if "icfn_unrelaxed" in manifest and (
            manifest["icfn_unrelaxed"].get("feature_schema") != manifest["icfn"]["feature_schema"]):
        raise ModelFileError(f"{path}: the unrelaxed ICFN's features differ from the ICFN's")
    return manifest


def _check_hidden_layer_sizes(path: Path, params: Mapping[str, Any], where: str) -> None:
    """An ICFN's ``hidden_layer_sizes`` (if given) must be a list of positive integers.

    Checked here, not left to the estimator, so that the error names the manifest
    and the field rather than the array file read next.
    """
    sizes = params.get("hidden_layer_sizes", [])
    if not (isinstance(sizes, list) and all(
            isinstance(h, int) and not isinstance(h, bool) and h >= 1 for h in sizes)):
        raise ModelFileError(f"{path}: manifest '{where}.hidden_layer_sizes' must be a list "
                             f"of positive integers, got {sizes!r}")


def _first_difference(saved: Sequence[str], expected: Sequence[str]) -> str:
    if len(saved) != len(expected):
        return f"{len(saved)} features vs {len(expected)}"
    for i, (a, b) in enumerate(zip(saved, expected, strict=True)):
        if a != b:
            return f"feature {i} is {a!r} vs {b!r}"
    return "same names"


def _check_features(path: Path, manifest: Mapping[str, Any], key: str,
                    expected: FeatureSchema | None) -> None:
    """The schema a model (``icfn`` or ``rcfn``) was trained on must be the one computed now."""
    if expected is None:
        return
    saved = manifest[key]["feature_schema"]
    model = key.upper()
    if saved["version"] != expected.version:
        raise ModelFileError(f"{path}: {model} trained on features {saved['version']} "
                             f"but this code computes {expected.version}")
    if saved != expected.to_dict():
        raise ModelFileError(
            f"{path}: {model} trained on features {saved['version']} with other names or units "
            f"than this code computes under the same version "
            f"({_first_difference(saved['names'], expected.names)})"
        )


def load_models(
    directory: Path,
    *,
    icfn_feature_schema: FeatureSchema | None = None,
    rcfn_feature_schema: FeatureSchema | None = None,
) -> ModelBundle:
    """Load a model directory written by :func:`save_models`, checking everything.

    Parameters
    ----------
    directory : Path
        The model directory.
    icfn_feature_schema : FeatureSchema, optional
        The schema this code computes ICFN features with (normally
        :data:`relaxgrip.perception.features.ICFN_SCHEMA`); the saved one must
        match.  ``None`` skips the check.
    rcfn_feature_schema : FeatureSchema, optional
        The schema this code computes RCFN features with (normally
        :data:`relaxgrip.perception.features.RCFN_SCHEMA`); the saved one must
        match.  ``None`` skips the check.

    Returns
    -------
    ModelBundle
        Both estimators, fitted, and the manifest.

    Raises
    ------
    ModelFileError
        A missing directory or file, a manifest that is not ours or too new,
        a file whose size or sha256 differs from the manifest, an unreadable
        npz, arrays missing or misshapen, or features other than expected.
    """
    directory = Path(directory)
    check_input_dir(directory, "model directory", ModelFileError)
    manifest_path = directory / MANIFEST_NAME
    manifest = _read_manifest(manifest_path)
    _check_features(manifest_path, manifest, "icfn", icfn_feature_schema)
    _check_features(manifest_path, manifest, "rcfn", rcfn_feature_schema)
    _check_hidden_layer_sizes(manifest_path, manifest["icfn"]["params"], "icfn.params")

    icfn_path, icfn_arrays = read_npz_entry(directory, manifest["icfn"], ModelFileError)
    try:
        icfn = ICFN.from_arrays(icfn_arrays, manifest["icfn"]["params"])
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f"{icfn_path}: {one_line(exc)}") from exc
    rcfn_path, rcfn_arrays = read_npz_entry(directory, manifest["rcfn"], ModelFileError)
    try:
        rcfn = RCFN.from_arrays(rcfn_arrays, manifest["rcfn"]["params"])
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f"{rcfn_path}: {one_line(exc)}") from exc

    n_icfn = len(manifest["icfn"]["feature_schema"]["names"])
    if icfn.n_features_in_ != n_icfn:
        raise ModelFileError(
            f"{icfn_path}: array shape wrong: {icfn.n_features_in_} features, "
            f"the manifest's schema has {n_icfn}"
        )
    n_rcfn = len(manifest["rcfn"]["feature_schema"]["names"])
    if rcfn.n_features_in_ != n_rcfn:
        raise ModelFileError(
            f"{rcfn_path}: array shape wrong: {rcfn.n_features_in_} features, "
            f"the manifest names {n_rcfn}"
        )
    return ModelBundle(icfn=icfn, rcfn=rcfn, manifest=manifest,
                       unrelaxed=_load_unrelaxed(directory, manifest),
                       hold_bias=_load_hold_bias(manifest_path, manifest),
                       directory=directory.resolve())


#: The manifest section ``relaxgrip calibrate-hold`` writes.
HOLD_BIAS_KEY = "hold_bias"


def _load_hold_bias(path: Path, manifest: Mapping[str, Any]) -> HoldBias | None:
    """``relax``'s calibrated closed-loop error, when the manifest has one."""
    section = manifest.get(HOLD_BIAS_KEY)
    if section is None:
        return None
    if not (isinstance(section, dict) and isinstance(section.get("relax"), dict)):
        raise ModelFileError(f"{path}: manifest '{HOLD_BIAS_KEY}' lacks its 'relax' grid")
    try:
        return HoldBias.from_dict(section["relax"])
    except InputError as exc:
        raise ModelFileError(f"{path}: {exc}") from None


#: The manifest sections whose files a calibration belongs to.
_MODEL_SECTIONS = ("icfn", "rcfn", "icfn_unrelaxed", "history")


def model_checksums(manifest: Mapping[str, Any]) -> dict[str, str]:
    """The sha256 of each model file a manifest names, by section."""
    return {key: str(manifest[key]["sha256"]) for key in _MODEL_SECTIONS
            if isinstance(manifest.get(key), dict) and "sha256" in manifest[key]}


def set_hold_bias(directory: Path, bias: HoldBias, record: Mapping[str, Any],
                  measured_on: Mapping[str, Any] | None = None) -> Path:
    """Store ``relax``'s calibrated closed-loop error in a model directory, atomically.

    Only the manifest is rewritten: the model files, their checksums and the
    training record stay.  ``record`` (how the calibration was measured) is
    kept beside the grid, with the checksums of the models it was measured
    on.  Training new models writes a manifest without it.

    Parameters
    ----------
    measured_on : mapping, optional
        The manifest of the models the holds ran with
        (:attr:`ModelBundle.manifest`); if the directory's models are not
        those any more (trained anew while the holds ran), nothing is written.

    Returns
    -------
    Path
        The manifest's path.

    Raises
    ------
    ModelFileError
        The directory is not a loadable model directory.
    InputError
        It cannot be written.
    """
    directory = Path(directory)
    manifest = load_models(directory).manifest  # every file checked before it is rewritten
    path = directory / MANIFEST_NAME
    checksums = model_checksums(manifest)
    if measured_on is not None and model_checksums(measured_on) != checksums:
        raise InputError(f"{directory}: its models changed while the calibration ran; "
                         "nothing written")
    check_writable(path, InputError)
    manifest[HOLD_BIAS_KEY] = {"relax": bias.to_dict(),
                               "record": {**record, "model_sha256": checksums}}
    write_files_atomically(directory, [(MANIFEST_NAME, _manifest_bytes(manifest, "calibration"))])
    return path


def _load_unrelaxed(directory: Path, manifest: Mapping[str, Any]) -> UnrelaxedIcfn | None:
    """The unrelaxed ICFN and its branch parameters, when the manifest names them.

    It reads the ICFN features its section names under ``features``; a
    directory saved before the section named them read all of them.
    """
    if "icfn_unrelaxed" not in manifest:
        return None
    schema = manifest["icfn"]["feature_schema"]["names"]
    features = manifest["icfn_unrelaxed"].get("features", schema)
    if not (isinstance(features, list) and features
            and all(isinstance(f, str) for f in features)):
        raise ModelFileError(f"{directory / MANIFEST_NAME}: manifest 'icfn_unrelaxed.features' "
                             "is not a list of feature names")
    n_features = len(features)
    path, arrays = read_npz_entry(directory, manifest["icfn_unrelaxed"], ModelFileError)
    params = manifest["icfn_unrelaxed"]["params"].get("members")
    if not (isinstance(params, list) and params and all(isinstance(p, dict) for p in params)):
        raise ModelFileError(f"{path}: manifest 'icfn_unrelaxed.params.members' is not a "
                             "list of parameter objects")
    unclaimed = sorted({k.split("/", 1)[0] for k in arrays}
                       - {f"member{i}" for i in range(len(params))})
    if unclaimed:  # a member the manifest lost would be dropped from the ensemble unseen
        raise ModelFileError(f"{path}: {len(params)} member(s) in the manifest, but the file "
                             f"also holds {', '.join(unclaimed)}")
    members = []
    for i, member_params in enumerate(params):
        prefix = f"member{i}/"
        member_arrays = {k.removeprefix(prefix): v for k, v in arrays.items()
                         if k.startswith(prefix)}
        _check_hidden_layer_sizes(directory / MANIFEST_NAME, member_params,
                                  f"icfn_unrelaxed.params.members[{i}]")
        try:
            member = ICFN.from_arrays(member_arrays, member_params)
        except (TypeError, ValueError) as exc:
            raise ModelFileError(f"{path}: member {i}: {one_line(exc)}") from exc
        if member.n_features_in_ != n_features:
            raise ModelFileError(f"{path}: array shape wrong: member {i} reads "
                                 f"{member.n_features_in_} features, the manifest names "
                                 f"{n_features}")
        members.append(member)
    path, arrays = read_npz_entry(directory, manifest["history"], ModelFileError)
    try:
        model = ObserverModel.from_arrays(arrays, manifest["history"]["params"])
    except (TypeError, ValueError) as exc:
        raise ModelFileError(f"{path}: {one_line(exc)}") from exc
    try:
        return UnrelaxedIcfn(tuple(members), model, tuple(features))
    except ValueError as exc:
        raise ModelFileError(f"{directory / MANIFEST_NAME}: {one_line(exc)}") from exc
