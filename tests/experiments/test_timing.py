"""Timing experiment (Fig. "network" b): every stage measured, the sums add up, the figure."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from relaxgrip.experiments.timing import PAPER_LATENCY_MS, run_timing
from relaxgrip.plots.timing import plot_timing


@pytest.fixture(scope="module")
def timing():
    return run_timing(quick=True)


def test_every_stage_is_measured(timing):
    stages = {"aruco_pose", "aruco_full_frame", "thermal", "features", "icfn", "rcfn",
              "perception", "instantaneous", "compensated"}
    assert set(timing.median_ms) == stages
    for stage in stages:
        assert 0.0 < timing.median_ms[stage] <= timing.p99_ms[stage], stage
        assert math.isfinite(timing.p99_ms[stage])


def test_end_to_end_latencies_contain_their_parts(timing):
    m = timing.median_ms
    # Medians of sums are not sums of medians, but a whole can't be cheaper than one part.
    assert m["instantaneous"] >= m["icfn"]
    assert m["instantaneous"] >= 0.8 * m["perception"]
    assert m["compensated"] >= m["rcfn"]
    assert m["aruco_full_frame"] > m["aruco_pose"]  # tracking in a ROI beats a full search


def test_to_dict_sets_ours_beside_the_paper(timing):
    d = timing.to_dict()
    assert d["paper_ms"] == PAPER_LATENCY_MS
    assert d["speedup_compensated"] == pytest.approx(
        PAPER_LATENCY_MS["compensated"] / timing.median_ms["compensated"])


def test_figure(timing, tmp_path: Path):
    path = plot_timing(timing, tmp_path / "timing.png")
    assert path.stat().st_size > 10_000
