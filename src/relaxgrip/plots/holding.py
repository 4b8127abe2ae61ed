"""The holding figure (paper Fig. "sphere" b–f): force and estimate per configuration, errors."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from relaxgrip.experiments.controlled_hold import HoldComparison, HoldResult
from relaxgrip.plots.common import check_plot_path, new_figure, save_figure

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["plot_hold", "plot_hold_comparison"]

_TITLES = {"fixed": "without holding control (fixed)",
           "icfn": "without relaxation compensation (icfn)",
           "relax": "ours: ICFN + RCFN (relax)",
           "observer": "viscoelastic observer (observer)"}
_COLORS = {"fixed": "tab:gray", "icfn": "tab:red", "relax": "tab:green",
           "observer": "tab:purple"}
#: The observer is ``relax``'s estimate through a standard hold: dashed, so both show.
_LINESTYLES = {"observer": (0, (4, 3))}


def _thin(t: np.ndarray, every_s: float = 0.2) -> np.ndarray:
    """Indices at about ``every_s`` spacing (a 280 s hold has 8400 samples)."""
    step = max(1, round(every_s / max(float(np.median(np.diff(t))), 1e-6)))
    return np.arange(0, t.size, step)


def plot_hold_comparison(comparison: HoldComparison, path: str | Path) -> Path:
    """Draw the paper's holding figure.

    Top row: per configuration, the true force (blue) and the estimate
    (orange, dashed) against the target over the hold, the steady-state
    interval shaded.  Bottom: the estimate's error over time for every
    configuration, and the distribution of the true force's error from the
    target over the steady-state interval.

    Parameters
    ----------
    comparison : HoldComparison
        Output of :func:`relaxgrip.experiments.controlled_hold.compare_holds`.
    path : str or pathlib.Path
        Output file (``.png``, ``.pdf`` or ``.svg``).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = check_plot_path(path)
    holds = comparison.holds
    n = len(holds)
    fig = new_figure(4.2 * max(n, 2), 6.6)
    grid = fig.add_gridspec(2, max(n, 2))
    top = [fig.add_subplot(grid[0, j]) for j in range(n)]
    for ax, (name, hold) in zip(top, holds.items(), strict=True):
        _force_panel(ax, name, hold)
    for ax in top[1:]:
        ax.sharey(top[0])
    ax_err = fig.add_subplot(grid[1, : max(n, 2) - 1])
    ax_box = fig.add_subplot(grid[1, max(n, 2) - 1])
    for name, hold in holds.items():
        idx = _thin(hold.t_s)
        ax_err.plot(hold.t_s[idx], (hold.estimate_n - hold.truth_n)[idx], lw=1.0,
                    color=_COLORS.get(name), ls=_LINESTYLES.get(name, "-"), label=name)
    ax_err.axhline(0.0, color="k", lw=0.6)
    ax_err.set_xlabel("time since hold onset (s)")
    ax_err.set_ylabel("estimate − true force (N)")
    ax_err.set_title("(e) estimation error over time")
    ax_err.legend(loc="best", fontsize=8)
    data, labels = [], []
    for name, hold in holds.items():
        lo, hi = hold.window
        mask = (hold.t_s >= lo) & (hold.t_s <= hi)
        data.append(hold.truth_n[mask] - hold.target_n)
        m = hold.metrics()
        labels.append(f"{name}\nMAE {m['mae_n']:.3f}")
    ax_box.boxplot(data, tick_labels=labels, showfliers=False)
    ax_box.axhline(0.0, color="k", lw=0.6)
    ax_box.set_ylabel("true force − target (N)")
    reductions = comparison.reductions()
    note = ", ".join(f"{k.replace('vs_', '−')} {v:.0%}" for k, v in reductions.items())
    ax_box.set_title(f"(f) target error, steady state\nrelax MAE reduction: {note}"
                     if note else "(f) target error, steady state", fontsize=9)
    first = next(iter(holds.values()))
    fig.suptitle(f"{first.duration_s:g} s hold at {first.target_n:g} N, {first.temp_c:g} °C, "
                 f"seed {first.seed} ({first.twin_version})")
    return save_figure(fig, path)


def _force_panel(ax: Axes, name: str, hold: HoldResult) -> None:
    idx = _thin(hold.t_s)
    lo, hi = hold.window
    ax.axvspan(lo, hi, color="0.93", zorder=0)
    ax.plot(hold.t_s[idx], hold.truth_n[idx], color="tab:blue", lw=1.2, label="true force")
    ax.plot(hold.t_s[idx], hold.estimate_n[idx], color="tab:orange", lw=1.2, ls="--",
            label="estimate")
    lo_n, hi_n = hold.series("band_lo_n")[idx], hold.series("band_hi_n")[idx]
    if np.isfinite(lo_n).any():
        ax.fill_between(hold.t_s[idx], lo_n, hi_n, color="tab:orange", alpha=0.2, lw=0,
                        label="95 % band")
    ax.axhline(hold.target_n, color="k", lw=0.6, ls=":", label="target")
    m = hold.metrics()
    ax.set_title(f"{_TITLES.get(name, name)}\nMAE {m['mae_n']:.3f} N", fontsize=9)
    ax.set_xlabel("time since hold onset (s)")
    ax.set_ylabel("force (N)")
    ax.legend(loc="lower left", fontsize=7)


def plot_hold(hold: HoldResult, path: str | Path) -> Path:
    """Draw one hold: force and estimate, and the estimate's error."""
    return plot_hold_comparison(HoldComparison({hold.estimator: hold}), path)
