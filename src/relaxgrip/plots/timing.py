"""The paper's Fig. "network" b: latency per stage, ours beside the paper's."""

from __future__ import annotations

from pathlib import Path

from relaxgrip.experiments.timing import PAPER_LATENCY_MS, TimingResult
from relaxgrip.plots.common import new_figure, save_figure

__all__ = ["plot_timing"]

_STAGES = (
    ("aruco_pose", "marker pose"),
    ("aruco_full_frame", "full-frame ArUco"),
    ("thermal", "thermal (1 Hz)"),
    ("icfn", "ICFN"),
    ("rcfn", "RCFN"),
    ("instantaneous", "instantaneous"),
    ("compensated", "compensated"),
)


def plot_timing(result: TimingResult, path: Path) -> Path:
    """Horizontal bars of median latency per stage (log scale), the paper's where it gives one."""
    import numpy as np

    fig = new_figure(7.0, 3.6)
    ax = fig.subplots()
    y = np.arange(len(_STAGES))
    ours = [result.median_ms[key] for key, _ in _STAGES]
    p99 = [result.p99_ms[key] for key, _ in _STAGES]
    ax.barh(y + 0.2, ours, height=0.38, label="relaxgrip (median)", color="tab:green")
    ax.plot(p99, y + 0.2, "|", color="k", markersize=9, label="relaxgrip p99")
    paper = [PAPER_LATENCY_MS.get(key, np.nan) for key, _ in _STAGES]
    ax.barh(y - 0.2, paper, height=0.38, label="paper", color="tab:gray")
    ax.set_yticks(y, [label for _, label in _STAGES])
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("latency per frame (ms)")
    ax.set_title("Force perception latency by stage (one core)")
    ax.legend(loc="lower right", fontsize=8)
    return save_figure(fig, path)
