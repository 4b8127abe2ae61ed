"""``relaxgrip dataset build``, ``train``, ``evaluate`` end to end on a small dataset."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest

from relaxgrip.learning.observer import load_observer
from tests.clitools import assert_one_error_line, run_cli, run_main


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("cli")
    data, models = root / "data", root / "models"
    proc = run_cli("dataset", "build", "--out", data, "--icfn-samples", "300",
                   "--rcfn-sequences", "30", "--seed", "5", "--jobs", "2", "--json")
    assert proc.returncode == 0, proc.stderr
    manifest = json.loads(proc.stdout)
    assert manifest["counts"]["icfn_samples"] == 300
    assert manifest["counts"]["rcfn_sequences"] == 30
    proc = run_cli("train", "--data", data, "--out", models, "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["icfn"]["train_rows"] > 100
    # Beside the paper's ICFN, the unrelaxed one on the shipped observer's branches.
    assert summary["icfn_unrelaxed"]["members"] == 5
    assert 0.5 < summary["icfn_unrelaxed"]["retained_share_percentiles"]["p50"] <= 1.0
    assert (models / "icfn_unrelaxed.npz").is_file()
    return data, models


def test_fit_observer_reads_the_onset_with_the_given_models_icfn(
        trained: tuple[Path, Path], tmp_path: Path) -> None:
    # A lab's observer: its band's onset error is its own ICFN's, not the twin's.
    data, models = trained
    bands = {}
    options: dict[str, list[str | Path]] = {"shipped": [], "own": ["--models", models]}
    for name, extra in options.items():
        proc = run_cli("fit-observer", "--data", data, "--out", tmp_path / name, *extra)
        assert proc.returncode == 0, proc.stderr
        record = json.loads((tmp_path / name / "manifest.json").read_text())["training"]
        assert record["onset_icfn"] == ("shipped" if name == "shipped" else str(models))
        bands[name] = load_observer(tmp_path / name).band_rel(0.0, 40.0)
    # The tiny models' ICFN misses the onset by more than the shipped one does.
    assert bands["own"] != bands["shipped"]


def test_train_without_the_unrelaxed_icfn(trained: tuple[Path, Path], tmp_path: Path) -> None:
    proc = run_cli("train", "--data", trained[0], "--out", tmp_path / "m", "--no-unrelaxed",
                   "--json")
    assert proc.returncode == 0, proc.stderr
    assert "icfn_unrelaxed" not in json.loads(proc.stdout)
    assert not (tmp_path / "m" / "icfn_unrelaxed.npz").exists()


def test_evaluate_json_has_the_paper_metrics(trained: tuple[Path, Path], tmp_path: Path) -> None:
    data, models = trained
    proc = run_cli("evaluate", "--data", data, "--models", models, "--json", "--plot", tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert set(out["icfn"]) >= {"mae_n", "rmse_n", "r2", "median_ae_n"}
    assert set(out["icfn"]["median_ae_n"]) == {"0-1", "1-2", "2-5", "5-10"}
    assert set(out["rcfn"]) >= {"nrmse_mean", "nrmse_median", "auc_rel_mean", "auc_rel_median",
                                "corr_mean"}
    assert set(out["repeatability"]) == {"40", "50", "60"}
    # The force relax reads: the unrelaxed ensemble times each sample's retained share.
    history = out["icfn_history"]
    assert history["samples"] == out["icfn"]["samples"]
    assert set(history) == set(out["icfn"])
    assert 0.0 < history["mae_n"] < float("inf")  # 200 training rows: accuracy is not the point
    for group in out["repeatability"].values():
        assert set(group) >= {"nrmse_mean", "nrmse_std", "auc_rel_mean", "corr_mean",
                              "gt_end_std_n", "gt_std_100s_n"}
    assert (tmp_path / "accuracy.png").read_bytes()[:4] == b"\x89PNG"


def test_evaluate_table(
    trained: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    data, models = trained
    code, out, _ = run_main(["evaluate", "--data", data, "--models", models], monkeypatch, capsys)
    assert code == 0
    assert "ICFN MAE" in out
    assert "loading history" in out
    assert "repeatability 50 °C" in out


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["dataset", "build", "--out", "{tmp}/d", "--jobs", "0"], "--jobs must be >= 1"),
        # joblib's pool had ended in a traceback on a count past a C int.
        (["dataset", "build", "--out", "{tmp}/d", "--jobs", "99999999999999999999"],
         "--jobs must be at most 256 worker processes"),
        (["dataset", "build", "--out", "{tmp}/d", "--backend", "spark"],
         "--backend must be one of"),
        (["dataset", "build", "--out", "{tmp}/d", "--seed", "-2"], "seed must be >= 0"),
        (["dataset", "build", "--out", "{tmp}/d", "--hold-s", "inf"], "(and be finite)"),
        (["dataset", "build", "--out", "{tmp}"], "holds no relaxgrip-dataset output"),
        (["dataset", "build", "--out", "/proc/ds"], "cannot write in /proc"),
        (["train", "--data", "{data}", "--out", "{data}"], "holds no relaxgrip-models output"),
        (["train", "--data", "{data}", "--out", "{tmp}/m", "--seed", "-1"],
         "--seed must be in 0 .. 2**31 - 1"),
        (["fit-observer", "--data", "{data}", "--out", "{data}"],
         "holds no relaxgrip-observer output"),
        (["fit-observer", "--data", "{data}", "--out", "{tmp}/o", "--models", "{tmp}"],
         "not a relaxgrip model directory"),
        (["reproduce", "--out", "{tmp}/manifest.json"], "exists and is not a directory"),
        (["reproduce", "--out", "/proc/rep"], "cannot write in /proc"),
        (["train", "--data", "{tmp}/none", "--out", "{tmp}/m"], "no such dataset directory"),
        (["train", "--data", "{data}", "--out", "{tmp}/m", "--observer", "{tmp}/none"],
         "not an observer model directory"),
        (["train", "--data", "{data}", "--out", "{tmp}/m", "--observer", "{tmp}",
          "--no-unrelaxed"], "drop --no-unrelaxed"),
        (["evaluate", "--data", "{tmp}/none"], "no such dataset directory"),
        (["evaluate", "--data", "{data}", "--models", "{tmp}"], "not a relaxgrip model directory"),
        (["evaluate", "--data", "{data}", "--split", "holdout"], "--split must be"),
        (["evaluate", "--data", "{data}", "--plot", "{tmp}/nowhere"], "no such directory"),
        (["evaluate", "--data", "{data}", "--plot", "{tmp}/manifest.json"],
         "not a directory (it names the folder for accuracy.png)"),
    ],
)
def test_bad_input(
    trained: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str], args: list[str], expected: str,
) -> None:
    (tmp_path / "manifest.json").write_text('{"hello": 1}')
    argv: list[str | Path] = [
        a.replace("{tmp}", str(tmp_path)).replace("{data}", str(trained[0])) for a in args
    ]
    code, out, err = run_main(argv, monkeypatch, capsys)
    assert_one_error_line(code, out, err, expected)


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--hold-s", "1e308"], "hold must last 10 s to 3600 s (and be finite), got 1e+308"),
        (["--hold-s", "3601"], "hold must last 10 s to 3600 s"),
        (["--icfn-samples", "999999999999"],
         "at most 107,000 ICFN samples (ten times the default), got 999,999,999,999"),
        (["--rcfn-sequences", "999999999999"],
         "at most 8,100 RCFN sequences (ten times the default), got 999,999,999,999"),
        (["--backend", "ray"], "--backend ray needs Ray: pip install 'relaxgrip[ray]'"),
        (["--backend", "dask"], "--backend dask needs Dask: pip install 'relaxgrip[dask]'"),
    ],
    ids=["hold-overflow", "hold-over-an-hour", "icfn-samples", "rcfn-sequences", "ray", "dask"],
)
def test_build_refuses_before_it_starts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
    args: list[str], expected: str,
) -> None:
    """Out-of-range sizes and a backend that is not installed: one line, no progress bar
    before it, and no dataset directory."""
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # as if not installed, whether or not it is
    monkeypatch.setitem(sys.modules, "dask", None)
    code, out, err = run_main(["dataset", "build", "--out", tmp_path / "d", *args],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, expected)
    assert not (tmp_path / "d").exists()


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from relaxgrip.learning.build import build_dataset
    from relaxgrip.learning.datasets import DatasetSpec

    out = tmp_path_factory.mktemp("tiny") / "data"
    build_dataset(out, DatasetSpec(icfn_samples=40, rcfn_sequences=4, hold_s=10.0, seed=1),
                  jobs=2)
    return out


def _nan_in(table: str, column: str) -> Callable[[Path], None]:
    def corrupt(d: Path) -> None:
        frame = pd.read_parquet(d / f"{table}.parquet")
        frame.loc[0, column] = float("nan")
        frame.to_parquet(d / f"{table}.parquet", index=False)
    return corrupt


def _schema_null(d: Path) -> None:
    manifest = json.loads((d / "manifest.json").read_text())
    manifest["icfn_schema"] = None
    (d / "manifest.json").write_text(json.dumps(manifest))


def _curves_directory(d: Path) -> None:
    (d / "rcfn_curves.parquet").unlink()
    (d / "rcfn_curves.parquet").mkdir()


def _force_as_text(d: Path) -> None:
    frame = pd.read_parquet(d / "icfn.parquet")
    frame["force_n"] = frame["force_n"].astype(str)
    frame.to_parquet(d / "icfn.parquet", index=False)


@pytest.mark.parametrize("command", ["evaluate", "train", "fit-observer"])
@pytest.mark.parametrize(
    ("corrupt", "expected"),
    [
        (_schema_null, "the manifest's icfn_schema is None, not a feature schema"),
        (_nan_in("icfn", "force_n"), "icfn.parquet: 1 NaN or infinite value in column 'force_n'"),
        (_nan_in("icfn", "marker_dx_m"), "in column 'marker_dx_m'"),
        (_nan_in("rcfn_features", "temp_c"), "rcfn_features.parquet: 1 NaN or infinite value"),
        (_curves_directory, "rcfn_curves.parquet: a directory, not a Parquet table"),
        (_force_as_text, "icfn.parquet: column 'force_n' holds"),
    ],
    ids=["schema-null", "nan-force", "nan-feature", "nan-temp", "curves-dir", "text-force"],
)
def test_a_damaged_dataset_is_one_line_before_any_work(
    tiny_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str], command: str, corrupt: Callable[[Path], None],
    expected: str,
) -> None:
    damaged = tmp_path / "damaged"
    shutil.copytree(tiny_data, damaged)
    corrupt(damaged)
    args: list[str | Path] = [command, "--data", damaged]
    if command != "evaluate":
        args += ["--out", tmp_path / "out"]
    code, out, err = run_main(args, monkeypatch, capsys)
    assert_one_error_line(code, out, err, expected)
    assert not (tmp_path / "out").exists()


def test_calibrate_hold_lists_the_recordings_once(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The models note and the calibration read the same files: the directory listed once
    (the calibration was given the directory and listed it again)."""
    from relaxgrip.errors import InputError
    from relaxgrip.experiments import recorded_calibration
    from relaxgrip.learning.training import default_models_dir
    from relaxgrip.recording import provenance

    models = tmp_path / "models"
    shutil.copytree(default_models_dir(), models)
    holds = tmp_path / "holds"
    holds.mkdir()
    for name in ("b.mcap", "a.mcap"):
        (holds / name).write_bytes(b"")
    seen: dict[str, list[Path]] = {}

    def note(files: list[Path], *args: object, **kwargs: object) -> None:
        seen["note"] = list(files)

    def calibrate(paths: list[Path], *args: object) -> None:
        seen["calibration"] = list(paths)
        raise InputError("stop here")

    monkeypatch.setattr(provenance, "differences_note", note)
    monkeypatch.setattr(recorded_calibration, "calibration_from_recordings", calibrate)
    code, _, err = run_main(["calibrate-hold", models, "--recordings", holds, "--dry-run"],
                            monkeypatch, capsys)
    assert code == 2
    assert "stop here" in err
    assert seen["note"] == seen["calibration"] == [holds / "a.mcap", holds / "b.mcap"]
