"""``relaxgrip fit-material`` end to end, on pyvisco's measurements and on broken files.

Every bad input gives one ``error:`` line, exit code 2 and no material file.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.physics.material import Material, ShiftLaw
from tests.clitools import assert_one_error_line, run_cli, run_main

DATA = Path(__file__).resolve().parents[1] / "data" / "pyvisco"
TRUE = Material("E", 15e6, (300e6, 250e6, 200e6, 150e6), (1e-2, 1.0, 1e2, 1e4),
                ShiftLaw("wlf", (8.0, 60.0), 40.0), (20.0, 60.0))


def project_csv(path: Path, temps: tuple[float, ...] = (20.0, 30.0, 40.0, 50.0, 60.0)) -> Path:
    """A clean time-domain file in the project's convention (MPa, temp_c, set)."""
    t = np.logspace(-1, 3, 9)
    lines = ["time_s,modulus_mpa,temp_c,set"]
    for k, temp in enumerate(temps):
        for ti, e in zip(t, TRUE.relaxation_modulus_pa(t, temp), strict=True):
            lines.append(f"{ti:.6g},{e / 1e6:.6g},{temp},{k}")
    path.write_text("\n".join(lines) + "\n")
    return path


def fit(args: list[str | Path], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    return run_main(["fit-material", *args], monkeypatch, capsys)


def test_json_carries_the_issue_keys(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "m.json"
    code, stdout, err = fit([project_csv(tmp_path / "a.csv"), "--json", "--out", out,
                             "--max-terms", "8"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(stdout)
    assert d["ref_temp_c"] == pytest.approx(40.0)
    assert d["shift"]["model"] in ("wlf", "arrhenius", "two_regime")
    assert set(d["log_aT"]) == {"20", "30", "40", "50", "60"}
    assert d["log_aT"]["40"] == 0.0
    assert all({"modulus_pa", "tau_s"} == set(t) for t in d["prony"]["terms"])
    assert d["prony"]["e_inf_pa"] >= 0
    assert d["fit"]["rms_log10"] < 0.01
    assert "rms_log10_master" in d["fit"]
    mat = Material.from_dict(json.loads(out.read_text()))
    assert mat.shift.model == d["shift"]["model"]
    assert mat.provenance["sources"][0]["file"] == "a.csv"


def test_ref_temp_c_moves_the_reference(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, err = fit([project_csv(tmp_path / "a.csv"), "--json", "--ref-temp-c", "35",
                             "--max-terms", "6"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(stdout)
    assert d["ref_temp_c"] == 35.0
    assert d["log_aT"]["30"] > 0 > d["log_aT"]["40"]


@pytest.mark.slow
def test_pyvisco_files_table_and_plot(tmp_path: Path) -> None:
    png = tmp_path / "fit.png"
    proc = run_cli("fit-material", DATA / "time_user_raw.csv", "--max-terms", "12",
                   "--plot", png, timeout_s=300.0)
    assert proc.returncode == 0, proc.stderr
    assert "two_regime" in proc.stdout
    assert png.stat().st_size > 10_000


def _bad(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


PYV_HEAD = "t,E_relax,T,Set\ns,MPa,C,-\n"


def _pyv_rows(temps: tuple[float, ...] = (20.0, 25.0)) -> str:
    t = np.logspace(-1, 2, 6)
    rows = []
    for k, temp in enumerate(temps):
        for ti, e in zip(t, TRUE.relaxation_modulus_pa(t, temp), strict=True):
            rows.append(f"{ti:.6g},{e / 1e6:.6g},{temp},{k}")
    return "\n".join(rows) + "\n"


BAD_CASES = {
    "missing units row": ("t,E_relax,T,Set\n" + _pyv_rows(), "line 2: missing the units row"),
    "unknown unit": (PYV_HEAD.replace("MPa", "psi") + _pyv_rows(), "unknown unit 'psi'"),
    "single temperature": (PYV_HEAD + _pyv_rows((30.0,)), "a single temperature"),
    "time backwards": (PYV_HEAD + "0.1,900,20,0\n1,890,20,0\n0.5,880,20,0\n10,870,20,0\n"
                       + _pyv_rows(), "line 5: time goes backwards within the set"),
    "negative modulus": (PYV_HEAD + "0.1,-900,20,0\n" + _pyv_rows(),
                         "line 3: modulus must be > 0"),
    "nan modulus": (PYV_HEAD + "0.1,nan,20,0\n" + _pyv_rows(), "line 3: modulus"),
    "no overlap": (PYV_HEAD + "0.1,1000,20,0\n1,990,20,0\n10,980,20,0\n"
                   "0.1,10,60,1\n1,9.9,60,1\n10,9.8,60,1\n", "do not overlap enough to shift"),
    "missing column": ("t,T,Set\ns,C,-\n0.1,20,0\n", "missing column(s) E_relax"),
    "not a number": (PYV_HEAD + "0.1,abc,20,0\n" + _pyv_rows(), "is not a number"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_input_is_one_line_and_writes_nothing(case: str, tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    text, expected = BAD_CASES[case]
    src = _bad(tmp_path, "bad.csv", text)
    out = tmp_path / "m.json"
    code, stdout, err = fit([src, "--out", out], monkeypatch, capsys)
    assert_one_error_line(code, stdout, err, expected)
    assert "bad.csv" in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv"]


@pytest.mark.parametrize(("flags", "expected"), [
    (["--max-terms", "0"], "--max-terms must be 1-60"),
    (["--out", "m.txt"], "ends in .json"),
    (["--ref-temp-c", "90"], "outside the measured"),
    (["--plot", "fig.xyz"], "xyz"),
])
def test_bad_flags(flags: list[str], expected: str, tmp_path: Path,
                   monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    src = project_csv(tmp_path / "a.csv")
    monkeypatch.chdir(tmp_path)
    code, stdout, err = fit([src, *flags], monkeypatch, capsys)
    assert_one_error_line(code, stdout, err, expected)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"]


def test_files_of_different_domains_are_refused(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    code, stdout, err = fit([project_csv(tmp_path / "a.csv"), DATA / "freq_user_raw.csv"],
                            monkeypatch, capsys)
    assert_one_error_line(code, stdout, err, "cannot be fitted together")


def test_force_and_displacement_with_geometry(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    t = np.logspace(-1, 3, 9)
    lines = ["time_s,force_n,displacement_mm,temp_c"]
    for temp in (20.0, 30.0, 40.0):
        e = TRUE.relaxation_modulus_pa(t, temp)
        force = e * 1e-6 * (0.5 / 50.0)  # area 1 mm^2, strain 0.5 / 50
        lines += [f"{ti:.6g},{f:.6g},0.5,{temp}" for ti, f in zip(t, force, strict=True)]
    src = _bad(tmp_path, "fd.csv", "\n".join(lines) + "\n")
    code, stdout, err = fit([src, "--json", "--max-terms", "6"], monkeypatch, capsys)
    assert_one_error_line(code, stdout, err, "--gauge-length-mm and --area-mm2")
    code, stdout, err = fit([src, "--json", "--max-terms", "6", "--gauge-length-mm", "50",
                             "--area-mm2", "1"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(stdout)
    assert d["prony"]["e_inf_pa"] + sum(t["modulus_pa"] for t in d["prony"]["terms"]) \
        == pytest.approx(TRUE.e_instant_pa, rel=0.2)
