"""The paper's accuracy figure (Fig. "acc"), drawn from an :class:`Evaluation`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relaxgrip.learning.evaluation import CurveScore, Evaluation, spread_text
from relaxgrip.metrics import FORCE_RANGES_N
from relaxgrip.plots.common import new_figure, save_figure

__all__ = ["plot_accuracy"]


def _quantile_curves(curves: list[CurveScore], quantiles: tuple[float, ...]) -> list[CurveScore]:
    order = sorted(curves, key=lambda c: c.nrmse)
    return [order[min(len(order) - 1, round(q * (len(order) - 1)))] for q in quantiles]


def plot_accuracy(result: Evaluation, path: str | Path) -> Path:
    """Parity, error by force range, NRMSE and AUC_rel, reconstructions, repeatability."""
    fig = new_figure(13.0, 7.5)
    grid = fig.add_gridspec(2, 4)
    truth, pred = result.icfn_truth_n, result.icfn_predicted_n
    summary = result.icfn_summary()

    ax = fig.add_subplot(grid[0, 0])
    ax.scatter(truth, pred, s=4, alpha=0.35, color="tab:blue", linewidths=0)
    top = float(max(truth.max(), pred.max()))
    ax.plot([0, top], [0, top], color="k", lw=0.8)
    ax.set(xlabel="true force (N)", ylabel="ICFN estimate (N)",
           title=f"(a) ICFN parity: MAE {summary['mae_n']:.3f} N, R² {summary['r2']:.3f}")

    ax = fig.add_subplot(grid[0, 1])
    error = np.abs(pred - truth)
    groups, labels = [], []
    for k, (lo, hi) in enumerate(FORCE_RANGES_N):
        last = k == len(FORCE_RANGES_N) - 1
        inside = (truth >= lo) & ((truth <= hi) if last else (truth < hi))
        groups.append(error[inside] if inside.any() else np.array([np.nan]))
        labels.append(f"{lo:g}–{hi:g}")
    ax.boxplot(groups, tick_labels=labels, showfliers=False)
    ax.set(xlabel="true force range (N)", ylabel="absolute error (N)",
           title="(b) ICFN error by force range")

    rcfn = result.rcfn_summary()
    panels = (("nrmse", "NRMSE", "c"), ("auc_rel", "AUC$_{rel}$", "d"))
    for col, (key, label, tag) in enumerate(panels):
        ax = fig.add_subplot(grid[0, 2 + col])
        values = np.array([getattr(c, key) for c in result.curves])
        ax.hist(values, bins=30, color="tab:orange", alpha=0.8)
        ax.axvline(float(np.median(values)), color="k", lw=1, ls="--",
                   label=f"median {rcfn[key + '_median']:.3f}\nmean {rcfn[key + '_mean']:.3f}")
        ax.set(xlabel=label, ylabel="sequences", title=f"({tag}) RCFN {label}")
        ax.legend(frameon=False)

    ax = fig.add_subplot(grid[1, 0:2])
    colours = ("tab:green", "tab:blue", "tab:red")
    for q, curve, colour in zip((0.0, 0.5, 0.9), _quantile_curves(result.curves, (0.0, 0.5, 0.9)),
                                colours, strict=True):
        ax.plot(curve.t_s, curve.truth_n, color=colour, lw=1.5,
                label=f"q={q:g}: truth (seq {curve.sequence}, {curve.temp_set_c:g} °C)")
        ax.plot(curve.t_s, curve.predicted_n, color=colour, lw=1.2, ls="--",
                label=f"q={q:g}: RCFN, NRMSE {curve.nrmse:.3f}")
    ax.set(xlabel="time since onset (s)", ylabel="force (N)",
           title="(e) reconstructions at NRMSE quantiles 0.0 / 0.5 / 0.9")
    ax.legend(frameon=False, fontsize=7, ncol=2)

    ax = fig.add_subplot(grid[1, 2:4])
    stats = result.repeatability_summary()
    for (temp, group), colour in zip(result.repeat_groups.items(), colours, strict=False):
        t = group[0].t_s
        truths = np.array([np.interp(t, c.t_s, c.truth_n) for c in group])
        preds = np.array([np.interp(t, c.t_s, c.predicted_n) for c in group])
        ax.fill_between(t, truths.min(axis=0), truths.max(axis=0), color=colour, alpha=0.25)
        ax.plot(t, preds.mean(axis=0), color=colour, ls="--", lw=1.2)
        s = stats[temp]
        ax.plot(t, truths.mean(axis=0), color=colour, lw=1.5,
                label=f"{temp} °C: NRMSE {s['nrmse_mean']:.3f}±{s['nrmse_std']:.3f}, "
                      f"{spread_text(s)}")
    ax.set(xlabel="time since onset (s)", ylabel="force (N)",
           title="(f) repeatability: six holds per temperature (band: truth, dashed: RCFN)")
    ax.legend(frameon=False, fontsize=7)
    fig.suptitle(f"Force perception and relaxation accuracy ({result.split} split)")
    return save_figure(fig, path)
