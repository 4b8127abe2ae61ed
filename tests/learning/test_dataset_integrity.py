"""Damaged times, set points and values no gripper gives are refused on loading; the observer
fits holds without set points and turns whatever else a loadable dataset holds into one-line
errors."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from relaxgrip.errors import InputError
from relaxgrip.learning.datastore import MAX_SET_TEMP_C, load_dataset
from relaxgrip.learning.observer import ObserverModel
from tests.clitools import assert_one_error_line, run_cli, run_main
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
    ("a negative time since the onset",
     edit_table("rcfn_features", lambda t: t.assign(hold_time_s=t["hold_time_s"] - 5.0)),
     "rcfn_features.parquet: column 'hold_time_s' has 12 values below 0 s (e.g. -5, row 0)"),
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
                        hold_time_s=0.0, closure_ratio=-1e300, temp_c=-273.15, rz_rad=6.28)))
    data = load_dataset(copy)
    assert (data.icfn["marker_dx_m"] == 1.0).all()
    assert (data.rcfn_features["closure_ratio"] == -1e300).all()


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


def test_fit_observer_refuses_negative_times_in_one_line(
        tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    damaged = _damaged(tiny, tmp_path,
                       edit_table("rcfn_curves", lambda t: t.assign(t_s=t["t_s"] - 1000.0)))
    code, out, err = run_main(["fit-observer", "--data", damaged, "--out", tmp_path / "obs"],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, "starts at -1000 s, before the hold onset")
    assert not (tmp_path / "obs").exists()


def test_holds_without_set_points_are_grouped_by_measured_temperature(tiny: Path,
                                                                      tmp_path: Path) -> None:
    """A recordings dataset lacks set temperatures (NaN): each hold joins the group of its
    measured temperature, which here groups them as their set points did."""
    known = ObserverModel().fit(load_dataset(tiny))
    unknown = _damaged(tiny, tmp_path,
                       edit_table("rcfn_sequences", lambda t: t.assign(temp_set_c=np.nan)))
    model = ObserverModel().fit(load_dataset(unknown))
    assert model.temps_c_.size == 3  # 40, 50 and 60 °C
    np.testing.assert_allclose(model.temps_c_, known.temps_c_)
    assert np.isfinite(model.band_rel_).all()


NAN = float("nan")


@pytest.mark.parametrize(("set_temps", "temps", "expected"), [
    # One setting whose holds straddle a whole degree is one group (rounding split it).
    ([NAN, NAN, NAN, NAN], [40.59, 40.48, 50.48, 60.46], [40.5, 40.5, 50.5, 60.5]),
    # Holds within a kelvin of the one before run into one setting.
    ([NAN, NAN, NAN], [39.6, 40.4, 41.2], [40.4, 40.4, 40.4]),
    ([NAN, NAN], [40.0, 41.5], [40.0, 41.5]),
    # Near a set temperature, a setting joins its group; far from every one, its own.
    ([40.0, NAN, NAN, 55.0], [40.3, 40.6, 47.2, 55.1], [40.0, 40.0, 47.2, 55.0]),
])
def test_holds_without_set_points_join_the_setting_their_temperatures_share(
        set_temps: list[float], temps: list[float], expected: list[float]) -> None:
    from relaxgrip.learning.observer import _group_keys

    assert _group_keys(set_temps, temps) == pytest.approx(expected)


def test_one_hold_without_a_set_point_fits(tiny: Path, tmp_path: Path) -> None:
    mixed = _damaged(tiny, tmp_path, edit_table("rcfn_sequences",
                                                 set_cell("temp_set_c", np.nan, row=3)))
    model = ObserverModel().fit(load_dataset(mixed))
    assert model.n_sequences_ == 4
    assert np.isfinite(model.temps_c_).all()


OBSERVER_DAMAGE: list[tuple[str, Callable[[Path], None], str]] = [
    ("holds under a second", edit_table("rcfn_curves", lambda t: t[t["t_s"] <= 0.5]),
     "only 0 usable RCFN sequences"),
    ("a hold of years", edit_table("rcfn_curves", lambda t: t.assign(t_s=t["t_s"] * 1e9)),
     "RCFN sequence 0: a hold of 1e+10 s; the observer identifies holds of at most 86400 s"),
    ("an absurd closure ratio",
     edit_table("rcfn_features", lambda t: t.assign(closure_ratio=1e300)),
     "makes a loading of 1"),
    ("forces of the wrong sign",
     edit_table("rcfn_curves", lambda t: t.assign(force_n=-t["force_n"])),
     "no RCFN sequence gives the observer a positive stiffness"),
]


@pytest.mark.parametrize(("corrupt", "expected"), [case[1:] for case in OBSERVER_DAMAGE],
                         ids=[case[0] for case in OBSERVER_DAMAGE])
def test_the_observer_refuses_loadable_nonsense_in_one_line(
        tiny: Path, tmp_path: Path, corrupt: Callable[[Path], None], expected: str) -> None:
    data = load_dataset(_damaged(tiny, tmp_path, corrupt))
    with pytest.raises(InputError) as info:
        ObserverModel().fit(data)
    assert expected in str(info.value)
    assert "\n" not in str(info.value)


def test_fit_observer_takes_fewer_terms_for_short_holds(
        tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from relaxgrip.learning.observer import load_observer

    code, out, err = run_main(["fit-observer", "--data", tiny, "--out", tmp_path / "one",
                               "--terms", "1"], monkeypatch, capsys)
    assert code == 0, err
    assert "observer of 1 branches" in " ".join(out.split())
    assert load_observer(tmp_path / "one").n_terms == 1
    code, out, err = run_main(["fit-observer", "--data", tiny, "--out", tmp_path / "six",
                               "--terms", "6"], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "--terms must be 1-5, got 6")
    assert not (tmp_path / "six").exists()
