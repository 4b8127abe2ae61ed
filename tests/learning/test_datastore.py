"""Loading a dataset checks it: a damaged one is refused in one line, before any work."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from relaxgrip.errors import InputError
from relaxgrip.learning.datastore import TABLES, load_dataset, write_dataset
from relaxgrip.perception.features import ICFN_SCHEMA


def _copy(source: Path, tmp_path: Path) -> Path:
    damaged = tmp_path / "damaged"
    shutil.copytree(source, damaged)
    return damaged


def edit_manifest(change: Callable[[dict[str, Any]], None]) -> Callable[[Path], None]:
    def corrupt(d: Path) -> None:
        manifest = json.loads((d / "manifest.json").read_text())
        change(manifest)
        (d / "manifest.json").write_text(json.dumps(manifest))
    return corrupt


def edit_table(name: str, change: Callable[[pd.DataFrame], pd.DataFrame | None]
               ) -> Callable[[Path], None]:
    def corrupt(d: Path) -> None:
        path = d / f"{name}.parquet"
        table = pd.read_parquet(path)
        changed = change(table)
        (table if changed is None else changed).to_parquet(path, index=False)
    return corrupt


def set_cell(column: str, value: Any, row: int = 0) -> Callable[[pd.DataFrame], None]:
    def change(table: pd.DataFrame) -> None:
        table.loc[row, column] = value
    return change


def replace_by_directory(d: Path) -> None:
    (d / "rcfn_curves.parquet").unlink()
    (d / "rcfn_curves.parquet").mkdir()


def _names_without_last(m: dict[str, Any]) -> None:
    m["icfn_schema"]["names"] = m["icfn_schema"]["names"][:-1]


def _names_swapped(m: dict[str, Any]) -> None:
    names = m["rcfn_schema"]["names"]
    names[0], names[1] = names[1], names[0]


DAMAGE: list[tuple[str, Callable[[Path], None], str]] = [
    ("icfn schema null", edit_manifest(lambda m: m.update(icfn_schema=None)),
     "the manifest's icfn_schema is None, not a feature schema; rebuild the dataset"),
    ("rcfn schema text", edit_manifest(lambda m: m.update(rcfn_schema="x")),
     "the manifest's rcfn_schema is 'x', not a feature schema"),
    ("schema names not a list", edit_manifest(lambda m: m["icfn_schema"].update(names=3)),
     "the manifest's icfn_schema is {"),
    ("a feature name removed", edit_manifest(_names_without_last),
     f"built with ICFN features {ICFN_SCHEMA.version!r} under other names than this relaxgrip "
     f"computes (the dataset lacks {ICFN_SCHEMA.names[-1]!r}); rebuild the dataset"),
    ("feature names swapped", edit_manifest(_names_swapped),
     "under other names than this relaxgrip computes (same names in another order: "
     "feature 0 is 'onset_dx_m' vs 'temp_c')"),
    ("no spec", edit_manifest(lambda m: m.pop("spec")), "no spec with an integer seed"),
    ("icfn without force_n", edit_table("icfn", lambda t: t.drop(columns="force_n")),
     "icfn.parquet: no column 'force_n'; rebuild the dataset"),
    ("icfn without its features", edit_table("icfn", lambda t: t[["episode", "split"]]),
     "icfn.parquet: no columns 't_s', 'force_n', 'marker_dx_m' and "
     f"{len(ICFN_SCHEMA.names) - 1} more"),
    ("sequences without split", edit_table("rcfn_sequences", lambda t: t.drop(columns="split")),
     "rcfn_sequences.parquet: no column 'split'"),
    ("curves without rows", edit_table("rcfn_curves", lambda t: t.iloc[:0]),
     "rcfn_curves.parquet: no rows for 4 of the 4 sequences of rcfn_sequences.parquet (e.g. 0)"),
    ("curves a directory", replace_by_directory,
     "rcfn_curves.parquet: a directory, not a Parquet table"),
    ("features of unknown sequences",
     edit_table("rcfn_features", lambda t: t.assign(sequence=t["sequence"] + 100)),
     "rcfn_features.parquet: rows of 4 sequences that rcfn_sequences.parquet does not have "
     "(e.g. 100)"),
    ("a sequence without features",
     edit_table("rcfn_features", lambda t: t[t["sequence"] != 2]),
     "rcfn_features.parquet: no rows for 1 of the 4 sequences of rcfn_sequences.parquet "
     "(e.g. 2)"),
    ("a sequence twice",
     edit_table("rcfn_sequences", lambda t: t.assign(sequence=[0, 1, 2, 2])),
     "rcfn_sequences.parquet: sequence 2 has 2 rows; ids must be unique"),
    ("NaN curve force", edit_table("rcfn_curves", set_cell("force_n", np.nan)),
     "rcfn_curves.parquet: 1 NaN or infinite value in column 'force_n'; rebuild the dataset"),
    ("inf feature temperature", edit_table("rcfn_features", set_cell("temp_c", np.inf, 3)),
     "rcfn_features.parquet: 1 NaN or infinite value in column 'temp_c'"),
    ("NaN ICFN label", edit_table("icfn", set_cell("force_n", np.nan)),
     "icfn.parquet: 1 NaN or infinite value in column 'force_n'"),
    ("NaN ICFN features", edit_table("icfn", lambda t: t.assign(
        marker_dx_m=np.nan, **{ICFN_SCHEMA.names[-1]: -np.inf})),
     "icfn.parquet: 40 NaN or infinite values in column 'marker_dx_m' (and in 1 other "
     "columns)"),
    ("NaN onset feature", edit_table("rcfn_sequences", set_cell("onset_marker_dx_m", np.nan)),
     "rcfn_sequences.parquet: 1 NaN or infinite value in column 'onset_marker_dx_m'"),
    ("force as text", edit_table("icfn", lambda t: t.assign(force_n=t["force_n"].astype(str))),
     "icfn.parquet: column 'force_n' holds"),
    ("set temperature as text",
     edit_table("rcfn_sequences", lambda t: t.assign(temp_set_c="warm")),
     "rcfn_sequences.parquet: column 'temp_set_c' holds"),
    ("unknown split", edit_table("icfn", set_cell("split", "bogus")),
     "icfn.parquet: 1 row of split 'bogus', not train, val or test; rebuild the dataset"),
    ("negative tau", edit_table("rcfn_sequences", set_cell("tau_s", -1.0)),
     "rcfn_sequences.parquet: column 'tau_s' has 1 values <= 0"),
]


@pytest.mark.parametrize(("corrupt", "expected"), [case[1:] for case in DAMAGE],
                         ids=[case[0] for case in DAMAGE])
def test_a_damaged_dataset_is_refused_in_one_line(
        tiny: Path, tmp_path: Path, corrupt: Callable[[Path], None], expected: str) -> None:
    damaged = _copy(tiny, tmp_path)
    corrupt(damaged)
    before = {p.name: p.stat().st_mtime_ns for p in damaged.iterdir()}
    with pytest.raises(InputError) as info:
        load_dataset(damaged)
    message = str(info.value)
    assert expected in message
    assert "\n" not in message
    assert {p.name: p.stat().st_mtime_ns for p in damaged.iterdir()} == before  # nothing touched


def test_the_intact_copy_loads(tiny: Path, tmp_path: Path) -> None:
    data = load_dataset(_copy(tiny, tmp_path))
    assert len(data.sequences) == 4
    assert set(data.curves["sequence"]) == set(data.sequences["sequence"])


def test_unknown_set_points_are_allowed(tiny: Path, tmp_path: Path) -> None:
    """A dataset from recordings lacks set temperatures, contacts and forces: NaN there is
    no damage (only the columns the estimators read must be finite)."""
    damaged = _copy(tiny, tmp_path)
    edit_table("rcfn_sequences", lambda t: t.assign(temp_set_c=np.nan, contact_set_m=np.nan,
                                                     force_set_n=np.nan))(damaged)
    edit_table("icfn", lambda t: t.assign(truth_temp_c=np.nan, speed_mm_s=np.nan))(damaged)
    data = load_dataset(damaged)
    assert data.sequences["temp_set_c"].isna().all()


def test_checks_are_quick(tiny: Path, tmp_path: Path) -> None:
    """Every load runs them: on a dataset of 800 holds (a million curve rows) they add
    little to reading the tables."""
    import time

    big = _copy(tiny, tmp_path)
    for name in ("rcfn_sequences", "rcfn_features", "rcfn_curves"):
        table = pd.read_parquet(tiny / f"{name}.parquet")
        pd.concat([table.assign(sequence=table["sequence"] + 10 * k) for k in range(200)],
                  ignore_index=True).to_parquet(big / f"{name}.parquet", index=False)
    load_dataset(big)  # warm the caches
    start = time.perf_counter()
    for name in TABLES:
        pd.read_parquet(big / f"{name}.parquet")
    read_s = time.perf_counter() - start
    start = time.perf_counter()
    data = load_dataset(big)
    load_s = time.perf_counter() - start
    assert len(data.sequences) == 800
    assert load_s < 3 * read_s + 0.5


def _rewrite(tiny: Path, out: Path) -> None:
    """The tiny dataset's tables and manifest written again to ``out``."""
    data = load_dataset(tiny)
    tables = {"icfn": data.icfn, "rcfn_sequences": data.sequences,
              "rcfn_features": data.rcfn_features, "rcfn_curves": data.curves}
    write_dataset(out, tables, data.manifest)


def test_a_dataset_directory_gets_the_umask_s_mode(tiny: Path, tmp_path: Path) -> None:
    """A lab's colleagues read its datasets: not the private mode of a temporary directory."""
    import os

    umask = os.umask(0o022)
    try:
        _rewrite(tiny, tmp_path / "shared")
    finally:
        os.umask(umask)
    assert (tmp_path / "shared").stat().st_mode & 0o777 == 0o755


def test_an_interrupt_while_a_dataset_replaces_another_loses_neither(
        tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C between moving the old dataset aside and the new one in: the new one is
    still put in place (there had been none at the path, the old one hidden beside it)."""
    import os
    import signal

    from relaxgrip.interrupts import interrupt

    out = _copy(tiny, tmp_path)
    replace = os.replace
    moves: list[str] = []

    def replace_then_interrupt(src: Any, dst: Any) -> None:
        replace(src, dst)
        moves.append(str(dst))
        if len(moves) == 1:  # the old dataset is aside
            interrupt(signal.SIGINT, None)

    monkeypatch.setattr(os, "replace", replace_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        _rewrite(tiny, out)
    monkeypatch.undo()
    assert len(load_dataset(out).sequences) == 4
