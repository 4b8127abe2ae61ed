"""``relaxgrip bench``: speed and latency benchmarks (medians of repeated runs)."""

from __future__ import annotations

from typing import Annotated

import typer
from rich.table import Table

from relaxgrip.bench import BENCHMARKS, DEFAULT_BENCHMARKS, run_benchmarks
from relaxgrip.cli._app import app, console, emit_json, int_option
from relaxgrip.errors import InputError

#: The most timed runs per benchmark: a median of more is no surer, and the slower benchmarks
#: (a closed-loop hold, a training) take seconds to minutes a run.
MAX_REPEAT = 1000


@app.command("bench")
def bench(
    names: Annotated[
        list[str] | None, typer.Argument(help=f"Benchmarks to run: {', '.join(BENCHMARKS)} "
                                   f"(default: {', '.join(DEFAULT_BENCHMARKS)}).")
    ] = None,
    repeat: Annotated[int, int_option("--repeat", help="Timed runs per benchmark.")] = 5,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Measure how fast the twin and the pipeline run (all benchmarks by default)."""
    chosen = names or list(DEFAULT_BENCHMARKS)
    unknown = [n for n in chosen if n not in BENCHMARKS]
    if unknown:
        raise InputError(f"unknown benchmark {unknown[0]!r}; known: {', '.join(BENCHMARKS)}")
    if not 1 <= repeat <= MAX_REPEAT:
        raise InputError(f"--repeat must be 1-{MAX_REPEAT}, got {repeat}")
    report = run_benchmarks(chosen, repeat)
    if json_out:
        emit_json(report)
        return
    table = Table(title=f"relaxgrip bench ({report['twin_version']}, median of {repeat} runs)")
    for col in ("benchmark", "median", "min", "max", "× real time", "notes"):
        table.add_column(col, justify="left" if col in ("benchmark", "notes") else "right")
    for r in report["benchmarks"]:
        rt = r["realtime_factor"]
        extra = {k: v for k, v in r.items() if k not in {
            "name", "description", "runs", "median_s", "min_s", "max_s", "simulated_s",
            "realtime_factor"}}
        table.add_row(
            r["name"], format_duration(r["median_s"]), format_duration(r["min_s"]),
            format_duration(r["max_s"]), "" if rt is None else f"{rt:,.0f}×",
            ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                      for k, v in extra.items()),
        )
    console.print(table)


def format_duration(seconds: float) -> str:
    """A duration with three significant figures in a unit that fits (µs, ms or s)."""
    seconds = float(f"{seconds:.3g}")  # rounded before the unit is chosen: 0.9996 s is 1 s
    if seconds >= 1e3:
        return f"{seconds:.0f} s"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.3g} µs"
    if seconds < 1.0:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds:.3g} s"
