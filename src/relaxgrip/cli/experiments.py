"""``relaxgrip task NAME`` and ``relaxgrip reproduce``: the paper's experiments on the twin."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json, err_console, int_option
from relaxgrip.cli._twin import MaterialOption, RigOption, twin_config
from relaxgrip.errors import InputError

if TYPE_CHECKING:
    from relaxgrip.experiments.tasks import TaskResult


@app.command("task")
def task(
    name: Annotated[str, typer.Argument(
        help="hammer, orange, balloon, feather, brush, wrench, pinch-1kg, can, adhesive or cup.",
        show_default=False)],
    seed: Annotated[int, int_option("--seed", help="Twin seed.")] = 0,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    rig: RigOption = None,
    material: MaterialOption = None,
) -> None:
    """Run one of the paper's grasping tasks on the twin and check its success criteria.

    Exits 1 when a criterion does not hold.
    """
    from relaxgrip.experiments.tasks import task_function

    if seed < 0:
        raise InputError(f"--seed must be >= 0, got {seed}")
    run = task_function(name)
    result = run(seed=seed, config=twin_config(rig, material=material))
    if json_out:
        emit_json(result.to_dict())
    else:
        _print_task(result)
    if not result.success:
        raise typer.Exit(1)


def _print_task(result: TaskResult) -> None:
    verdict = "[green]success[/green]" if result.success else "[red]failed[/red]"
    table = Table(title=f"task {result.name}, seed {result.seed}: {verdict}")
    table.add_column("criterion")
    table.add_column("held")
    for criterion, held in result.criteria.items():
        table.add_row(criterion, "yes" if held else "[red]no[/red]")
    console.print(table)
    for key, value in result.figures.items():
        console.print(f"  {key} = {value:.4g}", highlight=False)


@app.command("reproduce")
def reproduce(
    out: Annotated[Path, typer.Option("--out", help="Report directory.")] = Path("reproduce"),
    quick: Annotated[bool, typer.Option(
        "--quick", help="Smaller datasets, shorter grids and holds "
                        "(about 1.5 min on 2 cores).")] = False,
    seed: Annotated[int, int_option("--seed", help="Twin seed.")] = 0,
    jobs: Annotated[int, int_option("--jobs", help="Sections run at once.")] = 2,
    section: Annotated[list[str] | None, typer.Option(
        "--section", help="Run only this section (repeatable).", show_default=False)] = None,
    rig: RigOption = None,
    material: MaterialOption = None,
) -> None:
    """Run every experiment of the paper, write DIR/report.md, DIR/results.json and figures."""
    from relaxgrip.reproduce import Section, check_request
    from relaxgrip.reproduce import reproduce as run_all

    if seed < 0:
        raise InputError(f"--seed must be >= 0, got {seed}")
    check_request(out, jobs, section)  # before the progress bar: a bad flag prints one line
    config = twin_config(rig, material=material)
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=err_console) as bar:
        job = bar.add_task("experiments", total=None)

        def progress(done_section: Section, done: int, total: int) -> None:
            bar.update(job, completed=done, total=total,
                       description=f"{done_section.key} done ({done_section.seconds:.0f} s)")

        sections = run_all(out, quick=quick, seed=seed, jobs=jobs, only=section,
                           progress=progress, config=config,
                           rig=None if rig is None else str(rig))
    for s in sections:
        console.print(f"[bold]{s.title}[/bold] ({s.seconds:.0f} s)")
        if not s.rows:
            console.print(f"  {s.finding}", markup=False, highlight=False)
        for row in s.rows:
            console.print(f"  {row.quantity}: paper {row.paper}, ours {row.ours}",
                          highlight=False, markup=False)
    console.print(f"{out / 'report.md'}, {out / 'results.json'}")
    failed = [s.key for s in sections if "error" in s.results]
    if failed:
        err_console.print(f"error: section(s) failed: {', '.join(failed)} (see the report)",
                          markup=False, highlight=False)
        raise typer.Exit(1)
