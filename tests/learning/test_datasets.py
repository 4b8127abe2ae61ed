"""Datasets from the twin: plans, splits, determinism across workers and backends, storage."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from relaxgrip.control import MAX_TARGET_N
from relaxgrip.errors import InputError
from relaxgrip.learning.build import build_dataset
from relaxgrip.learning.datasets import (
    ICFN_MAX_FORCE_N,
    ICFN_SAMPLES,
    MAX_HOLD_S,
    MAX_ICFN_SAMPLES,
    MAX_RCFN_SEQUENCES,
    REPEAT_TEMPS_C,
    REPEATS_PER_GROUP,
    DatasetSpec,
    plan_icfn,
    plan_rcfn,
)
from relaxgrip.learning.datastore import TABLES, load_dataset
from relaxgrip.learning.training import dataset_fingerprint
from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA

SMALL = DatasetSpec(icfn_samples=60, rcfn_sequences=6, seed=3)


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("data") / "small"
    build_dataset(out, SMALL, jobs=2)
    return out


def test_plans_cover_the_paper_ranges_and_split_by_condition() -> None:
    spec = DatasetSpec()
    episodes = plan_icfn(spec)
    assert sum(e.n_samples for e in episodes) == ICFN_SAMPLES == 10_700
    # Episode maxima reach beyond the controller's largest force target, up to the ceiling.
    maxima = [e.max_force_n for e in episodes]
    assert MAX_TARGET_N < max(maxima) <= ICFN_MAX_FORCE_N
    temps = [e.temp_c for e in episodes]
    assert 25.0 <= min(temps) < 27.0
    assert 58.0 < max(temps) <= 60.0
    sequences = plan_rcfn(spec)
    assert len(sequences) == 810
    assert len({s.contact_m for s in sequences}) == 4
    by_condition: dict[int, set[str]] = {}
    for s in sequences:
        by_condition.setdefault(s.condition, set()).add(s.split)
    assert all(len(splits) == 1 for splits in by_condition.values())
    shares = {k: sum(s.split == k for s in sequences) / 810 for k in ("train", "val", "test")}
    assert shares["train"] == pytest.approx(0.70, abs=0.03)
    assert shares["val"] == pytest.approx(0.15, abs=0.03)
    repeats = [s for s in sequences if s.object_name == "force_ball" and s.contact_m == 0.08
               and s.force_n == 5.0 and s.temp_c in REPEAT_TEMPS_C]
    assert len(repeats) == REPEATS_PER_GROUP * len(REPEAT_TEMPS_C)
    assert {s.split for s in repeats} == {"test"}


def test_tables_readme_and_manifest(small: Path) -> None:
    data = load_dataset(small)
    assert len(data.icfn) >= 55  # a stiff object may skip a force level or two
    assert set(ICFN_SCHEMA.names) <= set(data.icfn.columns)
    assert set(RCFN_SCHEMA.names) <= set(data.rcfn_features.columns)
    assert len(data.sequences) == 6
    curve = data.curves[data.curves["sequence"] == data.sequences["sequence"].iloc[0]]
    assert np.allclose(np.diff(curve["t_s"]), 0.1)  # 10 Hz
    assert curve["t_s"].iloc[-1] == pytest.approx(DatasetSpec().hold_s)
    assert (data.sequences["k_n"] > 0).all()
    assert np.allclose(data.sequences["kappa"], data.sequences["k_n"] / data.sequences["f0_n"])
    readme = (small / "README.md").read_text()
    for name in TABLES:
        for column in pd.read_parquet(small / f"{name}.parquet").columns:
            assert f"`{column}`" in readme
    manifest = json.loads((small / "manifest.json").read_text())
    assert manifest["icfn_schema"]["version"] == ICFN_SCHEMA.version
    assert manifest["noise"]["ir_netd_k"] == 0.05
    x, y = data.icfn_xy("train")
    assert x.shape[1] == len(ICFN_SCHEMA)
    assert np.all(np.isfinite(x))
    assert y.min() == 0.0  # the free-air samples
    assert y.max() <= ICFN_MAX_FORCE_N + 0.5


def test_same_seed_same_dataset_whatever_the_workers(small: Path, tmp_path: Path) -> None:
    serial = tmp_path / "serial"
    build_dataset(serial, SMALL, jobs=1)
    for name in TABLES:
        pd.testing.assert_frame_equal(pd.read_parquet(small / f"{name}.parquet"),
                                      pd.read_parquet(serial / f"{name}.parquet"))


def test_the_fingerprint_names_the_data_not_the_build(small: Path, tmp_path: Path) -> None:
    """A rebuild of one spec has the fingerprint of the first, whatever the build reports;
    another seed has another."""
    first = load_dataset(small)
    again = replace(first, manifest={**first.manifest, "build": {"seconds": 1.0}, "warnings": []})
    assert dataset_fingerprint(again) == dataset_fingerprint(first)
    other = DatasetSpec(icfn_samples=20, rcfn_sequences=0, seed=4)
    build_dataset(tmp_path / "other", other, jobs=1)
    assert dataset_fingerprint(load_dataset(tmp_path / "other")) != dataset_fingerprint(first)


def test_dask_backend_gives_the_same_dataset(small: Path, tmp_path: Path) -> None:
    pytest.importorskip("dask.distributed")
    spec = DatasetSpec(icfn_samples=20, rcfn_sequences=0, seed=3)
    build_dataset(tmp_path / "loky", spec, jobs=2)
    build_dataset(tmp_path / "dask", spec, jobs=2, backend="dask")
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "loky" / "icfn.parquet"),
                                  pd.read_parquet(tmp_path / "dask" / "icfn.parquet"))


def test_bad_inputs_and_damaged_datasets(small: Path, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such dataset directory"):
        load_dataset(tmp_path / "nope")
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine\n")
    with pytest.raises(InputError, match="holds no relaxgrip-dataset output"):
        build_dataset(foreign, SMALL, jobs=1)
    assert (foreign / "notes.txt").read_text() == "mine\n"  # nothing lost
    with pytest.raises(InputError, match=r"no manifest\.json"):
        load_dataset(foreign)
    broken = tmp_path / "broken"
    broken.mkdir()
    for f in small.iterdir():
        (broken / f.name).write_bytes(f.read_bytes())
    data = (broken / "icfn.parquet").read_bytes()
    (broken / "icfn.parquet").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="unreadable Parquet"):
        load_dataset(broken)
    manifest = json.loads((small / "manifest.json").read_text())
    manifest["icfn_schema"]["version"] = "relaxgrip-icfn-features-v0"
    (broken / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(InputError, match="rebuild the dataset"):
        load_dataset(broken)
    with pytest.raises(InputError, match="jobs must be"):
        build_dataset(tmp_path / "x", SMALL, jobs=0)
    with pytest.raises(InputError, match="unknown backend"):
        build_dataset(tmp_path / "x", SMALL, backend="spark")
    with pytest.raises(InputError, match="seed"):
        DatasetSpec(seed=-1)


def test_rcfn_labels_touch_each_hold_where_its_frame_is(small: Path) -> None:
    data = load_dataset(small)
    x, y = data.rcfn_xy("all")
    assert x.shape == (len(data.rcfn_features), len(RCFN_SCHEMA.names))
    rows = data.rcfn_features
    f0 = rows["sequence"].map(data.sequences.set_index("sequence")["f0_n"]).to_numpy()
    t = rows["t_s"].to_numpy()
    touched = f0 * (1.0 - y[:, 0] * -np.expm1(-np.maximum(t, 1.0) / np.exp(y[:, 1])))
    truth = np.array([np.interp(max(ti, 1.0), c["t_s"], c["force_n"]) for ti, c in
                      zip(t, (data.curves[data.curves["sequence"] == s] for s in rows["sequence"]),
                          strict=True)])
    # Late in a hold the force may stop falling: those frames keep the whole-hold fit.
    assert np.quantile(np.abs(touched - truth), 0.9) < 0.002  # N
    assert np.abs(touched - truth).max() < 0.05
    for _, idx in rows.groupby("sequence").indices.items():  # one label per frame, not per hold
        assert np.ptp(y[idx, 1]) > 0.5


def test_a_dataset_without_holds_reads_as_one_with_no_rcfn_rows(small: Path, tmp_path: Path,
                                                                  monkeypatch, capsys) -> None:
    """An ICFN-only build writes its RCFN tables without columns: loading gives them the
    columns they are read by, and train and evaluate say what is missing in one line."""
    import shutil

    from tests.clitools import assert_one_error_line, run_main

    icfn_only = tmp_path / "icfn-only"
    shutil.copytree(small, icfn_only)
    for name in ("rcfn_sequences", "rcfn_features", "rcfn_curves"):
        pd.DataFrame().to_parquet(icfn_only / f"{name}.parquet")
    data = load_dataset(icfn_only)
    x, y = data.rcfn_xy("train")
    assert x.shape == (0, len(RCFN_SCHEMA.names))
    assert y.shape == (0, 2)
    code, out, err = run_main(["train", "--data", icfn_only, "--out", tmp_path / "m"],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, "the dataset has no ")
    code, out, err = run_main(["evaluate", "--data", icfn_only], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "no RCFN sequences in split 'test'")


def test_a_build_too_small_to_train_says_so(small: Path) -> None:
    """Six RCFN sequences are all repeatability holds, kept for test: the manifest warns
    that `relaxgrip train` will find no RCFN train or val rows."""
    manifest = json.loads((small / "manifest.json").read_text())
    assert manifest["counts"]["splits"].get("rcfn_sequences test") == 6
    gaps = [w for w in manifest["warnings"] if w.startswith("no rcfn_sequences")]
    assert len(gaps) == 2
    assert "the first 18 are the repeatability holds" in gaps[0]


@pytest.mark.parametrize(
    ("changes", "expected"),
    [
        ({"hold_s": 1e308}, "hold must last 10 s to 3600 s (and be finite), got 1e+308"),
        ({"hold_s": MAX_HOLD_S + 1}, "hold must last 10 s to 3600 s"),
        ({"hold_s": 5.0}, "hold must last 10 s to 3600 s"),
        ({"icfn_samples": 999_999_999_999}, "at most 107,000 ICFN samples (ten times the "
                                            "default), got 999,999,999,999"),
        ({"rcfn_sequences": MAX_RCFN_SEQUENCES + 1}, "at most 8,100 RCFN sequences"),
        ({"icfn_samples": 2}, "ask for 0 or at least 3 ICFN samples, got 2"),
    ],
)
def test_spec_sizes_are_bounded(changes: dict[str, Any], expected: str) -> None:
    """Sizes a build could never finish (or overflow on) are refused when the spec is made."""
    with pytest.raises(InputError) as info:
        replace(DatasetSpec(), **changes)
    assert expected in str(info.value)


@pytest.mark.parametrize("n", [3, 21, 22, 23, 402, 10_701])
def test_every_sample_count_plans_episodes_that_can_close(n: int) -> None:
    # An episode takes 2 samples before contact: a last one of 1 or 2 samples had no
    # force level to close to (22 samples divided by zero, 21 gave 22).
    sizes = [e.n_samples for e in plan_icfn(DatasetSpec(icfn_samples=n))]
    assert sum(sizes) == n
    assert min(sizes) >= 3


def test_a_last_episode_too_short_to_close_builds_into_the_one_before(tmp_path: Path) -> None:
    spec = DatasetSpec(icfn_samples=22, rcfn_sequences=0, seed=3)
    build_dataset(tmp_path / "d", spec, jobs=1)
    rows = pd.read_parquet(tmp_path / "d" / "icfn.parquet")
    assert rows["episode"].value_counts().to_dict() == {0: 22}


def test_the_largest_spec_plans() -> None:
    spec = DatasetSpec(icfn_samples=MAX_ICFN_SAMPLES, rcfn_sequences=MAX_RCFN_SEQUENCES,
                       hold_s=MAX_HOLD_S)
    assert sum(e.n_samples for e in plan_icfn(spec)) == MAX_ICFN_SAMPLES == 10 * ICFN_SAMPLES
    assert {s.hold_s for s in plan_rcfn(spec)} == {3600.0}


def test_a_missing_backend_is_refused_before_the_build(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from relaxgrip.learning.build import check_backend

    monkeypatch.setitem(sys.modules, "ray", None)  # as if not installed
    progress: list[int] = []
    with pytest.raises(InputError, match=r"--backend ray needs Ray: pip install"):
        build_dataset(tmp_path / "d", SMALL, backend="ray",
                      progress=lambda done, total: progress.append(done))
    assert progress == []
    assert not (tmp_path / "d").exists()
    assert check_backend("loky") == "loky"
    with pytest.raises(InputError, match="unknown backend 'spark'"):
        check_backend("spark")


def test_a_hold_without_rcfn_features_gives_no_sequence(monkeypatch: pytest.MonkeyPatch) -> None:
    """Had no frame of a hold given features, its sequence would have a curve and labels but
    nothing to read them from: it is dropped, as a hold that never reached its force is."""
    from relaxgrip.learning.datasets import run_rcfn_sequence
    from relaxgrip.perception.features import RcfnFeatures

    seq = plan_rcfn(DatasetSpec(icfn_samples=0, rcfn_sequences=1, hold_s=10.0))[0]
    monkeypatch.setattr(RcfnFeatures, "build", lambda self, temp_c: None)
    out = run_rcfn_sequence(seq)
    assert out.dropped == 1
    assert out.sequence == {}
    assert out.curve == {}


def test_a_build_of_no_units_writes_an_empty_dataset(tmp_path: Path) -> None:
    """Workers are no more than the units, but at least one: joblib refuses none."""
    build_dataset(tmp_path / "empty", replace(SMALL, icfn_samples=0, rcfn_sequences=0), jobs=2)
    manifest = json.loads((tmp_path / "empty" / "manifest.json").read_text())
    assert manifest["counts"]["icfn_samples"] == manifest["counts"]["rcfn_sequences"] == 0


def test_some_episodes_close_during_a_change_of_stiffness_mode() -> None:
    """A fifth cool with the heaters off (from 30 °C up), a tenth heat up (where they
    start above 27 °C); the rest of the plan is the steady one's."""
    episodes = plan_icfn(DatasetSpec())
    cooling = [e for e in episodes if e.start_temp_c is not None and e.start_temp_c > e.temp_c]
    heating = [e for e in episodes if e.start_temp_c is not None and e.start_temp_c < e.temp_c]
    assert len(cooling) / len(episodes) == pytest.approx(0.2 * 0.86, abs=0.04)  # from 30 °C up
    assert len(heating) / len(episodes) == pytest.approx(0.1 * 0.59, abs=0.03)
    assert all(5.0 <= e.start_temp_c - e.temp_c <= 20.0 and e.start_temp_c <= 65.0
               for e in cooling if e.start_temp_c is not None)
    assert all(e.start_temp_c is not None and 5.0 <= e.temp_c - e.start_temp_c <= 20.0
               for e in heating)
    assert {e.object_name for e in cooling} >= {"glass", "force_ball"}
    steady = [replace(e, start_temp_c=None) for e in episodes]
    for a, b in zip(steady, plan_icfn(DatasetSpec()), strict=True):
        assert a == replace(b, start_temp_c=None)


def test_a_cooling_finger_closes_warmest_towards_its_tip() -> None:
    """Heaters off from 52 °C: the fingers reach the episode's temperature and go on
    cooling while it closes; the infrared reads the tip warmer than the root, which a
    heated finger never is."""
    from relaxgrip.learning.datasets import IcfnEpisode, run_icfn_episode

    episode = IcfnEpisode(index=0, seed=5, object_name="glass", temp_c=38.0, contact_m=0.08,
                          speed_mm_s=2.5, max_force_n=6.0, n_samples=8, split="train",
                          start_temp_c=52.0)
    cooling = pd.DataFrame(run_icfn_episode(episode).rows)
    steady = pd.DataFrame(run_icfn_episode(replace(episode, start_temp_c=None)).rows)
    assert len(cooling) == len(steady) == 8
    assert 36.0 < cooling["truth_temp_c"].iloc[-1] < cooling["truth_temp_c"].iloc[0] <= 38.0
    assert (cooling["f0_grad_k_per_m"] > 5.0).all()  # measured +14 to +21 K/m
    assert (steady["f0_grad_k_per_m"] < 0.0).all()  # measured -4 K/m
    assert cooling["t_s"].iloc[0] > steady["t_s"].iloc[0] + 60.0  # about 90 s of cooling
