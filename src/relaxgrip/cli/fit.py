"""``relaxgrip fit-relaxation``: fit the relaxation models to a measured CSV record."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json, float_option, int_option
from relaxgrip.errors import InputError
from relaxgrip.experiments.relaxation_fit import (
    RelaxationFitResult,
    fit_relaxation,
    load_relaxation_csv,
)
from relaxgrip.physics.fitting import MAX_PRONY_TERMS, WEIGHTINGS
from relaxgrip.plots.common import check_plot_path
from relaxgrip.plots.relaxation_fit import plot_relaxation_fit

__all__ = ["fit_relaxation_command"]


@app.command("fit-relaxation")
def fit_relaxation_command(
    file: Annotated[
        Path,
        typer.Argument(
            metavar="FILE.csv",
            help="CSV record with columns time_s, displacement_mm, force_n.",
            show_default=False,
        ),
    ],
    window_s: Annotated[
        float | None,
        float_option(
            "--window-s",
            metavar="H",
            help="Fit only the first H seconds of the hold (default: the whole hold).",
            show_default=False,
        ),
    ] = None,
    terms: Annotated[
        int,
        int_option(
            "--terms", metavar="N", help=f"Number of Prony terms (1-{MAX_PRONY_TERMS})."
        ),
    ] = 3,
    weighting: Annotated[
        str,
        typer.Option(
            "--weighting",
            metavar="time|sample",
            help="Least squares over time (trapezoid, the NRMSE norm) or over samples.",
        ),
    ] = "time",
    json_out: Annotated[
        bool, typer.Option("--json", help="Print one JSON object instead of a table.")
    ] = False,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            metavar="PATH",
            help="Also save a figure (.png, .pdf or .svg).",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Fit the reduced model and a Prony series to the hold phase of a relaxation test."""
    # Flags are checked before the file is read so that a typo fails fast, with one line.
    if weighting not in WEIGHTINGS:
        raise InputError(f"--weighting must be one of {', '.join(WEIGHTINGS)}, got {weighting!r}")
    if not 1 <= terms <= MAX_PRONY_TERMS:
        raise InputError(
            f"--terms must be 1-{MAX_PRONY_TERMS}, got {terms} "
            "(each term about triples the fit's search time)"
        )
    if window_s is not None and not window_s > 0:  # also rejects nan
        raise InputError(f"--window-s must be > 0, got {window_s}")
    if plot is not None:
        check_plot_path(plot)

    result = fit_relaxation(
        load_relaxation_csv(file), window_s=window_s, n_terms=terms, weighting=weighting
    )
    if plot is not None:
        plot_relaxation_fit(result, plot)

    if json_out:
        emit_json(result.to_dict())
        return
    console.print(_table(result))
    if plot is not None:
        console.print(f"figure written to {plot}", highlight=False)


def _table(result: RelaxationFitResult) -> Table:
    """Both fits' parameters and scores as a rich table."""
    table = Table(
        title=(
            f"{result.source.name}: hold from {result.hold_start_s:.4g} s, "
            f"{result.weighting}-weighted fit over {result.window_s:.4g} s"
        ),
        caption="reduced: F_inst − K(1 − e^(−t/τ));  Prony: F_eq + Σ k_i e^(−t/τ_i)",
    )
    table.add_column("model")
    table.add_column("parameters")
    table.add_column("NRMSE", justify="right")
    table.add_column("AUC_rel", justify="right")
    reduced, prony = result.reduced, result.prony
    table.add_row(
        "reduced",
        f"F_inst = {reduced.f_inst_n:.5g} N\nK = {reduced.k_n:.5g} N\nτ = {reduced.tau_s:.5g} s",
        f"{result.reduced_nrmse:.5f}",
        f"{result.reduced_auc_rel:.3g}",
    )
    terms = "\n".join(
        f"k{i} = {k:.5g} N, τ{i} = {tau:.5g} s"
        for i, (k, tau) in enumerate(zip(prony.k_n, prony.tau_s, strict=True), 1)
    )
    table.add_row(
        f"Prony ({len(prony.tau_s)} terms)",
        f"F_eq = {prony.f_eq_n:.5g} N\n{terms}",
        f"{result.prony_nrmse:.5f}",
        f"{result.prony_auc_rel:.3g}",
    )
    return table
