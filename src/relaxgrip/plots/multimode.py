"""The multimode figure (paper Fig. "modes" b): each contrast, the same grasp in two modes."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from relaxgrip.experiments.multimode import MultimodeResult, SqueezeRun
from relaxgrip.experiments.stiffness_modulation import GraspRun
from relaxgrip.plots.common import check_plot_path, new_figure, save_figure
from relaxgrip.plots.stiffness_modulation import MODE_COLORS
from relaxgrip.twin import get_object

__all__ = ["plot_multimode"]


def plot_multimode(result: MultimodeResult, path: str | Path) -> Path:
    """Draw the paper's Fig. "modes" b, one column per contrast.

    Top: the true contact force of each mode over the grasp (with the can's
    yield force and, for the pinch and the box, the force friction alone
    would need at zero tilt).  Bottom: the object's height (the arm's while
    the grip carries it, zero once it is back on the table) and where the
    truth had it slipping.

    Parameters
    ----------
    result : MultimodeResult
        Output of :func:`relaxgrip.experiments.multimode.run_multimode`.
    path : str or pathlib.Path
        Output file (``.png``, ``.pdf`` or ``.svg``).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = check_plot_path(path)
    tasks = result.tasks()
    fig = new_figure(15.0, 7.5)
    grid = fig.add_gridspec(2, 3)
    columns: list[tuple[str, str, Mapping[str, GraspRun | SqueezeRun]]] = [
        ("pinch-1kg", "1 kg weight, pinched on the distal pads at 10 N", result.pinch),
        ("can", "empty aluminium can, same closure", result.can),
        ("adhesive", "flat box (μ 0.2), adhesive vs force closure", result.adhesive),
    ]
    for j, (name, title, runs) in enumerate(columns):
        top = fig.add_subplot(grid[0, j])
        bottom = fig.add_subplot(grid[1, j], sharex=top)
        for mode, run in runs.items():
            t, force, height, slipping = _series(run)
            color = MODE_COLORS.get(mode)
            top.plot(t, force, color=color, lw=1.3, label=_label(name, mode, run))
            bottom.plot(t, height, color=color, lw=1.3, label=mode)
            if slipping.any():
                bottom.plot(t[slipping], np.zeros(int(slipping.sum())), "|", color=color, ms=8)
        first = next(iter(runs.values()))
        obj = get_object(first.object_name)
        if np.isfinite(obj.yield_force_n):
            top.axhline(obj.yield_force_n, color="k", lw=0.7, ls="--",
                        label=f"yield {obj.yield_force_n:g} N")
        if name != "can":
            need = obj.weight_n / (2.0 * obj.friction_coeff)
            top.axhline(need, color="0.4", lw=0.7, ls=":",
                        label=f"friction alone, no tilt: {need:.1f} N")
        verdict = "holds" if tasks[name].success else "does not hold"
        top.set_title(f"{title}\ncontrast {verdict}", fontsize=9)
        top.set_ylabel("true force (N)")
        top.legend(loc="lower right", fontsize=7)
        bottom.set_xlabel("time (s)")
        bottom.set_ylabel("object height (mm)")
        bottom.legend(loc="upper left", fontsize=7)
    fig.suptitle(f"Multimode grasping, seed {result.seed} "
                 f"({result.twin_version}{', quick' if result.quick else ''})")
    return save_figure(fig, path)


def _series(run: GraspRun | SqueezeRun) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                 NDArray[np.float64], NDArray[np.bool_]]:
    """Time, true force, object height and slipping of either kind of run."""
    if isinstance(run, GraspRun):
        lifted = run.loop["truth_lifted"] == 1.0
        height = np.where(lifted, run.loop["arm_mm"], 0.0)
        return run.t_s, run.loop["truth_force_n"], height, run.slipping
    height = np.where(run.lifted, run.arm_mm, 0.0)
    return run.t_s, run.truth_n, height, run.slipping


def _label(name: str, mode: str, run: GraspRun | SqueezeRun) -> str:
    if isinstance(run, SqueezeRun):
        return f"{mode}: {'crushed' if run.is_crushed else 'intact'}, " \
               f"{'held' if run.held else 'dropped'}"
    held = run.criteria()
    ok = held["lifted_and_held"] and held["no_slip"]
    return f"{mode}: {'held' if ok else 'slipped/dropped'}"
