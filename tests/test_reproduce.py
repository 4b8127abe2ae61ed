"""``relaxgrip reproduce --quick`` regenerates every section of the report."""

from __future__ import annotations

import json
from pathlib import Path

from relaxgrip.experiments.tasks import TASKS
from relaxgrip.reproduce import SECTIONS
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
    assert "report.md" in stdout
