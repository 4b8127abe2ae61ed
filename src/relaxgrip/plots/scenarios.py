"""The scenarios figure: ``relax`` and ``observer`` through a ramp, a new target, a push."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relaxgrip.experiments.scenarios import SCENARIOS, ScenarioComparison
from relaxgrip.plots.common import check_plot_path, new_figure, save_figure
from relaxgrip.plots.holding import _COLORS, _thin

__all__ = ["plot_scenarios"]


def plot_scenarios(comparison: ScenarioComparison, path: str | Path) -> Path:
    """Draw each scenario: true force against the target, and each estimate's error.

    Top row: the true force under each estimator and the target over the
    hold, the steady-state interval shaded.  Bottom row: estimate − true
    force, with the observer's 95 % band around its estimate (less the truth).

    Parameters
    ----------
    comparison : ScenarioComparison
        Output of :func:`relaxgrip.experiments.scenarios.compare_scenarios`.
    path : str or pathlib.Path
        Output file (``.png``, ``.pdf`` or ``.svg``).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = check_plot_path(path)
    names = list(comparison.holds)
    n = len(names)
    fig = new_figure(4.4 * max(n, 1), 6.4)
    axes = fig.subplots(2, max(n, 1), squeeze=False, sharex="col")
    for j, name in enumerate(names):
        top, bottom = axes[0, j], axes[1, j]
        runs = comparison.holds[name]
        first = next(iter(runs.values()))
        lo, hi = first.window
        for ax in (top, bottom):
            ax.axvspan(lo, hi, color="0.93", zorder=0)
        idx = _thin(first.t_s)
        top.plot(first.t_s[idx], first.target_t_n[idx], color="k", lw=0.8, ls=":",
                 label="target")
        maes = []
        for est, hold in runs.items():
            idx = _thin(hold.t_s)
            color = _COLORS.get(est)
            mae = hold.metrics()["mae_n"]
            maes.append(f"{est} {mae:.3f}")
            top.plot(hold.t_s[idx], hold.truth_n[idx], color=color, lw=1.1,
                     label=f"true force, {est}")
            bottom.plot(hold.t_s[idx], (hold.estimate_n - hold.truth_n)[idx], color=color,
                        lw=1.0, label=est)
            band_lo, band_hi = hold.series("band_lo_n"), hold.series("band_hi_n")
            if np.isfinite(band_lo).any():
                bottom.fill_between(hold.t_s[idx], (band_lo - hold.truth_n)[idx],
                                    (band_hi - hold.truth_n)[idx], color=color, alpha=0.2,
                                    lw=0, label=f"{est} 95 % band")
        bottom.axhline(0.0, color="k", lw=0.6)
        top.set_title(f"{SCENARIOS[name].describe(comparison.duration_s)}\n"
                      f"MAE (N): {', '.join(maes)}", fontsize=9)
        top.set_ylabel("force (N)")
        bottom.set_ylabel("estimate − true force (N)")
        bottom.set_xlabel("time since hold onset (s)")
        top.legend(loc="lower left", fontsize=7)
        bottom.legend(loc="best", fontsize=7)
    fig.suptitle(f"Beyond Eq. 10: {comparison.duration_s:g} s holds at 5 N, 40 °C until the "
                 f"scenario acts, seed {comparison.seed}")
    return save_figure(fig, path)
