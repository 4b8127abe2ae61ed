"""The integrated demonstration's figure (Fig. "cup" f–h): force, temperatures, SMP modulus."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from relaxgrip.experiments.cup_demo import CupDemoResult
from relaxgrip.plots.common import check_plot_path, new_figure, save_figure

if TYPE_CHECKING:
    from matplotlib.axes import Axes

__all__ = ["plot_cup_demo"]

_STAGES = ("S1 IR sensing", "S2 approach", "S3 compliant grasp, pour", "S4 stiffening",
           "S5 glass hand-over")
_SHADES = ("#e8eef7", "#eef7e8", "#f7efe3", "#efe8f7", "#f7e8ec")
_FINGER_COLORS = ("tab:blue", "tab:orange")


def _stages(ax: Axes, result: CupDemoResult, label: bool) -> None:
    for k, (lo, hi) in enumerate(result.stages_s):
        ax.axvspan(lo, hi, color=_SHADES[k], zorder=0, lw=0)
        if label:
            ax.text(0.5 * (lo + hi), 1.01, f"S{k + 1}", transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=8)


def plot_cup_demo(result: CupDemoResult, path: str | Path) -> Path:
    """Draw the integrated demonstration.

    Top: the force estimate and the true force over the whole sequence,
    the target while one is set, stages S1–S5 shaded.  Then, per finger, the
    mean temperature the infrared camera reads with its spread along the
    finger (minimum to maximum over the face) shaded, and the storage modulus
    of the SMP at that temperature (right axis, red dashed); the dotted line
    marks Tg.

    Parameters
    ----------
    result : CupDemoResult
        Output of :func:`relaxgrip.experiments.cup_demo.run_cup_demo`.
    path : str or pathlib.Path
        Output file (``.png``, ``.pdf`` or ``.svg``).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = check_plot_path(path)
    t = result["t_s"]
    fig = new_figure(11.0, 8.0)
    ax_f, ax_0, ax_1 = fig.subplots(3, 1, sharex=True, height_ratios=(1.3, 1.0, 1.0))
    _stages(ax_f, result, label=True)
    # The estimate means something while a grasp is under way (not while opening wide).
    estimate = np.where(np.isfinite(result["target_n"]), result["estimate_n"], np.nan)
    ax_f.plot(t, result["truth_force_n"], color="tab:blue", lw=1.1, label="true force")
    ax_f.plot(t, estimate, color="tab:orange", lw=1.0, ls="--", label="estimate")
    ax_f.plot(t, result["target_n"], color="k", lw=0.7, ls=":", label="target")
    push = result["push_n"]
    if np.any(push > 0):
        ax_f.plot(t, np.where(push > 0, push, np.nan), color="tab:purple", lw=0.9,
                  label="hand's push")
    ax_f.axhline(result.figures.get("cup_yield_n", np.nan), color="tab:red", lw=0.6, ls="-.",
                 label="paper cup yield")
    ax_f.set_ylabel("force (N)")
    ax_f.set_ylim(bottom=-0.3)
    ax_f.legend(loc="upper left", fontsize=7, ncol=3)
    ax_f.set_title(
        f"(f) force over the sequence: chose the {result.chosen_side or 'no'} cup "
        f"(IR {', '.join(f'{k} {v:.1f} °C' for k, v in result.ir_cup_temps_c.items())}; "
        f"background {result.ir_background_c:.1f} °C)", fontsize=9, pad=14)
    tg_c = 48.0
    for j, ax in ((0, ax_0), (1, ax_1)):
        _stages(ax, result, label=False)
        color = _FINGER_COLORS[j]
        lo, hi = result[f"ir_min_{j}_c"], result[f"ir_max_{j}_c"]
        ax.fill_between(t, lo, hi, color=color, alpha=0.25, lw=0, label="spread along finger")
        ax.plot(t, result[f"ir_mean_{j}_c"], color=color, lw=1.2, label="IR mean")
        ax.axhline(tg_c, color="k", lw=0.7, ls=":", label="Tg ≈ 48 °C")
        ax.set_ylabel(f"finger {j} (°C)")
        twin = ax.twinx()
        twin.plot(t, result[f"modulus_{j}_pa"] * 1e-6, color="tab:red", lw=1.0, ls="--",
                  label="SMP E'")
        twin.set_ylabel("E' (MPa)", color="tab:red")
        twin.set_yscale("log")
        lines, labels = ax.get_legend_handles_labels()
        l2, lab2 = twin.get_legend_handles_labels()
        ax.legend(lines + l2, labels + lab2, loc="upper right", fontsize=7, ncol=2)
    ax_0.set_title("(g, h) finger temperatures (infrared) and the SMP storage modulus they give",
                   fontsize=9)
    ax_1.set_xlabel("time (s)")
    fig.suptitle(f"Integrated demonstration, seed {result.seed} ({result.twin_version})")
    return save_figure(fig, path)
