"""Model directories: round trip, integrity checks, schema checks, atomic saves."""

import dataclasses
import hashlib
import io
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sklearn  # type: ignore[import-untyped]
from numpy.typing import NDArray

import relaxgrip
from relaxgrip.errors import InputError
from relaxgrip.learning.icfn import ICFN
from relaxgrip.learning.rcfn import RCFN
from relaxgrip.learning.store import ModelFileError, load_models, save_models
from relaxgrip.perception.features import ICFN_SCHEMA, FeatureSchema
from relaxgrip.twin.config import TWIN_VERSION

RCFN_NAMES = tuple(f"rcfn_feature_{i}" for i in range(7))
RCFN_TEST_SCHEMA = FeatureSchema("relaxgrip-rcfn-features-test", RCFN_NAMES, ("",) * 7)
FINAL_NAMES = {"icfn.npz", "rcfn.npz", "manifest.json"}
Models = tuple[ICFN, RCFN, NDArray[np.float64], NDArray[np.float64]]
TRAINING = {"icfn": {"val_mae_n": np.float64(0.42), "n_train": np.int64(300)}, "seed": 7}


@pytest.fixture(scope="module")
def models():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(300, len(ICFN_SCHEMA)))
    y = X[:, 0] + 0.5 * X[:, 5] ** 2 + rng.normal(0.0, 0.1, 300)
    icfn = ICFN(hidden_layer_sizes=(8,), learning_rate_init=1e-2, max_iter=300).fit(X, y)
    Xr = rng.normal(size=(200, len(RCFN_NAMES)))
    Yr = np.column_stack([0.2 + 0.05 * Xr[:, 0], 3.0 - 0.3 * Xr[:, 1] * Xr[:, 2]])
    rcfn = RCFN().fit(Xr, Yr)
    return icfn, rcfn, X[:20], Xr[:20]


def save(directory: Path, models: Models, **overrides: Any) -> Path:
    icfn, rcfn, _, _ = models
    kwargs = {
        "icfn_feature_schema": ICFN_SCHEMA,
        "rcfn_feature_schema": RCFN_TEST_SCHEMA,
        "twin_version": TWIN_VERSION,
        "training": TRAINING,
        **overrides,
    }
    return save_models(directory, icfn, rcfn, **kwargs)


@pytest.fixture
def saved(tmp_path, models):
    directory = tmp_path / "models"
    save(directory, models)
    return directory


def test_round_trip(saved, models):
    icfn, rcfn, X, Xr = models
    bundle = load_models(saved, icfn_feature_schema=ICFN_SCHEMA,
                         rcfn_feature_schema=RCFN_TEST_SCHEMA)
    np.testing.assert_array_equal(bundle.icfn.predict(X), icfn.predict(X))
    np.testing.assert_array_equal(bundle.rcfn.predict(Xr), rcfn.predict(Xr))
    assert bundle.icfn.predict_one(X[0]) == icfn.predict_one(X[0])
    assert bundle.rcfn.relaxation(Xr[0], 4.0) == rcfn.relaxation(Xr[0], 4.0)
    assert bundle.icfn.get_params() == icfn.get_params()
    assert bundle.rcfn.get_params() == rcfn.get_params()
    assert bundle.icfn_feature_schema == ICFN_SCHEMA
    assert bundle.rcfn_feature_schema == RCFN_TEST_SCHEMA
    assert sorted(p.name for p in saved.iterdir()) == sorted(FINAL_NAMES)


def test_manifest_contents(saved, models):
    manifest = json.loads((saved / "manifest.json").read_text())
    assert (manifest["format"], manifest["format_version"]) == ("relaxgrip-models", 1)
    assert manifest["twin_version"] == TWIN_VERSION
    assert manifest["relaxgrip_version"] == relaxgrip.__version__
    assert manifest["sklearn_version"] == sklearn.__version__
    assert manifest["numpy_version"] == np.__version__
    assert manifest["created_utc"].endswith("+00:00")
    assert manifest["training"] == {"icfn": {"val_mae_n": 0.42, "n_train": 300}, "seed": 7}
    assert manifest["icfn"]["feature_schema"] == ICFN_SCHEMA.to_dict()
    assert manifest["rcfn"]["feature_schema"] == RCFN_TEST_SCHEMA.to_dict()
    assert manifest["icfn"]["params"]["hidden_layer_sizes"] == [8]
    assert manifest["rcfn"]["params"] == models[1].get_params()
    for key in ("icfn", "rcfn"):
        data = (saved / manifest[key]["file"]).read_bytes()
        assert manifest[key]["bytes"] == len(data)
        assert manifest[key]["sha256"] == hashlib.sha256(data).hexdigest()
        with np.load(saved / manifest[key]["file"], allow_pickle=False) as npz:
            assert all(npz[name].dtype == np.float64 for name in npz.files)


def test_saving_again_replaces_the_model(saved, models):
    save(saved, models, training={"run": 2})
    assert load_models(saved).manifest["training"] == {"run": 2}
    assert sorted(p.name for p in saved.iterdir()) == sorted(FINAL_NAMES)


def rewrite_npz(
    directory: Path, name: str, arrays: dict[str, Any] | None = None, data: bytes | None = None
) -> None:
    """Replace an npz file and fix its size and checksum in the manifest (a consistent forgery)."""
    if data is None:
        buffer = io.BytesIO()
        np.savez(buffer, **(arrays or {}))
        data = buffer.getvalue()
    (directory / name).write_bytes(data)
    manifest = json.loads((directory / "manifest.json").read_text())
    key = name.removesuffix(".npz")
    manifest[key]["bytes"] = len(data)
    manifest[key]["sha256"] = hashlib.sha256(data).hexdigest()
    (directory / "manifest.json").write_text(json.dumps(manifest))


def edit_manifest(directory: Path, change: Callable[[dict[str, Any]], object]) -> None:
    manifest = json.loads((directory / "manifest.json").read_text())
    change(manifest)
    (directory / "manifest.json").write_text(json.dumps(manifest))


def truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def flip_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))


def icfn_arrays_without(directory: Path, name: str) -> dict[str, Any]:
    with np.load(directory / "icfn.npz") as npz:
        return {key: npz[key] for key in npz.files if key != name}


def reshaped_rcfn(directory: Path) -> dict[str, Any]:
    with np.load(directory / "rcfn.npz") as npz:
        arrays = {key: npz[key] for key in npz.files}
    arrays["coef"] = arrays["coef"][:-1]
    return arrays


CORRUPTIONS: dict[str, tuple[Callable[[Path], object], str, str]] = {
    "missing manifest": (lambda d: (d / "manifest.json").unlink(), "manifest.json", "missing"),
    "missing icfn": (lambda d: (d / "icfn.npz").unlink(), "icfn.npz", "missing"),
    "foreign json": (
        lambda d: (d / "manifest.json").write_text('{"name": "something else", "version": 1}'),
        "manifest.json",
        "not a relaxgrip model directory",
    ),
    "json list": (
        lambda d: (d / "manifest.json").write_text("[1, 2, 3]"),
        "manifest.json",
        "not a relaxgrip model directory",
    ),
    "binary manifest": (
        lambda d: (d / "manifest.json").write_bytes(np.random.default_rng(5).bytes(300)),
        "manifest.json",
        "not a relaxgrip model directory",
    ),
    "newer format": (
        lambda d: edit_manifest(d, lambda m: m.update(format_version=2)),
        "manifest.json",
        "newer",
    ),
    "section missing": (
        lambda d: edit_manifest(d, lambda m: m.pop("rcfn")),
        "manifest.json",
        "lacks",
    ),
    "truncated npz": (lambda d: truncate(d / "icfn.npz"), "icfn.npz", "truncated or modified"),
    "modified byte": (lambda d: flip_byte(d / "rcfn.npz"), "rcfn.npz", "truncated or modified"),
    "unreadable npz": (
        lambda d: rewrite_npz(d, "icfn.npz", data=b"not a zip file at all"),
        "icfn.npz",
        "unreadable npz",
    ),
    "pickled array": (
        lambda d: rewrite_npz(d, "rcfn.npz", {"coef": np.array([{"a": 1}], dtype=object)}),
        "rcfn.npz",
        "unreadable npz",
    ),
    "array missing": (
        lambda d: rewrite_npz(d, "icfn.npz", icfn_arrays_without(d, "coef_1")),
        "icfn.npz",
        "missing array",
    ),
    "wrong shape": (
        lambda d: rewrite_npz(d, "rcfn.npz", reshaped_rcfn(d)),
        "rcfn.npz",
        "shape",
    ),
    "unknown parameter": (
        lambda d: edit_manifest(d, lambda m: m["icfn"]["params"].update(colour="red")),
        "icfn.npz",
        "colour",
    ),
    "hidden sizes text": (
        lambda d: edit_manifest(d, lambda m: m["icfn"]["params"].update(hidden_layer_sizes="abc")),
        "manifest.json",
        "'icfn.params.hidden_layer_sizes' must be a list of positive integers, got 'abc'",
    ),
    "hidden size zero": (
        lambda d: edit_manifest(d, lambda m: m["icfn"]["params"].update(hidden_layer_sizes=[0])),
        "manifest.json",
        r"'icfn.params.hidden_layer_sizes' must be a list of positive integers, got \[0\]",
    ),
    "rcfn temperature column": (
        lambda d: edit_manifest(d, lambda m: m["rcfn"]["params"].update(temp_column=99)),
        "rcfn.npz",
        "temp_column must be a column of the",
    ),
    "rcfn time column text": (
        lambda d: edit_manifest(d, lambda m: m["rcfn"]["params"].update(time_column="3")),
        "rcfn.npz",
        "time_column must be a column of the",
    ),
    "hidden size float": (
        lambda d: edit_manifest(d, lambda m: m["icfn"]["params"].update(
            hidden_layer_sizes=[8.5])),
        "manifest.json",
        "hidden_layer_sizes' must be a list of positive integers",
    ),
}


@pytest.mark.parametrize("case", list(CORRUPTIONS))
def test_damaged_directories_raise_one_line_errors(saved, case):
    damage, file_name, words = CORRUPTIONS[case]
    damage(saved)
    with pytest.raises(ModelFileError, match=words) as info:
        load_models(saved, icfn_feature_schema=ICFN_SCHEMA, rcfn_feature_schema=RCFN_TEST_SCHEMA)
    message = str(info.value)
    assert file_name in message
    assert "\n" not in message
    assert isinstance(info.value, InputError)


def test_missing_directory(tmp_path):
    with pytest.raises(ModelFileError, match="no such model directory"):
        load_models(tmp_path / "nowhere")


def test_a_file_is_not_a_model_directory(tmp_path):
    (tmp_path / "good.csv").write_text("t,f\n")
    with pytest.raises(ModelFileError,
                       match=r"good.csv: a file, not a directory \(a model directory"):
        load_models(tmp_path / "good.csv")


def test_feature_schema_version_mismatch(saved):
    newer = dataclasses.replace(ICFN_SCHEMA, version="relaxgrip-icfn-features-v99")
    with pytest.raises(ModelFileError, match="trained on features relaxgrip-icfn-features-v1 "
                       "but this code computes relaxgrip-icfn-features-v99"):
        load_models(saved, icfn_feature_schema=newer)


def test_same_schema_version_with_other_names(saved):
    names = ("renamed", *ICFN_SCHEMA.names[1:])
    other = dataclasses.replace(ICFN_SCHEMA, names=names)
    with pytest.raises(ModelFileError, match=r"other names or units.*feature 0"):
        load_models(saved, icfn_feature_schema=other)


def rcfn_schema(names: tuple[str, ...], version: str = RCFN_TEST_SCHEMA.version) -> FeatureSchema:
    return FeatureSchema(version, names, ("",) * len(names))


def test_rcfn_feature_names_mismatch(saved):
    with pytest.raises(ModelFileError, match=r"RCFN trained on features .*7 features vs 6"):
        load_models(saved, rcfn_feature_schema=rcfn_schema(RCFN_NAMES[:-1]))
    with pytest.raises(ModelFileError, match="feature 2 is 'rcfn_feature_2' vs 'x'"):
        load_models(saved, rcfn_feature_schema=rcfn_schema((*RCFN_NAMES[:2], "x",
                                                            *RCFN_NAMES[3:])))


def test_rcfn_feature_schema_version_mismatch(saved):
    # The RCFN's temperature input changed meaning with the same names (v2 -> v3): the
    # version alone must refuse the old models.
    with pytest.raises(ModelFileError, match="RCFN trained on features "
                       "relaxgrip-rcfn-features-test but this code computes x-v99"):
        load_models(saved, rcfn_feature_schema=rcfn_schema(RCFN_NAMES, "x-v99"))


def test_unversioned_rcfn_manifest_asks_for_retraining(saved):
    def to_names(m: dict[str, Any]) -> None:
        m["rcfn"]["feature_names"] = m["rcfn"].pop("feature_schema")["names"]

    edit_manifest(saved, to_names)
    with pytest.raises(ModelFileError, match=r"unversioned features.*retrain"):
        load_models(saved)


def test_save_checks_its_inputs(tmp_path, models):
    with pytest.raises(ValueError, match="schema has"):
        save(tmp_path / "a", models, icfn_feature_schema=dataclasses.replace(
            ICFN_SCHEMA, names=ICFN_SCHEMA.names[:-1], units=ICFN_SCHEMA.units[:-1]))
    with pytest.raises(ValueError, match="RCFN feature schema has"):
        save(tmp_path / "b", models, rcfn_feature_schema=rcfn_schema(RCFN_NAMES[:3]))
    with pytest.raises(ValueError, match="JSON"):
        save(tmp_path / "c", models, training={"mae": float("nan")})
    with pytest.raises(ValueError, match="JSON"):
        save(tmp_path / "d", models, training={"when": object()})
    assert not any((tmp_path / name).exists() for name in "abcd")


def failing_savez(monkeypatch: pytest.MonkeyPatch, fail_on_call: int) -> None:
    real = np.savez
    calls = []

    def savez(*args: Any, **kwargs: Any) -> None:
        calls.append(1)
        if len(calls) == fail_on_call:
            raise RuntimeError("power cut")
        real(*args, **kwargs)

    monkeypatch.setattr(np, "savez", savez)


def failing_replace(monkeypatch: pytest.MonkeyPatch, fail_on_call: int) -> None:
    real = os.replace
    calls = []

    def replace(src: Any, dst: Any) -> None:
        calls.append(1)
        if len(calls) == fail_on_call:
            raise OSError("disk gone")
        real(src, dst)

    monkeypatch.setattr(os, "replace", replace)


def test_interrupted_save_leaves_nothing_behind(tmp_path, models, monkeypatch):
    directory = tmp_path / "fresh"
    failing_savez(monkeypatch, fail_on_call=2)
    with pytest.raises(RuntimeError, match="power cut"):
        save(directory, models)
    assert not directory.exists() or list(directory.iterdir()) == []


def test_interrupted_write_keeps_the_previous_model(saved, models, monkeypatch):
    before = {name: (saved / name).read_bytes() for name in FINAL_NAMES}
    real_fdopen = os.fdopen
    calls = []

    def fdopen(fd, *args, **kwargs):
        calls.append(1)
        if len(calls) == 2:  # the first file is on disk under its temporary name
            os.close(fd)
            raise OSError("no space left on device")
        return real_fdopen(fd, *args, **kwargs)

    monkeypatch.setattr(os, "fdopen", fdopen)
    with pytest.raises(OSError, match="no space"):
        save(saved, models, training={"run": 2})
    assert {p.name for p in saved.iterdir()} == FINAL_NAMES  # no temporaries left
    assert {name: (saved / name).read_bytes() for name in FINAL_NAMES} == before
    assert load_models(saved).manifest["training"]["seed"] == 7


def test_crash_between_renames_is_detected_not_mixed(saved, models, monkeypatch):
    icfn, rcfn, X, Xr = models
    arrays = rcfn.to_arrays()
    arrays["intercept"] += 0.1
    other_rcfn = RCFN.from_arrays(arrays, rcfn.get_params())
    failing_replace(monkeypatch, fail_on_call=3)  # both npz renamed, the old manifest stays
    with pytest.raises(OSError, match="disk gone"):
        save(saved, (icfn, other_rcfn, X, Xr))
    assert {p.name for p in saved.iterdir()} == FINAL_NAMES
    with pytest.raises(ModelFileError, match=r"rcfn\.npz: truncated or modified"):
        load_models(saved)


def test_provenance_names_the_calibration_the_bundle_takes_off(saved):
    """A bundle built without its directory's calibration (``replace(bundle,
    hold_bias=None)``: the estimator takes none off) was said to run with it, from the
    manifest; and one given another calibration, with the directory's."""
    from relaxgrip.learning.hold_bias import HoldBias
    from relaxgrip.learning.store import set_hold_bias

    bias = HoldBias(np.array([5.0]), np.array([40.0]), np.array([100.0]), np.full((1, 1, 1), 0.05))
    set_hold_bias(saved, bias, {"seeds": [7]})
    bundle = load_models(saved)
    calibrated = bundle.provenance()["hold_bias_sha256"]
    assert calibrated is not None
    assert dataclasses.replace(bundle, hold_bias=None).provenance()["hold_bias_sha256"] is None
    other = HoldBias(np.array([5.0]), np.array([40.0]), np.array([100.0]), np.full((1, 1, 1), 0.1))
    assert dataclasses.replace(bundle, hold_bias=other).provenance()["hold_bias_sha256"] \
        not in (None, calibrated)
