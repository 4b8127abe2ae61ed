"""``relaxgrip task`` and ``relaxgrip reproduce``: registry, report files, bad input."""

from __future__ import annotations

import json
from pathlib import Path

from relaxgrip.experiments.tasks import TaskResult
from relaxgrip.reproduce import Row, Section, write_report
from tests.clitools import run_main


def test_task_result_succeeds_only_if_every_criterion_holds():
    ok = TaskResult("x", 0, {"lifted": True, "not_crushed": True}, {"peak_n": 1.0})
    bad = TaskResult("x", 0, {"lifted": True, "not_crushed": False}, {"peak_n": 1.0})
    empty = TaskResult("x", 0, {}, {})
    assert ok.success
    assert not bad.success
    assert not empty.success
    d = bad.to_dict()
    assert d["success"] is False
    assert d["criteria"] == {"lifted": True, "not_crushed": False}
    json.dumps(d)


def test_unknown_task_is_a_clear_error(monkeypatch, capsys):
    code, _, err = run_main(["task", "teapot"], monkeypatch, capsys)
    assert code == 2
    assert "unknown task 'teapot'" in err
    assert "hammer" in err


def test_reproduce_rejects_unknown_sections_and_missing_parents(monkeypatch, capsys,
                                                                tmp_path: Path):
    code, _, err = run_main(["reproduce", "--out", tmp_path / "r", "--section", "teapot"],
                            monkeypatch, capsys)
    assert code == 2
    assert "unknown section(s) teapot" in err
    code, _, err = run_main(["reproduce", "--out", tmp_path / "no" / "r"], monkeypatch, capsys)
    assert code == 2
    assert "does not exist" in err
    code, _, err = run_main(["reproduce", "--out", tmp_path / "r", "--jobs", "0"],
                            monkeypatch, capsys)
    assert code == 2
    assert "--jobs must be >= 1, got 0" in err
    assert not (tmp_path / "r").exists()


def test_reproduce_one_section_writes_report_and_results(monkeypatch, capsys, tmp_path: Path):
    out = tmp_path / "report"
    code, _stdout, err = run_main(["reproduce", "--quick", "--out", out, "--section",
                                  "characterization", "--jobs", "1"], monkeypatch, capsys)
    assert code == 0, err
    report = (out / "report.md").read_text()
    assert "## Stiffness characterization" in report
    assert "| 35–45 % |" in report
    assert "![" in report
    assert (out / "characterization.png").stat().st_size > 10_000
    results = json.loads((out / "results.json").read_text())
    assert list(results["sections"]) == ["characterization"]
    assert results["sections"]["characterization"]["results"]["z80_monotone_in_temp"] is True


def test_report_escapes_table_cells(tmp_path: Path):
    section = Section("s", "Title", [Row("a|b", "1", "2")], "finding", None, {"x": float("nan")})
    write_report(tmp_path, [section], quick=True, seed=0, seconds=1.0)
    assert "| a\\|b | 1 | 2 |" in (tmp_path / "report.md").read_text()
    assert json.loads((tmp_path / "results.json").read_text())["sections"]["s"]["results"] == {
        "x": None}
    assert not list(tmp_path.glob(".*tmp"))


def test_a_failing_section_is_reported_and_the_others_kept(monkeypatch, capsys, tmp_path: Path):
    from relaxgrip import reproduce

    def boom(out_dir: Path, quick: bool, seed: int) -> Section:
        raise RuntimeError("the twin caught fire\nsecond line")

    monkeypatch.setitem(reproduce.SECTIONS, "boom", boom)
    monkeypatch.setitem(reproduce.TITLES, "boom", "A broken experiment")
    out = tmp_path / "report"
    code, _, err = run_main(["reproduce", "--quick", "--out", out, "--jobs", "1", "--section",
                             "boom", "--section", "characterization"], monkeypatch, capsys)
    assert code == 1
    assert "section(s) failed: boom" in err
    report = (out / "report.md").read_text()
    assert "## A broken experiment" in report
    assert "FAILED: RuntimeError: the twin caught fire" in report
    assert "second line" not in report
    assert "## Stiffness characterization" in report
    results = json.loads((out / "results.json").read_text())
    assert results["sections"]["boom"]["results"] == {"error": "RuntimeError: the twin caught fire"}


def test_task_json_gives_success_criteria_and_figures(monkeypatch, capsys):
    code, out, err = run_main(["task", "can", "--seed", "1", "--json"], monkeypatch, capsys)
    assert code == 0, err
    d = json.loads(out)
    assert d["task"] == "can"
    assert d["seed"] == 1
    assert d["success"] is True
    assert d["criteria"] == {"compliant_not_crushed": True, "compliant_holds": True,
                             "stiff_crushes": True}
    assert d["figures"]["stiff_plastic_mm"] > 0.0 == d["figures"]["compliant_plastic_mm"]


def test_task_prints_its_verdict_and_criteria(monkeypatch, capsys):
    code, out, err = run_main(["task", "can"], monkeypatch, capsys)
    assert code == 0, err
    assert "success" in out
    assert "stiff_crushes" in out
