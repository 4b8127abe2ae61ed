"""``relaxgrip fit-material``: the finger's material from multi-temperature measurements."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json, float_option, int_option
from relaxgrip.errors import InputError
from relaxgrip.experiments.material_fit import (
    DEFAULT_MAX_TERMS,
    MaterialFitResult,
    fit_material,
    load_measurements,
)
from relaxgrip.fileio import check_writable, write_text_atomically
from relaxgrip.plots.common import check_plot_path

__all__ = ["fit_material_command"]


@app.command("fit-material")
def fit_material_command(
    files: Annotated[list[Path], typer.Argument(
        metavar="FILE.csv...", show_default=False,
        help="Measurements at two or more temperatures: relaxation modulus over time, or "
             "storage and loss modulus over frequency (pyvisco's CSV or the project's; "
             "docs/material.md).")],
    ref_temp_c: Annotated[float | None, float_option(
        "--ref-temp-c", metavar="T", show_default=False,
        help="Reference temperature (°C; default: a measured temperature near the "
             "middle).")] = None,
    max_terms: Annotated[int, int_option(
        "--max-terms", metavar="N",
        help="Most Prony terms the selection tries (1-60).")] = DEFAULT_MAX_TERMS,
    gauge_length_mm: Annotated[float | None, float_option(
        "--gauge-length-mm", metavar="L", show_default=False,
        help="Specimen gauge length, for force_n/displacement_mm records.")] = None,
    area_mm2: Annotated[float | None, float_option(
        "--area-mm2", metavar="A", show_default=False,
        help="Specimen cross-section, for force_n/displacement_mm records.")] = None,
    json_out: Annotated[bool, typer.Option(
        "--json", help="Print one JSON object instead of tables.")] = False,
    plot: Annotated[Path | None, typer.Option(
        "--plot", metavar="PATH", show_default=False,
        help="Also save a figure: master curve, shift factors, residuals "
             "(.png, .pdf or .svg).")] = None,
    out: Annotated[Path | None, typer.Option(
        "--out", metavar="FILE.json", show_default=False,
        help="Write the material file (for --material and a rig file's material =).")] = None,
) -> None:
    """Fit shift factors, a shift law and a Prony series to measurements at several temperatures."""
    if not 1 <= max_terms <= 60:
        raise InputError(f"--max-terms must be 1-60, got {max_terms}")
    if ref_temp_c is not None and not -273.15 < ref_temp_c < 1000.0:  # also rejects nan
        raise InputError(f"--ref-temp-c must be a temperature in °C, got {ref_temp_c}")
    for flag, value in (("--gauge-length-mm", gauge_length_mm), ("--area-mm2", area_mm2)):
        if value is not None and not value > 0:
            raise InputError(f"{flag} must be > 0, got {value}")
    if plot is not None:
        check_plot_path(plot)
    if out is not None:
        if out.suffix.lower() != ".json":
            raise InputError(f"--out {out}: a material file ends in .json")
        check_writable(out, InputError)

    meas = load_measurements(list(files), gauge_length_mm, area_mm2)
    result = fit_material(meas, ref_temp_c=ref_temp_c, max_terms=max_terms)
    if plot is not None:
        from relaxgrip.plots.material_fit import plot_material_fit

        plot_material_fit(result, plot)
    if out is not None:
        write_text_atomically(out, json.dumps(result.material.to_dict(), indent=2) + "\n")
    if json_out:
        emit_json(result.to_dict())
        return
    for table in _tables(result):
        console.print(table)
    for what, path in (("figure", plot), ("material file", out)):
        if path is not None:
            console.print(f"{what} written to {path}", highlight=False)


def _tables(result: MaterialFitResult) -> list[Table]:
    mat = result.material
    d = result.to_dict()
    shift = Table(title=f"shift factors at {mat.ref_temp_c:.2f} °C (log10 a_T)")
    for col in ("T (°C)", "overlap", "±", mat.shift.model):
        shift.add_column(col, justify="right")
    for k, t in enumerate(result.measurements.temps_c):
        key = f"{round(t):d}"
        shift.add_row(f"{t:.1f}", f"{result.log_at_ref[k]:.3f}",
                      f"{result.shift.sigma[k]:.3f}", f"{d['log_aT_model'][key]:.3f}")
    laws = Table(title="shift laws (leave-one-temperature-out error)")
    for col in ("law", "held-out (dec)", "parameters"):
        laws.add_column(col)
    for f in d["shift"]["selection"]:
        params = ", ".join(f"{k} = {v:.4g} ± {f['params_sigma'][k]:.2g}"
                           for k, v in f["params"].items())
        mark = " (chosen)" if f["model"] == mat.shift.model else ""
        laws.add_row(f["model"] + mark, f"{f['heldout_rms_decades']:.3f}", params)
    chosen = ", ".join(f"{k} = {v:.5g} ± {d['shift']['params_sigma'][k]:.2g}"
                       for k, v in d["shift"]["params"].items())
    laws.caption = f"after the joint refinement: {chosen}"
    prony = Table(title=f"Prony series at {mat.ref_temp_c:.2f} °C "
                        f"(E_inf = {mat.e_inf_pa:.5g} Pa)")
    prony.add_column("modulus (Pa)", justify="right")
    prony.add_column("tau (s)", justify="right")
    for e, tau in zip(mat.moduli_pa, mat.tau_s, strict=True):
        prony.add_row(f"{e:.5g}", f"{tau:.4g}")
    prony.caption = (f"{len(mat.tau_s)} terms (target {result.prony.target_log10:.4f}, the "
                     f"master curve's scatter); RMS log10: whole model {result.rms_log10:.4f}, "
                     f"master curve {result.rms_log10_master:.4f}")
    return [shift, laws, prony]
