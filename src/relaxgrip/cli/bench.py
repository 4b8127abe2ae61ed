"""``relaxgrip bench``: speed and latency benchmarks (medians of repeated runs)."""

from __future__ import annotations

from contextlib import nullcontext
from typing import Annotated, Any

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
    profile: Annotated[bool, typer.Option(
        "--profile", help="Also run each benchmark once under cProfile and list its functions "
                          "with the most self time.")] = False,
    compare: Annotated[str | None, typer.Option(
        "--compare", metavar="REF",
        help="Also run the same benchmarks on git ref REF (a temporary worktree, its own "
             "PYTHONPATH, a subprocess) and print the speed-up.")] = None,
) -> None:
    """Measure how fast the twin and the pipeline run (all benchmarks by default).

    Every benchmark reports its median, min and max over --repeat runs and its median as a
    multiple of a fixed NumPy reference workload timed in the same run (``reference_ratio``),
    which two machines or two loads can compare.

    ``relaxgrip bench faults`` injects every fault on every backend instead and prints the
    time each takes to reach the safe state (motor stopped, heaters off): the median and the
    maximum over --repeat holds (twin seeds 5000 on), against 200 ms plus one control period.
    """
    if names and "faults" in names:
        if names != ["faults"]:
            raise InputError("bench faults runs alone: give it without other benchmarks")
        if profile or compare is not None:
            raise InputError("bench faults takes neither --profile nor --compare")
        if not 1 <= repeat <= 100:
            raise InputError(f"--repeat must be 1-100 holds for faults, got {repeat}")
        _bench_faults(repeat, json_out)
        return
    chosen = names or list(DEFAULT_BENCHMARKS)
    unknown = [n for n in chosen if n not in BENCHMARKS]
    if unknown:
        raise InputError(f"unknown benchmark {unknown[0]!r}; known: {', '.join(BENCHMARKS)}")
    if not 1 <= repeat <= MAX_REPEAT:
        raise InputError(f"--repeat must be 1-{MAX_REPEAT}, got {repeat}")
    there = None
    if compare is not None:
        from relaxgrip.bench.compare import run_on_ref

        # The ref first: one that does not run fails before minutes of benchmarks here.
        there = run_on_ref(compare, chosen, repeat)
    report = run_benchmarks(chosen, repeat, profile=profile)
    rows = None
    if compare is not None and there is not None:
        from relaxgrip.bench.compare import compare_reports

        rows = compare_reports(report, there)
        report["compare"] = {"ref": compare, "commit": there["commit"],
                             "ref_twin_version": there.get("twin_version"),
                             "ref_reference_s": there["reference_s"], "benchmarks": rows,
                             "ref_report": there}
    if json_out:
        emit_json(report)
        return
    table = Table(title=f"relaxgrip bench ({report['twin_version']}, median of {repeat} runs)",
                  caption=f"× ref: the median over the NumPy reference workload's "
                          f"({format_duration(report['reference_s'])} in this run)")
    for col in ("benchmark", "median", "min", "max", "× ref", "× real time", "notes"):
        table.add_column(col, justify="left" if col in ("benchmark", "notes") else "right")
    for r in report["benchmarks"]:
        rt = r["realtime_factor"]
        extra = {k: v for k, v in r.items() if k not in {
            "name", "description", "runs", "median_s", "min_s", "max_s", "simulated_s",
            "realtime_factor", "profile", "reference_ratio"}}
        table.add_row(
            r["name"], format_duration(r["median_s"]), format_duration(r["min_s"]),
            format_duration(r["max_s"]), f"{r['reference_ratio']:.3g}",
            "" if rt is None else f"{rt:,.0f}×",
            ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}"
                      for k, v in extra.items()),
        )
    console.print(table)
    if profile:
        for r in report["benchmarks"]:
            _print_profile(r["name"], r["profile"])
    if rows is not None:
        _print_comparison(report["compare"])


def _print_profile(name: str, entries: list[dict[str, Any]]) -> None:
    table = Table(title=f"{name}: functions by self time (one run under cProfile)")
    for col in ("function", "calls", "self", "share", "cumulative"):
        table.add_column(col, justify="left" if col == "function" else "right")
    for e in entries:
        table.add_row(e["function"], str(e["calls"]), format_duration(e["self_s"]),
                      f"{100 * e['self_share']:.1f} %", format_duration(e["cumulative_s"]))
    console.print(table)


def _print_comparison(compare: dict[str, Any]) -> None:
    table = Table(title=f"against {compare['ref']} ({compare['commit'][:10]}, "
                        f"{compare['ref_twin_version']})",
                  caption="speed-up: the ref's median over this one's; normalised: each "
                          "median over the reference workload timed beside it first")
    for col in ("benchmark", f"{compare['ref']}", "this", "speed-up", "normalised"):
        table.add_column(col, justify="left" if col == "benchmark" else "right")
    for row in compare["benchmarks"]:
        table.add_row(row["name"], format_duration(row["ref_median_s"]),
                      format_duration(row["median_s"]), f"{row['speedup']:.2f}×",
                      f"{row['speedup_normalised']:.2f}×")
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


def _bench_faults(repeat: int, json_out: bool) -> None:
    """The fault matrix (:mod:`relaxgrip.experiments.fault_matrix`), one hold per seed."""
    from relaxgrip.experiments.fault_matrix import (
        BACKENDS,
        BUDGET_S,
        FAULTS,
        FaultCell,
        run_fault_matrix,
    )

    seeds = list(range(5000, 5000 + repeat))
    done = [0]
    total = len(FAULTS) * len(BACKENDS) * repeat
    with console.status(f"fault matrix: {total} cells …") if not json_out \
            else nullcontext() as status:

        def progress(cell: FaultCell) -> None:
            done[0] += 1
            if status is not None:
                status.update(f"fault matrix: {done[0]}/{total}, {cell.fault} on "
                              f"{cell.backend} done …")

        matrix = run_fault_matrix(seeds=seeds, on_cell=progress)
    ok, cells = matrix.passed
    if json_out:
        emit_json(matrix.to_dict())
    else:
        seed_text = f"{seeds[0]}" if repeat == 1 else f"{seeds[0]}-{seeds[-1]}"
        table = Table(title=f"Fault matrix ({matrix.twin_version}, seeds {seed_text}): time to "
                            "motor stopped and heaters off, median / max (ms)",
                      caption=f"budget {BUDGET_S * 1e3:.0f} ms (200 ms + one 33 ms period), "
                              "virtual time, timed from when the fault is one (a camera's "
                              "stall from its limit: the allowance after the injection)")
        table.add_column("fault", no_wrap=True)
        for backend in matrix.backends:
            table.add_column(backend, justify="right")
        table.add_column("allowance", justify="right")
        table.add_column("reason (last backend)")
        for fault in matrix.faults:
            row, allowance, reason = [fault], 0.0, ""
            for backend in matrix.backends:
                s = matrix.summary(fault, backend)
                if "unsupported" in s:
                    row.append("n/a")
                    continue
                mark = "" if s["ok"] else " FAIL"
                row.append(f"{s['median_s'] * 1e3:.1f} / {s['max_s'] * 1e3:.1f}{mark}")
                allowance, reason = max(allowance, s["allowance_s"]), s["reason"]
            table.add_row(*row, f"{allowance:.3g} s" if allowance > 0.05 else "",
                          reason[:90] + ("…" if len(reason) > 90 else ""))
        console.print(table)
        console.print(f"{ok} of {cells} cells reach the safe state within "
                      f"{BUDGET_S * 1e3:.0f} ms in every run, a one-line reason given and the "
                      "recording closed complete (n/a: the fault does not exist there)",
                      markup=False, highlight=False)
    if ok < cells:
        raise typer.Exit(1)
