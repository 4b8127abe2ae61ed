"""``relaxgrip fit-relaxation`` end to end, on measured and on broken records.

The acceptance cases run ``python -m relaxgrip`` as a subprocess; further
error cases call :func:`relaxgrip.cli.main` in-process, which takes exactly
the same path from ``InputError`` to one ``error:`` line and exit code 2.
"""

from __future__ import annotations

import json
import os
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.physics.viscoelastic import prony_force
from tests.clitools import SHARED_DIR, assert_one_error_line, run_cli, run_main

DATA_DIR = SHARED_DIR / "data" / "vhb4910-relaxation"
REAL_FILES = sorted(DATA_DIR.glob("*.csv")) if DATA_DIR.is_dir() else []
needs_data = pytest.mark.skipif(not REAL_FILES, reason=f"VHB4910 data not found in {DATA_DIR}")

HEADER = "time_s,displacement_mm,force_n"
Row = tuple[float, float, float]


def run_fit(*args: str | Path) -> subprocess.CompletedProcess[str]:
    """``python -m relaxgrip fit-relaxation ARGS`` in a fresh interpreter."""
    return run_cli("fit-relaxation", *args, timeout_s=120.0)


def run_fit_main(
    args: list[str | Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> tuple[int, str, str]:
    """``relaxgrip fit-relaxation ARGS`` in-process: exit code, stdout, stderr."""
    return run_main(["fit-relaxation", *args], monkeypatch, capsys)


def synthetic_rows() -> list[Row]:
    """A 2 s ramp to 40 mm at 50 Hz, then a 120 s hold (50 Hz to 10 s, 5 Hz after)."""
    t_ramp = np.arange(0.0, 2.0, 0.02)
    t_hold = np.concatenate([np.arange(0.0, 10.0, 0.02), np.arange(10.0, 120.0, 0.2)])
    force_hold = prony_force(t_hold, 0.5, (0.4, 0.3), (2.0, 30.0))
    rows = [(t, 20.0 * t, 0.6 * t) for t in t_ramp]
    rows += [(2.0 + t, 40.0, f) for t, f in zip(t_hold, force_hold, strict=True)]
    return rows


def write_csv(path: Path, rows: list[Row], header: str = HEADER) -> Path:
    lines = [header, *(",".join(f"{v:.6f}" for v in row) for row in rows)]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.fixture
def good_csv(tmp_path: Path) -> Path:
    return write_csv(tmp_path / "good.csv", synthetic_rows())


# --- measured records (acceptance) ----------------------------------------------------


@pytest.fixture(scope="module")
def real_runs() -> dict[Path, subprocess.CompletedProcess[str]]:
    """``--json`` runs on every measured record, concurrently (each is a separate process)."""
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        runs = pool.map(lambda path: run_fit(path, "--json"), REAL_FILES)
        return dict(zip(REAL_FILES, runs, strict=True))


@needs_data
@pytest.mark.parametrize("path", REAL_FILES, ids=lambda p: p.name)
def test_fits_measured_vhb4910_record(
    path: Path, real_runs: dict[Path, subprocess.CompletedProcess[str]]
) -> None:
    proc = real_runs[path]
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    out = json.loads(proc.stdout)  # exactly one JSON document on stdout
    assert set(out) == {"file", "hold_start_s", "window_s", "weighting", "reduced", "prony"}
    assert out["file"] == str(path)
    assert out["weighting"] == "time"
    assert out["hold_start_s"] > 0
    assert out["window_s"] > 1000  # the whole ~30 min hold
    assert set(out["reduced"]) == {"f_inst_n", "k_n", "tau_s", "nrmse", "auc_rel"}
    assert set(out["prony"]) == {"f_eq_n", "terms", "nrmse", "auc_rel"}
    terms = out["prony"]["terms"]
    assert len(terms) == 3
    assert all(set(term) == {"k_n", "tau_s"} for term in terms)
    taus = [term["tau_s"] for term in terms]
    assert taus == sorted(taus)
    assert all(tau > 0 for tau in taus)
    # Acceptance criterion: a 3-term Prony series fits every measured curve to NRMSE < 1 %.
    assert out["prony"]["nrmse"] < 0.01
    assert out["reduced"]["nrmse"] > out["prony"]["nrmse"]


# --- options --------------------------------------------------------------------------


def test_plot_writes_png(good_csv: Path, tmp_path: Path) -> None:
    png = tmp_path / "fit.png"
    proc = run_fit(good_csv, "--json", "--plot", png)
    assert proc.returncode == 0, proc.stderr
    json.loads(proc.stdout)  # --plot adds nothing to standard output
    assert png.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    assert png.stat().st_size > 1000


def test_table_output(
    good_csv: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run_fit_main([good_csv, "--terms", "2"], monkeypatch, capsys)
    assert (code, err) == (0, "")
    for text in ("NRMSE", "AUC_rel", "reduced", "Prony (2 terms)", "F_inst", "τ2"):
        assert text in out


def test_window_and_weighting_options(
    good_csv: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    args: list[str | Path] = [good_csv, "--json", "--window-s", "40", "--terms", "2"]
    code, out, err = run_fit_main([*args, "--weighting", "sample"], monkeypatch, capsys)
    assert (code, err) == (0, "")
    result = json.loads(out)
    assert result["window_s"] == pytest.approx(40.0)
    assert result["weighting"] == "sample"
    assert result["hold_start_s"] == pytest.approx(2.0)
    # Noiseless two-mode data, printed to 6 decimals: recovered to that precision.
    terms = result["prony"]["terms"]
    assert [term["tau_s"] for term in terms] == pytest.approx([2.0, 30.0], rel=1e-3)
    assert [term["k_n"] for term in terms] == pytest.approx([0.4, 0.3], rel=1e-3)
    assert result["prony"]["nrmse"] < 1e-4


# --- bad input ------------------------------------------------------------------------


def bad_case(tmp_path: Path, name: str) -> list[str | Path]:
    """Arguments for one bad invocation; files are written to ``tmp_path``."""
    rows = synthetic_rows()
    csv = tmp_path / f"{name}.csv"
    if name == "missing-file":
        return [tmp_path / "nope.csv", "--json"]
    if name == "missing-column":
        write_csv(csv, [(t, f, f) for t, _, f in rows], header="time_s,force_n,load")
    elif name == "nan":
        rows[150] = (rows[150][0], rows[150][1], float("nan"))
        write_csv(csv, rows)
    elif name == "non-monotonic-time":
        rows[200], rows[201] = rows[201], rows[200]
        write_csv(csv, rows)
    elif name == "no-hold":
        write_csv(csv, [(t, 20.0 * t, f) for t, _, f in rows])
    elif name == "not-a-csv":
        csv.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe")
    elif name == "huge-force":  # squares overflow float64: warnings, then scipy's text
        write_csv(csv, [(t, x, f * 1e300) for t, x, f in rows])
    elif name == "huge-time":  # formerly a fit of meaningless numbers, and 20 warnings
        write_csv(csv, [(t * 1e300, x, f) for t, x, f in rows])
    elif name == "duplicate-column":  # formerly the first force_n was read, silently
        csv.write_text("time_s,force_n,displacement_mm,force_n\n" + "".join(
            f"{t:.6f},99,{x:.6f},{f:.6f}\n" for t, x, f in rows), encoding="utf-8")
    elif name == "too-few-rows":
        write_csv(csv, rows[:5])
    elif name in ("bad-number", "underscore-number"):
        write_csv(csv, rows)
        typo = "0.4mm" if name == "bad-number" else "0_4"  # float("0_4") is 4.0
        text = csv.read_text(encoding="utf-8").replace("0.020000,0.400000", f"0.020000,{typo}",
                                                       1)
        csv.write_text(text, encoding="utf-8")
    else:
        write_csv(csv, rows)
    flags: dict[str, list[str | Path]] = {
        "terms-0": ["--terms", "0"],
        "terms-6": ["--terms", "6"],
        "window-negative": ["--window-s", "-1"],
        "window-too-short": ["--window-s", "0.05"],
        "weighting-unknown": ["--weighting", "log"],
        "plot-missing-dir": ["--plot", tmp_path / "no" / "such" / "dir.png"],
        "plot-bad-extension": ["--plot", tmp_path / "fit.bmp"],
    }
    return [csv, "--json", *flags.get(name, [])]


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("missing-file", "nope.csv: no such file"),
        ("missing-column", "missing column(s) displacement_mm"),
        ("nan", "line 152: force_n is 'nan'"),
        ("non-monotonic-time", "line 203: time_s 4 does not increase"),
        ("no-hold", "no hold phase"),
        ("terms-0", "--terms must be 1-5, got 0"),
        ("window-negative", "--window-s must be > 0"),
        # In a fresh interpreter: no RuntimeWarning may reach standard error.
        ("huge-force", "the force reaches 1.2e+300 N, beyond any relaxation test (a fit "
                       "takes at most 1e+09 N)"),
        ("huge-time", "the record lasts 1.2e+302 s, beyond any relaxation test (a fit "
                      "takes at most 1e+10 s)"),
    ],
)
def test_bad_input_subprocess(tmp_path: Path, name: str, expected: str) -> None:
    proc = run_fit(*bad_case(tmp_path, name))
    assert_one_error_line(proc.returncode, proc.stdout, proc.stderr, expected)


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("not-a-csv", "not a text CSV"),
        ("too-few-rows", "only 5 data rows"),
        ("bad-number", "line 3: displacement_mm value '0.4mm' is not a number"),
        ("underscore-number", "line 3: displacement_mm value '0_4' is not a number"),
        ("window-too-short", "needs at least 10"),
        ("weighting-unknown", "--weighting must be one of time, sample"),
        ("plot-missing-dir", "does not exist"),
        ("plot-bad-extension", "unsupported plot format"),
        ("terms-6", "--terms must be 1-5, got 6 (each term about triples the fit's search "
                    "time)"),
        ("duplicate-column", "duplicate-column.csv: the header names force_n more than once; "
                             "keep one column of each name"),
    ],
)
def test_bad_input_in_process(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    name: str,
    expected: str,
) -> None:
    code, out, err = run_fit_main(bad_case(tmp_path, name), monkeypatch, capsys)
    assert_one_error_line(code, out, err, expected)


def test_plot_to_a_fifo_is_refused_before_the_fit(
    good_csv: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str]
) -> None:
    fifo = tmp_path / "fit.png"
    os.mkfifo(fifo)  # the atomic rename would replace it with a regular file
    code, out, err = run_fit_main([good_csv, "--plot", fifo], monkeypatch, capsys)
    assert_one_error_line(code, out, err, f"{fifo} is a FIFO, not a regular file: "
                                          "choose another output")
    assert fifo.is_fifo()


@pytest.mark.parametrize("variant", ["semicolon-decimal-comma", "tab", "blank-rows"])
def test_spreadsheet_exports_read_as_the_plain_csv(
    good_csv: Path, tmp_path: Path, variant: str, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    text = good_csv.read_text(encoding="utf-8")
    if variant == "semicolon-decimal-comma":
        other = text.replace(",", ";").replace(".", ",")
    elif variant == "tab":
        other = text.replace(",", "\t")
    else:
        lines = text.splitlines()
        other = "\n".join([*lines[:50], "", ",,", *lines[50:], "   "]) + "\n"
    path = tmp_path / f"{variant}.csv"
    path.write_text(other, encoding="utf-8")
    _, plain, _ = run_fit_main([good_csv, "--json"], monkeypatch, capsys)
    code, out, err = run_fit_main([path, "--json"], monkeypatch, capsys)
    assert (code, err) == (0, "")
    got, want = json.loads(out), json.loads(plain)
    assert got["hold_start_s"] == want["hold_start_s"]
    assert got["prony"]["terms"] == want["prony"]["terms"]
