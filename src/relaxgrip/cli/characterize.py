"""``relaxgrip characterize``: the finger's temperature-dependent stiffness."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json
from relaxgrip.cli._twin import MaterialOption, RigOption, twin_config
from relaxgrip.experiments.characterization import characterize as run_characterization
from relaxgrip.plots.common import check_plot_path


@app.command("characterize")
def characterize(
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    plot: Annotated[
        Path | None, typer.Option("--plot", help="Save the z(x) figure (.png/.pdf/.svg).")
    ] = None,
    rig: RigOption = None,
    material: MaterialOption = None,
) -> None:
    """Characterize finger stiffness over 2-8 N and 27-60 °C (paper Fig. 'deform')."""
    if plot is not None:
        check_plot_path(plot)
    result = run_characterization(twin_config(rig, material=material).finger)
    if plot is not None:
        from relaxgrip.plots.characterization import plot_characterization

        plot_characterization(result, plot)
    if json_out:
        emit_json(result.to_dict())
        return
    t_lo, t_hi = result.temps_c[0], result.temps_c[-1]
    table = Table(
        title=f"Finger characterization, load at {result.contact_m * 1e3:g} mm "
        f"({result.twin_version})",
        caption="k80 = F / z(80 mm) in N/mm; z80 ratio hot/cold; A_z = ∫z dx in mm²",
    )
    for col in ("F (N)", f"k80 {t_lo:g} °C", f"k80 {t_hi:g} °C", "k80 drop", "z80 ratio",
                f"A_z {t_lo:g} °C", f"A_z {t_hi:g} °C"):
        table.add_column(col, justify="right", no_wrap=True)
    for i, load in enumerate(result.loads_n):
        table.add_row(
            f"{load:g}",
            f"{result.k80_n_per_m[i, 0] / 1e3:.3f}",
            f"{result.k80_n_per_m[i, -1] / 1e3:.3f}",
            f"{result.k80_drop_pct[i]:.1f} %",
            f"×{result.z80_ratio[i]:.2f}",
            f"{result.area_m2[i, 0] * 1e6:.0f}",
            f"{result.area_m2[i, -1] * 1e6:.0f}",
        )
    console.print(table)
    console.print("paper: k80 drop 35-45 %, z80 ×1.6-1.7, A_z at 8 N 361 -> 626 mm²")
    if plot is not None:
        console.print(f"figure: {plot}")
