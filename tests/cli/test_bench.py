"""``relaxgrip bench``: the report's shape (speed itself is measured, never asserted)."""

from __future__ import annotations

import json

import pytest

from relaxgrip.cli.bench import format_duration
from tests.clitools import assert_one_error_line, run_main


def test_json_report_has_medians_and_realtime_factor(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run_main(["bench", "twin-hold", "--repeat", "1", "--json"], monkeypatch, capsys)
    assert code == 0
    report = json.loads(out)
    (bench,) = report["benchmarks"]
    assert bench["name"] == "twin-hold"
    assert bench["runs"] == 1
    assert bench["median_s"] > 0.0
    # The run closes to 5 N before its 280 s hold: that time is simulated too.
    assert 15.0 < bench["closing_s"] < 30.0
    assert bench["simulated_s"] == pytest.approx(280.0 + bench["closing_s"])
    assert bench["realtime_factor"] == pytest.approx(bench["simulated_s"] / bench["median_s"])
    # The machine-independent figure: the median over the reference workload's, same run.
    assert report["reference_min_s"] <= report["reference_s"] <= report["reference_max_s"]
    assert bench["reference_ratio"] == pytest.approx(bench["median_s"] / report["reference_s"])
    assert "profile" not in bench


def test_reference_workload_is_fixed() -> None:
    from relaxgrip.bench.core import reference_workload

    assert reference_workload() == reference_workload()


def test_profile_lists_functions_by_self_time(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run_main(["bench", "twin-step", "--repeat", "1", "--profile", "--json"],
                            monkeypatch, capsys)
    assert code == 0
    (bench,) = json.loads(out)["benchmarks"]
    entries = bench["profile"]
    assert 0 < len(entries) <= 15
    self_s = [e["self_s"] for e in entries]
    assert self_s == sorted(self_s, reverse=True)
    assert all(e["cumulative_s"] >= e["self_s"] and e["calls"] >= 1 for e in entries)
    assert sum(e["self_share"] for e in entries) <= 1.0 + 1e-9
    # The twin's step is among them, named by its path in the package.
    assert any(e["function"].startswith("relaxgrip/twin/twin.py:") for e in entries)


def test_compare_runs_the_same_benchmarks_on_a_ref(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import subprocess

    before = subprocess.run(["git", "worktree", "list"], capture_output=True, text=True,
                            check=True).stdout
    code, out, err = run_main(["bench", "twin-step", "--repeat", "1", "--compare", "HEAD",
                               "--json"], monkeypatch, capsys)
    assert code == 0, err
    report = json.loads(out)
    compare = report["compare"]
    assert compare["ref"] == "HEAD"
    assert len(compare["commit"]) == 40
    (row,) = compare["benchmarks"]
    assert row["name"] == "twin-step"
    assert row["speedup"] == pytest.approx(row["ref_median_s"] / row["median_s"])
    assert row["speedup_normalised"] > 0.0
    assert compare["ref_report"]["benchmarks"][0]["name"] == "twin-step"
    # The temporary worktree is gone again.
    after = subprocess.run(["git", "worktree", "list"], capture_output=True, text=True,
                           check=True).stdout
    assert after == before


def test_compare_with_a_ref_that_does_not_run(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import subprocess

    # The repository's first commit: a package skeleton without the benchmarks.
    root = subprocess.run(["git", "rev-list", "--max-parents=0", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.split()[-1]
    code, out, err = run_main(["bench", "twin-step", "--repeat", "1", "--compare", root],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, "the benchmarks do not run on")


@pytest.mark.parametrize(
    ("args", "expected"),
    [(["bench", "warp-drive"], "unknown benchmark 'warp-drive'"),
     (["bench", "--repeat", "0"], "--repeat must be 1-1000, got 0"),
     (["bench", "--repeat", "1001"], "--repeat must be 1-1000, got 1001"),
     (["bench", "--repeat", "99999999999999999999"], "--repeat must be 1-1000"),
     (["bench", "twin-step", "--compare", "no-such-ref-anywhere"],
      "no commit 'no-such-ref-anywhere'"),
     (["bench", "twin-step", "--compare", "--json"], "--compare takes a git ref"),
     (["bench", "faults", "--profile"], "bench faults takes neither --profile nor --compare")],
)
def test_bad_flags(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    args: list[str],
    expected: str,
) -> None:
    code, out, err = run_main(list(args), monkeypatch, capsys)
    assert_one_error_line(code, out, err, expected)


@pytest.mark.parametrize(
    ("seconds", "shown"),
    [(1.0095e-5, "10.1 µs"), (9.81e-4, "981 µs"), (2.15e-3, "2.15 ms"), (8.81, "8.81 s"),
     # rounded up into the next unit, and past 1000 s: never "1e+03 ms" or "1.23e+03 s"
     (9.9996e-4, "1 ms"), (0.9996, "1 s"), (999.6, "1000 s"), (1234.5, "1230 s")],
)
def test_table_durations_keep_three_figures(seconds: float, shown: str) -> None:
    # A 10 µs median had been printed as "0.0 ms".
    assert format_duration(seconds) == shown
