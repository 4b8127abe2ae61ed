"""The stiffness-modulation figure (paper Fig. "grasp"): contacts a–c, their peaks, grasps d–f."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from relaxgrip.control.phases import PHASES, GraspPhase
from relaxgrip.experiments.stiffness_modulation import (
    ContactRun,
    GraspRun,
    StiffnessModulationResult,
)
from relaxgrip.plots.common import check_plot_path, new_figure, save_figure

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["MODE_COLORS", "plot_stiffness_modulation"]

#: One colour per stiffness mode (the paper's: stiff blue, compliant red).
MODE_COLORS = {"stiff": "tab:blue", "medium": "tab:purple", "compliant": "tab:red",
               "adhesive": "tab:orange"}
_PHASE_SHADES = {GraspPhase.OPEN: "0.97", GraspPhase.CLOSE: "0.92", GraspPhase.HOLD: "0.86",
                 GraspPhase.LIFT: "0.92", GraspPhase.SUSTAIN: "0.97"}
_LETTERS = "abcdef"


def plot_stiffness_modulation(result: StiffnessModulationResult, path: str | Path) -> Path:
    """Draw the paper's Fig. "grasp".

    Top row (a–c): per contact object, the true force (solid) and the ICFN
    estimate (dashed) over the stroke at each stiffness state.  Middle row:
    per object and state, the peak force and the peak force rate (true and
    estimated) and the perceived peak deflection.  Bottom row (d–f): per
    grasp, the true force and the estimate through the phases, the target and
    its band.

    Parameters
    ----------
    result : StiffnessModulationResult
        Output of :func:`relaxgrip.experiments.stiffness_modulation.run_stiffness_modulation`.
    path : str or pathlib.Path
        Output file (``.png``, ``.pdf`` or ``.svg``).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = check_plot_path(path)
    objects = result.objects()
    grasps = list(result.grasps.items())
    n_cols = max(len(objects), len(grasps), 3)
    fig = new_figure(4.6 * n_cols, 12.0)
    grid = fig.add_gridspec(3, n_cols)
    for j, obj in enumerate(objects):
        _contact_panel(fig.add_subplot(grid[0, j]), f"({_LETTERS[j]}) {obj}",
                       result.contact_runs(obj))
    _peak_panel(fig.add_subplot(grid[1, 0]), result, "peak_true_n", "peak_est_n",
                "peak force (N)", "peak force per state")
    _peak_panel(fig.add_subplot(grid[1, 1]), result, "peak_true_rate_n_per_s",
                "peak_est_rate_n_per_s", "peak force rate (N/s)", "peak force rate per state")
    _peak_panel(fig.add_subplot(grid[1, 2]), result, "peak_deflection_m", None,
                "peak marker deflection (m)", "perceived deflection (the sensing signal)")
    for j, (name, run) in enumerate(grasps):
        _grasp_panel(fig.add_subplot(grid[2, j]), f"({_LETTERS[3 + j]}) {name}", run)
    fig.suptitle(f"Force perception under stiffness modulation, seed {result.seed} "
                 f"({result.twin_version}{', quick' if result.quick else ''})")
    return save_figure(fig, path)


def _contact_panel(ax: Axes, title: str, runs: tuple[ContactRun, ...]) -> None:
    for run in runs:
        color = MODE_COLORS.get(run.mode)
        f = run.figures()
        label = f"{run.mode} {f['temp_c']:.0f} °C"
        ax.plot(run.t_s, run.truth_n, color=color, lw=1.4, label=f"{label} true")
        ax.plot(run.t_s, run.estimate_n, color=color, lw=1.0, ls="--", label=f"{label} ICFN")
    ax.axvline(0.0, color="k", lw=0.5, ls=":")
    ax.set_xlim(-runs[0].stroke.rest_s, float(runs[0].t_s[-1]))
    ax.set_xlabel("time since the press starts (s)")
    ax.set_ylabel("force (N)")
    detected = "all detected" if all(r.detected for r in runs) else \
        "detected: " + ", ".join(r.mode for r in runs if r.detected)
    ax.set_title(f"{title}: {runs[0].stroke.travel_mm:g} mm stroke ({detected})", fontsize=9)
    ax.legend(loc="upper right", fontsize=6, ncol=2)


def _peak_panel(ax: Axes, result: StiffnessModulationResult, true_key: str,
                est_key: str | None, ylabel: str, title: str) -> None:
    objects = result.objects()
    width = 0.8 / 3
    for k, obj in enumerate(objects):
        for i, run in enumerate(result.contact_runs(obj)):
            f = run.figures()
            x = k + (i - 1) * width
            color = MODE_COLORS.get(run.mode)
            ax.bar(x, f[true_key], width * 0.9, color=color,
                   label=run.mode if k == 0 else None)
            if est_key is not None:
                ax.plot([x], [f[est_key]], marker="o", mfc="white", mec="k", ms=4, ls="none",
                        label="ICFN estimate" if k == 0 and i == 0 else None)
    ax.set_xticks(np.arange(len(objects)), objects)
    ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper left", fontsize=7)


def _grasp_panel(ax: Axes, title: str, run: GraspRun) -> None:
    t = run.t_s
    phases = run.loop["phase"].astype(int)
    starts = np.flatnonzero(np.diff(phases, prepend=-1))
    for a, b in zip(starts, [*starts[1:], t.size - 1], strict=True):
        phase = PHASES[phases[a]]
        if phase in _PHASE_SHADES:
            ax.axvspan(t[a], t[b], color=_PHASE_SHADES[phase], zorder=0)
            ax.text(0.5 * (t[a] + t[b]), 1.0, phase.value, transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=6)
    color = MODE_COLORS.get(run.mode)
    ax.plot(t, run.loop["truth_force_n"], color=color, lw=1.3, label="true force")
    ax.plot(t, run.loop["estimate_n"], color="k", lw=0.9, ls="--",
            label=f"{run.estimator} estimate")
    ax.axhline(run.target_n, color="k", lw=0.6, ls=":", label="target")
    ax.axhspan(run.target_n - run.band_n, run.target_n + run.band_n, color=color, alpha=0.12,
               label=f"±{run.band_n:g} N band")
    verdict = "success" if run.success else "failed: " + ", ".join(
        k for k, v in run.criteria().items() if not v)
    ax.set_title(f"{title}, {run.mode}, {run.target_n:g} N ({verdict})", fontsize=9, pad=12)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (N)")
    ax.set_ylim(bottom=0.0, top=max(1.5 * run.target_n, float(np.nanmax(run.loop["truth_force_n"]))
                                    * 1.1))
    ax.legend(loc="lower right", fontsize=6)
