"""``relaxgrip dataset build``, ``train``, ``evaluate`` and ``calibrate``."""

from __future__ import annotations

import shlex
import sys
import time
from contextlib import nullcontext
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json, err_console, float_option, int_option
from relaxgrip.cli._twin import MaterialOption, RigOption, twin_config
from relaxgrip.errors import InputError

dataset_app = typer.Typer(help="Generate and convert training datasets.", no_args_is_help=True)
app.add_typer(dataset_app, name="dataset")


@dataset_app.command("build")
def dataset_build(
    out: Annotated[Path, typer.Option("--out", help="Dataset directory to write.",
                                      show_default=False)],
    icfn_samples: Annotated[int | None, int_option(
        "--icfn-samples", show_default=False,
        help="ICFN samples (default 10,700, up to 11 N; the paper's 8,258 reach 8 N).")] = None,
    rcfn_sequences: Annotated[int, int_option("--rcfn-sequences",
                                                help="RCFN relaxation sequences.")] = 810,
    seed: Annotated[int, int_option("--seed", help="Master seed.")] = 0,
    hold_s: Annotated[float, float_option(
        "--hold-s", help="Length of each RCFN hold (s); the paper recorded 100 s.")] = 280.0,
    jobs: Annotated[int, int_option("--jobs", help="Parallel workers.")] = 2,
    backend: Annotated[str, typer.Option("--backend", help="joblib backend: loky, dask or ray.")
                       ] = "loky",
    json_out: Annotated[bool, typer.Option("--json", help="Print the manifest as JSON.")] = False,
    rig: RigOption = None,
    material: MaterialOption = None,
) -> None:
    """Generate ICFN and RCFN datasets on the twin, through the real perception pipeline."""
    from relaxgrip.learning.build import BACKENDS, build_dataset, check_backend
    from relaxgrip.learning.datasets import DatasetSpec
    from relaxgrip.learning.datastore import check_dataset_out
    from relaxgrip.validate import check_jobs

    if backend not in BACKENDS:
        raise InputError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    check_backend(backend)  # its optional dependency, before the progress bar shows
    check_jobs(jobs)
    check_dataset_out(out)
    config = twin_config(rig, material=material)
    spec = DatasetSpec(rcfn_sequences=rcfn_sequences, seed=seed, hold_s=hold_s)
    if icfn_samples is not None:
        spec = replace(spec, icfn_samples=icfn_samples)
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=err_console, transient=json_out) as bar:
        task = bar.add_task("episodes and sequences", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        manifest = build_dataset(out, spec, jobs=jobs, backend=backend, progress=progress,
                                 config=config)
    if json_out:
        emit_json(manifest)
        return
    counts = manifest["counts"]
    for warning in manifest["warnings"]:
        err_console.print(f"warning: {warning}", markup=False, highlight=False, soft_wrap=True)
    console.print(f"{out}: {counts['icfn_samples']} ICFN samples, {counts['rcfn_sequences']} "
                  f"RCFN sequences in {manifest['build']['seconds']:.0f} s "
                  f"({backend}, {jobs} jobs); README.md describes every column")


@app.command("train")
def train(
    data: Annotated[Path, typer.Option("--data", help="Dataset directory.", show_default=False)],
    out: Annotated[Path, typer.Option("--out", help="Model directory to write.",
                                      show_default=False)],
    seed: Annotated[int, int_option("--seed", help="Random state of the training.")] = 0,
    json_out: Annotated[bool, typer.Option("--json", help="Print the training summary.")] = False,
) -> None:
    """Train the ICFN and the RCFN, selecting each on the validation split."""
    from relaxgrip.learning.datastore import load_dataset
    from relaxgrip.learning.store import check_models_out
    from relaxgrip.learning.training import train_models

    if not 0 <= seed < 2**31:
        raise InputError(f"--seed must be in 0 .. 2**31 - 1, got {seed}")
    check_models_out(out)  # before training, not after
    dataset = load_dataset(data)
    start = time.perf_counter()
    trained = train_models(dataset, random_state=seed)
    trained.save(out)
    seconds = time.perf_counter() - start
    if json_out:
        emit_json({"models": str(out), "seconds": seconds, **trained.training})
        return
    table = Table(title=f"ICFN candidates (validation), trained in {seconds:.1f} s")
    for col in ("hidden layers", "alpha", "val MAE (N)", "val RMSE (N)"):
        table.add_column(col, justify="right")
    for row in trained.icfn_candidates:
        table.add_row(str(tuple(row["params"]["hidden_layer_sizes"])),
                      f"{row['params']['alpha']:g}", f"{row['val_mae_n']:.3f}",
                      f"{row['val_rmse_n']:.3f}")
    console.print(table)
    console.print(f"models written to {out}; the observer needs a calibration: "
                  f"relaxgrip calibrate {out} (12 holds of 280 s)")


@app.command("evaluate")
def evaluate(
    data: Annotated[Path, typer.Option("--data", help="Dataset directory.", show_default=False)],
    models: Annotated[Path | None, typer.Option(
        "--models", help="Model directory (default: the shipped models).", show_default=False)
    ] = None,
    split: Annotated[str, typer.Option("--split", help="train, val, test or all.")] = "test",
    plot: Annotated[Path | None, typer.Option(
        "--plot", help="Directory for the accuracy figure (accuracy.png).", show_default=False)
    ] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Score the models with the paper's metrics (ICFN, RCFN, repeatability)."""
    from relaxgrip.learning.datastore import load_dataset
    from relaxgrip.learning.evaluation import evaluate as run_evaluation
    from relaxgrip.learning.evaluation import spread_text
    from relaxgrip.learning.store import load_models
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA

    if split not in ("train", "val", "test", "all"):
        raise InputError(f"--split must be train, val, test or all, got {split!r}")
    if plot is not None and not plot.is_dir():
        raise InputError(f"--plot {plot}: " + ("not a directory (it names the folder for "
                                              "accuracy.png)" if plot.exists()
                                              else "no such directory"))
    dataset = load_dataset(data)
    bundle = load_default_models() if models is None else load_models(
        models, icfn_feature_schema=ICFN_SCHEMA, rcfn_feature_schema=RCFN_SCHEMA)
    result = run_evaluation(dataset, bundle, split)
    figure = None
    if plot is not None:
        from relaxgrip.plots.accuracy import plot_accuracy

        figure = plot_accuracy(result, plot / "accuracy.png")
    if json_out:
        emit_json(result.to_dict())
        return
    s = result.to_dict()
    icfn, rcfn = s["icfn"], s["rcfn"]
    table = Table(title=f"Accuracy on the {split} split (paper in brackets)")
    table.add_column("metric")
    table.add_column("value", justify="right")
    rows = [
        ("ICFN MAE", f"{icfn['mae_n']:.3f} N [0.651]"),
        ("ICFN RMSE", f"{icfn['rmse_n']:.3f} N [0.886]"),
        ("ICFN R²", f"{icfn['r2']:.3f} [0.848]"),
        *((f"ICFN median AE {k} N", f"{v:.3f} N") for k, v in icfn["median_ae_n"].items()),
        ("RCFN NRMSE mean / median", f"{rcfn['nrmse_mean']:.3f} / {rcfn['nrmse_median']:.3f}"
                                     " [0.160 / 0.118]"),
        ("RCFN AUC_rel mean / median", f"{rcfn['auc_rel_mean']:.3f} / "
                                       f"{rcfn['auc_rel_median']:.3f} [0.065 / 0.049]"),
        ("RCFN curve correlation", f"{rcfn['corr_mean']:.4f} [0.990]"),
    ]
    for temp, g in s["repeatability"].items():
        rows.append((f"repeatability {temp} °C", f"NRMSE {g['nrmse_mean']:.3f}±{g['nrmse_std']:.3f}"
                     f", AUC {g['auc_rel_mean']:.3f}, corr {g['corr_mean']:.3f}, "
                     f"{spread_text(g)}"))
    for name, value in rows:
        table.add_row(name, value)
    console.print(table)
    if figure is not None:
        console.print(f"figure: {figure}")


@app.command("calibrate")
def calibrate_command(
    models: Annotated[Path, typer.Argument(
        help="Model directory (relaxgrip train); the observer's calibration is written into "
             "its manifest.", show_default=False)],
    seeds: Annotated[str | None, typer.Option(
        "--seeds", help="Twin seeds of the holds (default 1000-1011: 1, 5 and 8 N at 40 and "
                        "55 °C, two seeds each); at most 12.", show_default=False)] = None,
    recordings: Annotated[list[Path] | None, typer.Option(
        "--recordings", help="Recorded regulated holds (.mcap) or directories of them, with "
                             "a force reference (/relaxgrip/force_ref); at most 12.",
        show_default=False)] = None,
    duration_s: Annotated[float, float_option(
        "--duration-s", help="Hold length of the twin's holds (s).")] = 280.0,
    jobs: Annotated[int, int_option("--jobs", help="Holds in parallel.")] = 1,
    dry_run: Annotated[bool, typer.Option(
        "--dry-run", help="Measure and print, write nothing.")] = False,
    json_out: Annotated[bool, typer.Option("--json", help="Print the calibration.")] = False,
    rig: RigOption = None,
) -> None:
    """Calibrate the observer against a force reference on up to 12 regulated holds."""
    from relaxgrip.experiments.calibration import calibrate
    from relaxgrip.experiments.controlled_hold import check_hold_duration_s
    from relaxgrip.learning.store import load_models
    from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
    from relaxgrip.validate import check_jobs, parse_seeds

    check_jobs(jobs)
    check_hold_duration_s(duration_s, "--duration-s")
    if recordings and (seeds is not None or rig is not None):
        raise InputError("--recordings calibrates on recorded holds: --seeds and --rig are "
                         "for the twin's")
    seed_list = None if seeds is None else parse_seeds(seeds)
    bundle = load_models(models, icfn_feature_schema=ICFN_SCHEMA,
                         rcfn_feature_schema=RCFN_SCHEMA)
    config = None if recordings else twin_config(rig)
    command = shlex.join(["relaxgrip", *sys.argv[1:]]) if sys.argv[1:] else "relaxgrip calibrate"
    with console.status("calibration holds …") if not json_out else nullcontext():
        run = calibrate(models, bundle, seeds=seed_list, recordings=recordings or None,
                        duration_s=duration_s, n_jobs=jobs, dry_run=dry_run, command=command,
                        config=config)
    if json_out:
        emit_json(run.to_dict())
        return
    cal = run.calibration
    table = Table(title=f"observer calibration on {len(run.holds)} holds against the force "
                        "reference")
    table.add_column("hold")
    table.add_column("95 % |error| / (1 N + F_inst)", justify="right")
    for hold, score in zip(run.holds, cal.record["scores"], strict=True):
        table.add_row(hold.name, f"{score:.4f}")
    console.print(table)
    c0, c1, c2 = cal.coef
    console.print(f"error model e = {c0:+.4f} N {c1:+.4f} F_inst {c2:+.4f} R(t); band "
                  f"±{cal.band_rel:.4f} (1 N + F_inst) (hold rank {cal.record['band_rank']} "
                  f"of {len(run.holds)})")
    console.print("measured (not written)" if run.written is None
                  else f"written to {run.written}")
