"""``relaxgrip task`` and ``relaxgrip reproduce``: registry, report files, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

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

    def boom(out_dir: Path, quick: bool, seed: int, config: object) -> Section:
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


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
def test_a_failed_task_exits_1(monkeypatch, capsys, json_flag):
    import relaxgrip.experiments.tasks as tasks

    failed = TaskResult("hammer", 0, {"lifted_and_held": False}, {"peak_true_n": 1.0})
    monkeypatch.setattr(tasks, "task_function", lambda name: lambda seed, config: failed)
    code, out, err = run_main(["task", "hammer", *json_flag], monkeypatch, capsys)
    assert code == 1, err
    assert "Traceback" not in err
    if json_flag:
        assert json.loads(out)["success"] is False
    else:
        assert "failed" in out


def test_reproduce_refuses_a_directory_that_is_not_a_report(monkeypatch, capsys,
                                                            tmp_path: Path):
    data = tmp_path / "dataset"
    data.mkdir()
    (data / "icfn.parquet").write_bytes(b"precious")
    code, out, err = run_main(["reproduce", "--quick", "--out", data], monkeypatch, capsys)
    assert code == 2, err
    assert out == ""
    assert err.strip().splitlines() == [
        f"error: {data} is not empty and holds no reproduce output (report.md, results.json): "
        "choose another --out"]
    assert [p.name for p in data.iterdir()] == ["icfn.parquet"]


def _fake_section(name: str, interrupt: bool = False):
    """A section that draws a small figure, then returns or is interrupted (Ctrl-C)."""
    def section(out_dir: Path, quick: bool, seed: int, config: object) -> Section:
        (out_dir / name).write_bytes(b"figure")
        if interrupt:
            raise KeyboardInterrupt
        return Section(name, name, [Row("q", "1", "2")], "finding", name, {})
    return section


def test_reproduce_moves_figures_in_only_when_every_section_is_back(monkeypatch, capsys,
                                                                   tmp_path: Path):
    from relaxgrip import reproduce

    out = tmp_path / "report"
    out.mkdir()
    (out / "report.md").write_text("old report")  # an earlier report: allowed, replaced
    (out / "kept.png").write_text("old figure")
    for key, interrupt in (("a.png", False), ("b.png", True)):
        monkeypatch.setitem(reproduce.SECTIONS, key, _fake_section(key, interrupt))
        monkeypatch.setitem(reproduce.TITLES, key, key)
    with pytest.raises(KeyboardInterrupt):
        reproduce.reproduce(out, quick=True, jobs=1, only=["a.png", "b.png"])
    # Interrupted: the directory is as it was, with no figure of the unfinished run.
    assert sorted(p.name for p in out.iterdir()) == ["kept.png", "report.md"]
    assert (out / "report.md").read_text() == "old report"
    monkeypatch.setitem(reproduce.SECTIONS, "b.png", _fake_section("b.png"))
    sections = reproduce.reproduce(out, quick=True, jobs=1, only=["a.png", "b.png"])
    assert [s.figure for s in sections] == ["a.png", "b.png"]
    assert sorted(p.name for p in out.iterdir()) == ["a.png", "b.png", "kept.png", "report.md",
                                                     "results.json"]
    assert (out / "a.png").read_bytes() == b"figure"
    assert "old report" not in (out / "report.md").read_text()
