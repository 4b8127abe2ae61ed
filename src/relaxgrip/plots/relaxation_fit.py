"""Figure of a relaxation fit: measured hold-phase force, both models, residuals."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relaxgrip.experiments.relaxation_fit import RelaxationFitResult
from relaxgrip.plots.common import check_plot_path, new_figure, save_figure

__all__ = ["plot_relaxation_fit"]


def plot_relaxation_fit(result: RelaxationFitResult, path: str | Path) -> Path:
    """Draw the measured hold-phase force with both fits, and their residuals.

    Time since the hold start is on a logarithmic axis (relaxation spans
    decades); the first hold sample, at ``t = 0``, cannot be shown there and
    is left out.  The fitted window is shaded when it is shorter than the hold.

    Parameters
    ----------
    result : RelaxationFitResult
        Output of :func:`relaxgrip.experiments.relaxation_fit.fit_relaxation`.
    path : str or pathlib.Path
        Output file, ``.png``, ``.pdf`` or ``.svg``.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    relaxgrip.errors.InputError
        If the format is unsupported or the directory does not exist, see
        :func:`relaxgrip.plots.common.check_plot_path`.
    """
    path = check_plot_path(path)
    shown = result.time_s > 0
    t = result.time_s[shown]
    f = result.force_n[shown]
    reduced = result.reduced
    prony = result.prony
    curves = (
        (
            result.reduced_force_n[shown],
            "C1",
            f"reduced: τ = {reduced.tau_s:.3g} s, NRMSE = {result.reduced_nrmse:.4f}",
        ),
        (
            result.prony_force_n[shown],
            "C2",
            f"Prony, {len(prony.tau_s)} terms: τ = "
            + ", ".join(f"{tau:.3g}" for tau in prony.tau_s)
            + f" s, NRMSE = {result.prony_nrmse:.4f}",
        ),
    )

    fig = new_figure(8.0, 6.0)
    ax_f, ax_r = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    ax_f.plot(t, f, ".", color="0.4", markersize=2, label="measured")
    for model_n, color, label in curves:
        ax_f.plot(t, model_n, "-", color=color, linewidth=1.5, label=label)
        ax_r.plot(t, model_n - f, "-", color=color, linewidth=1.0)
    ax_r.axhline(0.0, color="0.4", linewidth=0.8)
    if result.window_s < float(result.time_s[-1]):
        for ax in (ax_f, ax_r):
            ax.axvspan(float(np.min(t)), result.window_s, color="0.9", zorder=0)
    ax_f.set_xscale("log")
    ax_f.set_ylabel("force (N)")
    ax_f.set_title(
        f"{result.source.name}: hold from {result.hold_start_s:.4g} s, "
        f"{result.weighting}-weighted fit over {result.window_s:.4g} s"
    )
    ax_f.legend(loc="best", fontsize="small")
    ax_r.set_xlabel("time since hold start (s)")
    ax_r.set_ylabel("model − measured (N)")
    return save_figure(fig, path)
