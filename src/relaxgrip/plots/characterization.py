"""The deformation figure of the stiffness characterization (paper Fig. "deform")."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from relaxgrip.experiments.characterization import Characterization
from relaxgrip.plots.common import check_plot_path, new_figure, save_figure

__all__ = ["plot_characterization"]


def plot_characterization(result: Characterization, path: str | Path) -> Path:
    """Draw ``z(x)`` per load and temperature, local stiffness and ``A_z`` maps.

    Top row: one panel per load with the deformation profile at every
    temperature (blue cold to red hot), the 80 mm station marked.  Bottom:
    local stiffness at the sweep load over contact position and temperature,
    and ``A_z`` over load and temperature.

    Parameters
    ----------
    result : Characterization
        Output of :func:`relaxgrip.experiments.characterization.characterize`.
    path : str or pathlib.Path
        Output file (``.png``, ``.pdf`` or ``.svg``).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = check_plot_path(path)
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm

    n_loads = len(result.loads_n)
    fig = new_figure(3.0 * max(n_loads, 2), 6.4)
    grid = fig.add_gridspec(2, max(n_loads, 2))
    cmap = colormaps["coolwarm"]
    temps = result.temps_c
    colours = cmap(np.linspace(0.0, 1.0, len(temps)))
    x_mm = result.x_m * 1e3
    zmax = float(result.profiles_m.max()) * 1e3 * 1.05
    for i, load in enumerate(result.loads_n):
        ax = fig.add_subplot(grid[0, i])
        for k, temp in enumerate(temps):
            ax.plot(x_mm, result.profiles_m[i, k] * 1e3, color=colours[k], label=f"{temp:g} °C")
        ax.axvline(80.0, color="0.6", lw=0.8, ls=":")
        ax.axvline(result.contact_m * 1e3, color="0.3", lw=0.8, ls="--")
        ax.set_title(f"{load:g} N")
        ax.set_xlabel("x (mm)")
        ax.set_ylim(0.0, zmax)
        if i == 0:
            ax.set_ylabel("z (mm)")
            ax.legend(fontsize=7, frameon=False)

    half = max(n_loads, 2) // 2
    ax = fig.add_subplot(grid[1, :half])
    mesh = ax.pcolormesh(temps, result.positions_m * 1e3, result.local_stiffness_n_per_m / 1e3,
                         shading="nearest", cmap="viridis", norm=LogNorm())
    fig.colorbar(mesh, ax=ax, label="local stiffness (N/mm)")
    ax.set_xlabel("temperature (°C)")
    ax.set_ylabel("contact position (mm)")
    ax.set_title(f"local stiffness F/z(a) at {result.position_load_n:g} N")

    ax = fig.add_subplot(grid[1, half:])
    for i, load in enumerate(result.loads_n):
        ax.plot(temps, result.area_m2[i] * 1e6, marker="o", ms=3, label=f"{load:g} N")
    ax.axvline(48.0, color="0.5", ls=":", lw=0.8)
    ax.set_xlabel("temperature (°C)")
    ax.set_ylabel("A_z (mm²)")
    ax.set_title("global deformation A_z")
    ax.legend(fontsize=7, frameon=False)
    fig.suptitle(f"Finger stiffness characterization ({result.twin_version})")
    return save_figure(fig, path)
