"""``relaxgrip reproduce --quick`` regenerates every section of the report."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

import relaxgrip.experiments.controlled_hold as controlled_hold
from relaxgrip.control import EstimatorKind
from relaxgrip.experiments.tasks import TASKS
from relaxgrip.reproduce import SECTIONS, holding_section
from relaxgrip.twin import TwinConfig
from tests.clitools import run_main


def test_quick_reproduce_regenerates_every_section(monkeypatch, capsys, tmp_path: Path):
    out = tmp_path / "report"
    out.mkdir()
    (out / "report.md").write_text("stale")
    code, stdout, err = run_main(["reproduce", "--quick", "--out", out], monkeypatch, capsys)
    assert code == 0, err
    report = (out / "report.md").read_text()
    results = json.loads((out / "results.json").read_text())
    assert list(results["sections"]) == list(SECTIONS)
    assert results["quick"] is True
    for key, section in results["sections"].items():
        assert f"## {section['title']}" in report, key
        assert (out / section["figure"]).stat().st_size > 10_000, key
        assert f"![{section['title']}]({section['figure']})" in report
        rows = section["paper_vs_ours"]
        assert rows, key
        assert all(row["paper"] and row["ours"] for row in rows), key
    # Every task is scored, and on the default seed every one succeeds.
    table = report.split("## Tasks")[1]
    for name in TASKS:
        assert f"| {name} | success |" in table, name
    assert "stale" not in report
    # The console wraps a long path wherever the line reaches its width.
    assert "report.md" in stdout.replace("\n", "")
    holding = results["sections"]["holding"]
    assert list(holding["results"]["holds"]) == [kind.value for kind in EstimatorKind]
    assert any("observer" in row["quantity"] for row in holding["paper_vs_ours"])


def test_the_holding_section_holds_what_hold_compare_holds(monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture[str],
                                                           tmp_path: Path) -> None:
    """The report's Fig. "sphere" and ``relaxgrip hold --compare`` run the same estimators, the
    observer among them (the section's holds shortened to the CLI's 6 s here)."""
    code, out, err = run_main(["hold", "--compare", "--duration-s", "6", "--json"],
                              monkeypatch, capsys)
    assert code == 0, err
    compared = json.loads(out)["holds"]
    real = controlled_hold.compare_holds

    def short(*args: Any, **kwargs: Any) -> controlled_hold.HoldComparison:
        assert len(args) < 3, "the section passes its duration by name"
        return real(*args, **{**kwargs, "duration_s": 6.0})

    monkeypatch.setattr(controlled_hold, "compare_holds", short)
    section = holding_section(tmp_path, quick=True, seed=0, config=TwinConfig())
    holds = section.results["holds"]
    assert list(holds) == list(compared) == [kind.value for kind in EstimatorKind]
    for name, hold in holds.items():
        assert hold["mae_n"] == pytest.approx(compared[name]["mae_n"]), name
    observer = [row for row in section.rows if "observer" in row.quantity]
    assert len(observer) == 1
    assert observer[0].ours == f"{holds['observer']['mae_n']:.3f} N"
    assert f"observer within {holds['observer']['mae_n']:.3f} N" in section.finding
    assert (tmp_path / "holding.png").stat().st_size > 10_000


def test_the_scenarios_finding_says_whether_the_observer_is_ahead() -> None:
    from relaxgrip.reproduce import _scenarios_finding

    ahead = _scenarios_finding([12.6, 2.5, 44.4], 280.0)
    assert "Eq. 10's MAE is 2.5–44.4 times the observer's" in ahead
    alike = _scenarios_finding([1.0, 1.04, 0.97], 280.0)
    assert "relax and the observer hold alike" in alike
    assert "1.0 times the observer's" in alike
    assert "Eq. 10 assumes" not in alike
    assert "branch states" in _scenarios_finding([1.0, 1.3], 140.0)  # one apart: not alike


def test_reproduce_runs_on_the_twin_of_the_rig_given(monkeypatch, capsys, tmp_path: Path):
    from tests.rigs import RIG_FILES

    out = tmp_path / "lab"
    code, _, err = run_main(["reproduce", "--quick", "--section", "characterization",
                             "--out", out, "--rig", RIG_FILES["lab"], "--jobs", "1"],
                            monkeypatch, capsys)
    assert code == 0, err
    results = json.loads((out / "results.json").read_text())
    assert results["rig"] == str(RIG_FILES["lab"])
    assert f"of the rig `{RIG_FILES['lab']}`" in (out / "report.md").read_text()
    drops = results["sections"]["characterization"]["results"]["k80_drop_pct"].values()
    assert all(abs(d - 36.6) < 0.5 for d in drops)  # the lab's finger, not ours (about 40 %)
