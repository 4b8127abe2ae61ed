"""``relaxgrip bringup RIG.toml --out DIR``: data, models, calibration and a report for a rig."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from relaxgrip.cli._app import app, console, emit_json, err_console, float_option, int_option

if TYPE_CHECKING:
    from relaxgrip.bringup import Bringup


@app.command("bringup")
def bringup_command(
    rig: Annotated[Path, typer.Argument(help="The rig file (docs/rig-file.md).",
                                        show_default=False)],
    out: Annotated[Path, typer.Option("--out", help="Bring-up directory (made, or resumed).",
                                      show_default=False)],
    backend: Annotated[str, typer.Option(
        "--backend", help="twin (the rig's twin, unattended) or serial:RIG.toml (the rig "
                          "itself: the operator is told each step).")] = "twin",
    seed: Annotated[int, int_option("--seed", help="Seed of the plan and the twin's runs.")
                    ] = 0,
    takes: Annotated[int, int_option("--takes", help="Data holds of the plan (4-400).")] = 24,
    hold_s: Annotated[float, float_option("--hold-s", help="Length of every hold (s).")] = 100.0,
    calibration_holds: Annotated[int, int_option(
        "--calibration-holds", help="Regulated holds of the calibration (4-12).")] = 12,
    json_out: Annotated[bool, typer.Option("--json", help="Print the results as JSON.")] = False,
) -> None:
    """Record a rig's holds with its force reference, train and calibrate its models, report.

    DIR/models is then a model directory for --models (its observer in DIR/models/observer),
    DIR/report.md says how well the models do on the held-out recordings.  Stopped (Ctrl-C,
    a fault), it resumes where it stopped when run again with the same arguments.
    """
    from relaxgrip.bringup import Bringup

    start = time.perf_counter()
    if backend == "twin":
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), console=err_console, transient=json_out) as bar:
            task = bar.add_task("bring-up", total=None)

            def progress(step: str, done: int, total: int) -> None:
                bar.update(task, completed=done, total=total, description=f"bring-up: {step}")

            job = Bringup(rig, out, backend, seed, takes, hold_s, calibration_holds,
                          progress=progress)
            results = _run(job)
    else:
        def tell(step: str, done: int, total: int) -> None:
            err_console.print(f"[{done}/{total}] {step}", markup=False, highlight=False)

        def prompt(instruction: str) -> None:
            err_console.print(f"next: {instruction}", markup=False, highlight=False)
            console.input("press Enter when ready (Ctrl-C stops; run again to resume) ")

        job = Bringup(rig, out, backend, seed, takes, hold_s, calibration_holds,
                      progress=tell, prompt=prompt)
        results = _run(job)
    if json_out:
        emit_json({"out": str(out), "seconds": time.perf_counter() - start, **results})
        return
    report = results["report"]
    console.print(f"{out}/report.md: ICFN MAE {report['icfn']['mae_n']:.3f} N on the "
                  f"{report['split']} recordings; models in {out}/models "
                  f"({time.perf_counter() - start:.0f} s)")


def _run(job: Bringup) -> dict[str, Any]:
    try:
        return job.run()
    except KeyboardInterrupt:
        err_console.print(f"interrupted: motor stopped, heaters off; {len(job.state.done)} of "
                          f"{len(job.steps())} steps done, run the same command again to "
                          "resume", markup=False, highlight=False)
        raise typer.Exit(130) from None
