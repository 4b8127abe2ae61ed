"""Figure of a relaxation fit: measured hold-phase force, both models, residuals."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relaxgrip.errors import InputError
from relaxgrip.experiments.relaxation_fit import RelaxationFitResult

__all__ = ["PLOT_FORMATS", "check_plot_path", "plot_relaxation_fit"]

PLOT_FORMATS: tuple[str, ...] = (".png", ".pdf", ".svg")


def check_plot_path(path: str | Path) -> Path:
    """Check that a figure can be written to ``path``.

    Parameters
    ----------
    path : str or pathlib.Path
        Output file; its extension selects the format.

    Returns
    -------
    pathlib.Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    relaxgrip.errors.InputError
        If the extension is not one of :data:`PLOT_FORMATS` or the parent
        directory does not exist (it is not created).
    """
    path = Path(path)
    if path.suffix.lower() not in PLOT_FORMATS:
        raise InputError(
            f"{path}: unsupported plot format {path.suffix or '(none)'!r}; "
            f"use one of {', '.join(PLOT_FORMATS)}"
        )
    if not path.parent.is_dir():
        raise InputError(f"{path}: directory {path.parent} does not exist")
    return path


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
        See :func:`check_plot_path`.
    """
    path = check_plot_path(path)
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

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

    fig = Figure(figsize=(8.0, 6.0), layout="constrained")
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
    fig.savefig(path)
    return path
