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


@pytest.mark.parametrize(
    ("args", "expected"),
    [(["bench", "warp-drive"], "unknown benchmark 'warp-drive'"),
     (["bench", "--repeat", "0"], "--repeat must be 1-1000, got 0"),
     (["bench", "--repeat", "1001"], "--repeat must be 1-1000, got 1001"),
     (["bench", "--repeat", "99999999999999999999"], "--repeat must be 1-1000")],
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
