"""Damaged times, set points and values no gripper gives are refused on loading, in one line."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from relaxgrip.errors import InputError
from relaxgrip.learning.datastore import MAX_SET_TEMP_C, load_dataset
from tests.clitools import assert_one_error_line, run_cli
from tests.learning.test_datastore import edit_table, set_cell


def _damaged(source: Path, tmp_path: Path, *corruptions: Callable[[Path], None]) -> Path:
    copy = tmp_path / "damaged"
    shutil.copytree(source, copy)
    for corrupt in corruptions:
        corrupt(copy)
    return copy


def _times_reversed(sequence: int) -> Callable[[pd.DataFrame], pd.DataFrame]:
    """One sequence's ``t_s`` in reverse order, every other cell and the row order kept."""
    def change(table: pd.DataFrame) -> pd.DataFrame:
        rows = table["sequence"] == sequence
        table.loc[rows, "t_s"] = table.loc[rows, "t_s"].to_numpy()[::-1]
        return table
    return change


def _one_row_curve(table: pd.DataFrame) -> pd.DataFrame:
    keep = (table["sequence"] != 1) | (table.groupby("sequence").cumcount() == 0)
    return table[keep]


def _interleaved(table: pd.DataFrame) -> pd.DataFrame:
    """Rows of the sequences taken in turn: each sequence's own rows still in time order."""
    order = table.groupby("sequence").cumcount().to_numpy().argsort(kind="stable")
    return table.iloc[order]


DAMAGE: list[tuple[str, Callable[[Path], None], str]] = [
    ("a curve time repeated", edit_table("rcfn_curves", set_cell("t_s", 0.4, row=5)),
     "rcfn_curves.parquet: t_s of sequence 0 repeats 0.4 s, not strictly increasing; "
     "rebuild the dataset"),
    ("every curve time zero", edit_table("rcfn_curves", lambda t: t.assign(t_s=0.0)),
     "rcfn_curves.parquet: t_s of sequence 0 repeats 0 s, not strictly increasing "
     "(3 other sequences too)"),
    ("curve times shifted negative",
     edit_table("rcfn_curves", lambda t: t.assign(t_s=t["t_s"] - 1000.0)),
     "rcfn_curves.parquet: t_s of sequence 0 starts at -1000 s, before the hold onset at 0 s "
     "(3 other sequences too); rebuild the dataset"),
    ("a curve reversed",
     edit_table("rcfn_curves", _times_reversed(2)),
     "rcfn_curves.parquet: t_s of sequence 2 falls from 10 to 9.9 s, not strictly increasing"),
    ("a one-row curve", edit_table("rcfn_curves", _one_row_curve),
     "rcfn_curves.parquet: sequence 1 has only 1 row, needs at least 2"),
    ("feature times shifted negative",
     edit_table("rcfn_features", lambda t: t.assign(t_s=t["t_s"] - 5.0)),
     "rcfn_features.parquet: t_s of sequence 0 starts at -5 s, before the hold onset at 0 s"),
    ("a feature time repeated", edit_table("rcfn_features", set_cell("t_s", 0.0, row=1)),
     "rcfn_features.parquet: t_s of sequence 0 repeats 0 s, not strictly increasing"),
    ("a set temperature of a million degrees",
     edit_table("rcfn_sequences", set_cell("temp_set_c", 1e6)),
     "rcfn_sequences.parquet: column 'temp_set_c' has 1 set temperature at or below absolute "
     "zero or above 200 °C, e.g. 1e+06 °C (sequence 0); rebuild the dataset"),
    ("set temperatures below absolute zero",
     edit_table("rcfn_sequences", lambda t: t.assign(temp_set_c=-300.0)),
     "column 'temp_set_c' has 4 set temperatures at or below absolute zero"),
    ("a marker displacement of 1e300 m", edit_table("icfn", set_cell("marker_dx_m", 1e300, row=3)),
     "icfn.parquet: column 'marker_dx_m' has 1 value outside -1 to 1 m (e.g. 1e+300, row 3), "
     "which no gripper gives: a damaged cell or another unit; rebuild the dataset"),
    ("displacements in millimetres",
     edit_table("icfn", lambda t: t.assign(marker_dz_m=t["marker_dz_m"] * 1000.0)),
     "icfn.parquet: column 'marker_dz_m' has"),
    ("an onset temperature below absolute zero",
     edit_table("rcfn_sequences", set_cell("onset_f1_beam2_c", -300.0, row=2)),
     "rcfn_sequences.parquet: column 'onset_f1_beam2_c' has 1 value outside -273.15 to 1000 "
     "degC (e.g. -300, row 2)"),
    ("a negative temperature spread", edit_table("icfn", set_cell("f0_temp_std_k", -1.0)),
     "icfn.parquet: column 'f0_temp_std_k' has 1 value outside 0 to 1000 K"),
    ("a force of 1e200 N", edit_table("rcfn_curves", set_cell("force_n", 1e200, row=7)),
     "rcfn_curves.parquet: column 'force_n' has 1 value outside -1e+09 to 1e+09 N"),
    ("a rotation rate of 1e6 rad/s", edit_table("rcfn_features", set_cell("vry_rad_s", 1e6)),
     "column 'vry_rad_s' has 1 value outside -1000 to 1000 rad/s"),
]


@pytest.mark.parametrize(("corrupt", "expected"), [case[1:] for case in DAMAGE],
                         ids=[case[0] for case in DAMAGE])
def test_damaged_times_and_set_points_are_refused_in_one_line(
        tiny: Path, tmp_path: Path, corrupt: Callable[[Path], None], expected: str) -> None:
    with pytest.raises(InputError) as info:
        load_dataset(_damaged(tiny, tmp_path, corrupt))
    message = str(info.value)
    assert expected in message
    assert "\n" not in message


def test_sound_times_in_any_row_order_and_edge_set_points_load(tiny: Path,
                                                                tmp_path: Path) -> None:
    """Readers take each sequence's rows in file order: sequences may interleave; NaN (no set
    point) and the bound itself are no damage."""
    copy = _damaged(tiny, tmp_path, edit_table("rcfn_curves", _interleaved),
                    edit_table("rcfn_features", _interleaved),
                    edit_table("rcfn_sequences", lambda t: t.assign(
                        temp_set_c=[np.nan, MAX_SET_TEMP_C, -273.0, 40.0])))
    data = load_dataset(copy)
    assert not data.curves["sequence"].is_monotonic_increasing
    assert len(data.sequences) == 4


def test_values_on_the_bounds_of_what_a_gripper_gives_load(tiny: Path, tmp_path: Path) -> None:
    """The ranges include their bounds, and an unbounded dimensionless feature only needs to
    be finite."""
    copy = _damaged(tiny, tmp_path,
                    edit_table("icfn", lambda t: t.assign(marker_dx_m=1.0, marker_dy_m=-1.0,
                                                          marker_dx2_m2=0.0, f0_temp_std_k=0.0)),
                    edit_table("rcfn_features", lambda t: t.assign(
                        temp_c=-273.15, rz_rad=6.28)))
    data = load_dataset(copy)
    assert (data.icfn["marker_dx_m"] == 1.0).all()
    assert (data.rcfn_features["rz_rad"] == 6.28).all()


def test_evaluate_refuses_a_repeated_curve_time_in_one_line(tiny: Path, tmp_path: Path) -> None:
    damaged = _damaged(tiny, tmp_path, edit_table("rcfn_curves", set_cell("t_s", 0.4, row=5)))
    proc = run_cli("evaluate", "--data", damaged)
    assert_one_error_line(proc.returncode, proc.stdout, proc.stderr,
                          "rcfn_curves.parquet: t_s of sequence 0 repeats 0.4 s")


def test_train_refuses_a_value_no_gripper_gives_before_it_trains(tiny: Path,
                                                                 tmp_path: Path) -> None:
    damaged = _damaged(tiny, tmp_path, edit_table("icfn", set_cell("marker_dx_m", 1e300)))
    proc = run_cli("train", "--data", damaged, "--out", tmp_path / "models")
    assert_one_error_line(proc.returncode, proc.stdout, proc.stderr,
                          "column 'marker_dx_m' has 1 value outside -1 to 1 m")
    assert not (tmp_path / "models").exists()
