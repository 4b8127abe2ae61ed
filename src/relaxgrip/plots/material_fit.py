"""Figure of a material fit: master curve with the data, shift factors with the law, residuals."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relaxgrip.experiments.material_fit import MaterialFitResult
from relaxgrip.physics.material_fit import model_residuals_log10
from relaxgrip.plots.common import check_plot_path, new_figure, save_figure

__all__ = ["plot_material_fit"]


def plot_material_fit(result: MaterialFitResult, path: str | Path) -> Path:
    """Draw the master curve, the shift factors and the whole model's residuals.

    Top: every measured point at its reduced time (frequency), shifted by the
    fitted law, coloured by temperature, with the Prony series.  Bottom left:
    the automatic shift factors with their standard errors and the fitted
    law.  Bottom right: ``log10`` model minus measured at every point, against
    temperature.

    Parameters
    ----------
    result : MaterialFitResult
        Output of :func:`relaxgrip.experiments.material_fit.fit_material`.
    path : str or pathlib.Path
        Output file, ``.png``, ``.pdf`` or ``.svg``.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = check_plot_path(path)
    meas, mat = result.measurements, result.material
    temps = meas.temps_c
    law_at = mat.shift.log10_at(temps)
    fig = new_figure(11.0, 8.0)
    grid = fig.add_gridspec(2, 2, height_ratios=(3, 2))
    ax_m = fig.add_subplot(grid[0, :])
    ax_s = fig.add_subplot(grid[1, 0])
    ax_r = fig.add_subplot(grid[1, 1])
    cmap = __import__("matplotlib").colormaps["coolwarm"]
    span = max(float(temps.max() - temps.min()), 1e-9)
    lo, hi = np.inf, -np.inf
    for s, a in zip(meas.sets, law_at, strict=True):
        u = np.log10(s.x) + meas.sign * a
        lo, hi = min(lo, u.min()), max(hi, u.max())
        color = cmap((s.temp_c - temps.min()) / span)
        ax_m.plot(10**u, s.y, "o", color=color, markersize=3)
        if s.y2 is not None:
            ax_m.plot(10**u, s.y2, "s", color=color, markersize=2.5, mfc="none")
    x = np.logspace(lo - 0.5, hi + 0.5, 400)
    ref = mat.ref_temp_c
    if meas.domain == "time":
        ax_m.plot(x, mat.relaxation_modulus_pa(x, ref), "k-", linewidth=1.2,
                  label=f"Prony, {len(mat.tau_s)} terms")
        ax_m.set_xlabel(f"reduced time t / a_T (s), at {ref:.1f} °C")
        ax_m.set_ylabel(f"{mat.modulus}(t) (Pa)")
    else:
        ax_m.plot(x, mat.storage_modulus_pa(x, ref), "k-", linewidth=1.2,
                  label=f"Prony, {len(mat.tau_s)} terms: {mat.modulus}′ (o)")
        ax_m.plot(x, mat.loss_modulus_pa(x, ref), "k--", linewidth=1.0,
                  label=f"{mat.modulus}″ (□)")
        ax_m.set_xlabel(f"reduced angular frequency ω a_T (rad/s), at {ref:.1f} °C")
        ax_m.set_ylabel("modulus (Pa)")
    ax_m.set_xscale("log")
    ax_m.set_yscale("log")
    ax_m.legend(loc="best", fontsize="small")
    ax_m.set_title(f"{', '.join(Path(p).name for p in meas.sources) or 'measurements'}: "
                   f"RMS log10 {result.rms_log10:.4f} over {meas.n_points} points")

    ax_s.errorbar(temps, result.log_at_ref, yerr=result.shift.sigma, fmt="o", color="C0",
                  markersize=3, capsize=2, label="overlapping neighbours")
    tt = np.linspace(temps.min(), temps.max(), 200)
    ax_s.plot(tt, mat.shift.log10_at(tt), "-", color="C3",
              label=f"{mat.shift.model} (refined)")
    ax_s.set_xlabel("temperature (°C)")
    ax_s.set_ylabel("log10 a_T")
    ax_s.legend(loc="best", fontsize="small")

    res = model_residuals_log10(mat, meas)
    per_point = np.concatenate([
        np.full(s.y.size + (0 if s.y2 is None else s.y2.size), s.temp_c) for s in meas.sets])
    ax_r.plot(per_point, res, ".", color="0.3", markersize=3)
    ax_r.axhline(0.0, color="0.5", linewidth=0.8)
    ax_r.set_xlabel("temperature (°C)")
    ax_r.set_ylabel("log10 model − log10 measured")
    return save_figure(fig, path)
