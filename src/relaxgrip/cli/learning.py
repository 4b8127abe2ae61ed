"""``relaxgrip dataset build``, ``relaxgrip train``, ``relaxgrip evaluate``."""

from __future__ import annotations

import shlex
import time
from contextlib import nullcontext
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json, err_console, float_option, int_option
from relaxgrip.cli._twin import MaterialOption, RigOption, twin_config
from relaxgrip.errors import InputError

if TYPE_CHECKING:  # the CLI imports its commands' modules lazily
    from relaxgrip.experiments.band_calibration import BandCalibration

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
    observer: Annotated[Path | None, typer.Option(
        "--observer", help="Observer directory whose branch parameters give the loading "
        "history's retained shares (default: the shipped observer).", show_default=False)
    ] = None,
    unrelaxed: Annotated[bool, typer.Option(
        "--unrelaxed/--no-unrelaxed", help="Also train the ICFN on unrelaxed forces, which "
        "relax and observer read with the loading history.")] = True,
    json_out: Annotated[bool, typer.Option("--json", help="Print the training summary.")] = False,
) -> None:
    """Train the ICFN and the RCFN, selecting each on the validation split."""
    from relaxgrip.learning.datastore import load_dataset
    from relaxgrip.learning.observer import load_default_observer, load_observer
    from relaxgrip.learning.store import check_models_out
    from relaxgrip.learning.training import train_models

    if observer is not None and not unrelaxed:
        raise InputError("--observer gives the unrelaxed ICFN's shares: drop --no-unrelaxed")
    if not 0 <= seed < 2**31:  # the ensemble's members take the seeds after it
        raise InputError(f"--seed must be in 0 .. 2**31 - 1, got {seed}")
    check_models_out(out)  # before training, not after
    dataset = load_dataset(data)
    history = None
    if unrelaxed:
        history = load_default_observer() if observer is None else load_observer(observer)
    start = time.perf_counter()
    trained = train_models(dataset, random_state=seed, history=history)
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
    if (record := trained.training.get("icfn_unrelaxed")) is not None:
        console.print(f"unrelaxed ICFN (relax, observer) on {len(record['features'])} features: "
                      f"val MAE {record['val_mae_n']:.3f} N of unrelaxed force, retained share "
                      f"median {record['retained_share_percentiles']['p50']:.3f}")
    console.print(f"models written to {out}; relax's closed-loop error is not calibrated: "
                  f"relaxgrip calibrate-hold {out} measures it (288 holds, about 40 min on 2 "
                  "cores)")


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
    history = s.get("icfn_history")
    rows = [
        ("ICFN MAE", f"{icfn['mae_n']:.3f} N [0.651]"),
        ("ICFN RMSE", f"{icfn['rmse_n']:.3f} N [0.886]"),
        ("ICFN R²", f"{icfn['r2']:.3f} [0.848]"),
        *((f"ICFN median AE {k} N", f"{v:.3f} N") for k, v in icfn["median_ae_n"].items()),
        *([] if history is None else [(
            "ICFN × loading history (relax, observer) MAE / RMSE / R²",
            f"{history['mae_n']:.3f} N / {history['rmse_n']:.3f} N / {history['r2']:.3f}")]),
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


@app.command("fit-observer")
def fit_observer_command(
    data: Annotated[Path, typer.Option("--data", help="Dataset directory with RCFN holds.",
                                       show_default=False)],
    out: Annotated[Path, typer.Option("--out", help="Observer directory to write.",
                                      show_default=False)],
    terms: Annotated[int, int_option(
        "--terms", help="Prony branches, 1-5 (fewer for holds too short to separate three "
                        "relaxation times).")] = 3,
    models: Annotated[Path | None, typer.Option(
        "--models", help="Model directory whose ICFN reads the contact onset for the band's "
                         "onset error: the gripper's own (default: the shipped models).",
        show_default=False)] = None,
) -> None:
    """Identify the viscoelastic observer (``--estimator observer``) on a dataset's RCFN holds."""
    from relaxgrip.learning.observer import fit_observer

    if not 1 <= terms <= 5:  # before the dataset loads (the fit checks it too, by its name)
        raise InputError(f"--terms must be 1-5, got {terms}")
    start = time.perf_counter()
    model = fit_observer(data, out, models_dir=models, n_terms=terms)
    if model.identified_on_ != "train":
        err_console.print(f"warning: {data} has no RCFN train sequences: the observer was "
                          f"identified on all {model.n_sequences_}, and its band has no held-out "
                          "holds", markup=False, highlight=False, soft_wrap=True)
    console.print(f"{out}: observer of {model.n_terms} branches on {model.n_sequences_} "
                  f"sequences, {model.temps_c_.size} temperature knots, "
                  f"{time.perf_counter() - start:.0f} s")


#: The twin's band holds: options and defaults; ``--recordings`` takes recorded holds instead.
_TWIN_BAND = {"--seeds": "3000-3035", "--scenarios": "standard,ramp,step,light,firm,hot,warm",
              "--duration-s": "280"}


def _refuse_twin_options(options: dict[str, str], given: tuple[object, ...]) -> None:
    """With ``--recordings``, an option that sets the twin's holds (``given`` in the order of
    ``options``) is refused rather than ignored."""
    for flag, value in zip(options, given, strict=True):
        if value is not None:
            raise InputError(f"{flag} sets the twin's holds; with --recordings the holds are "
                             "the recordings'")


@app.command("calibrate-band")
def calibrate_band_command(
    observer: Annotated[Path, typer.Argument(
        help="Observer directory (relaxgrip fit-observer); its band's scales are rewritten.",
        show_default=False)],
    seeds: Annotated[str | None, typer.Option(
        "--seeds", help="Twin seeds: 3000-3035, 3,5,8 or a mix (take ones not used to check "
                        "or to design with; the shipped band: 3000-3035). "
                        "Each run counts about once: 12 seeds leave the scale about ±20 % "
                        "unsure, 36 about ±13 % (the reported interval). (default: "
                        f"{_TWIN_BAND['--seeds']})", show_default=False)] = None,
    scenarios: Annotated[str | None, typer.Option(
        "--scenarios", help="Comma-separated: standard, ramp (40 -> 55 °C from 150 s), "
                            "step (5 -> 3 N at 150 s), push (2 N from 200 s), light (1 N), "
                            "firm (8 N), hot (55 °C), warm (48 °C); holds at more than one "
                            "temperature set the band's temperature factors. (default: "
                            f"{_TWIN_BAND['--scenarios']})", show_default=False)] = None,
    duration_s: Annotated[float | None, float_option(
        "--duration-s", help="Hold length (s); profile times scale with it. (default: "
                             f"{_TWIN_BAND['--duration-s']})", show_default=False)] = None,
    recordings: Annotated[list[Path] | None, typer.Option(
        "--recordings", help="Calibrate on recorded holds instead of the twin: recordings "
                             "(.mcap) or directories of them, relax or observer holds with a "
                             "force reference; repeat the option for more.",
        show_default=False)] = None,
    models: Annotated[Path | None, typer.Option(
        "--models", help="ICFN/RCFN directory (default: the shipped models; with "
                         "--recordings, the models they ran with).",
        show_default=False)] = None,
    jobs: Annotated[int, int_option("--jobs", help="Holds in parallel.")] = 2,
    dry_run: Annotated[bool, typer.Option(
        "--dry-run", help="Measure and report; do not rewrite the directory.")] = False,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Recalibrate the observer's 95 % band on closed-loop holds, so it covers what it states.

    The holds run on the twin, or, with --recordings, are a lab's own recorded
    holds of its gripper, replayed.
    """
    from relaxgrip.experiments.band_calibration import calibrate_band
    from relaxgrip.experiments.controlled_hold import check_hold_duration_s
    from relaxgrip.learning.observer import load_observer, set_band_scale
    from relaxgrip.learning.store import load_models
    from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
    from relaxgrip.validate import check_jobs, parse_names, parse_seeds

    if recordings is not None:
        _refuse_twin_options(_TWIN_BAND, (seeds, scenarios, duration_s))
    seed_list = parse_seeds(_TWIN_BAND["--seeds"] if seeds is None else seeds)
    names = parse_names(_TWIN_BAND["--scenarios"] if scenarios is None else scenarios,
                        "--scenarios")
    duration_s = float(_TWIN_BAND["--duration-s"]) if duration_s is None else duration_s
    check_hold_duration_s(duration_s, "--duration-s")
    check_jobs(jobs)
    model = load_observer(observer)
    bundle = None if models is None else load_models(
        models, icfn_feature_schema=ICFN_SCHEMA, rcfn_feature_schema=RCFN_SCHEMA)
    start = time.perf_counter()
    note = None
    if recordings is not None:
        from relaxgrip.control.estimators import estimator_provenance
        from relaxgrip.experiments.recorded_calibration import calibrate_band_on_recordings
        from relaxgrip.learning.training import load_default_models
        from relaxgrip.recording import require_mcap
        from relaxgrip.recording.dataset import recording_files
        from relaxgrip.recording.provenance import differences_note, recorded_models

        require_mcap()
        files = recording_files(recordings)
        if bundle is None:
            bundle = recorded_models(files) or load_default_models()
        note = differences_note(files, estimator_provenance("observer", bundle, model),
                                ignore=("calibration", "observer band"))
        with (console.status("replaying the recorded holds …") if not json_out
              else nullcontext()):
            result = calibrate_band_on_recordings(model, files, bundle, jobs)
    else:
        with (console.status(f"{len(names) * len(seed_list)} closed-loop holds …")
              if not json_out else nullcontext()):
            result = calibrate_band(model, seed_list, names, duration_s, bundle, jobs)
    if not dry_run:
        set_band_scale(observer, result.band_scale, result.record(), result.drift_scale,
                       result.band_floor_n, (result.band_temps_c, result.band_temp_factors))
    if json_out:
        emit_json({"observer": str(observer), "written": not dry_run, **result.record(),
                   "summary": result.summary(), "models_note": note})
        return
    if note is not None:
        err_console.print(f"note: {note}", markup=False, highlight=False, soft_wrap=True)
    table = Table(title=f"band coverage at {result.level:.0%}: scale {result.previous_scale:.3g}"
                        f" -> {result.band_scale:.3g}, drift scale "
                        f"{result.previous_drift_scale:.3g} -> {result.drift_scale:.3g}, floor "
                        f"{result.previous_floor_n:.3g} -> {result.band_floor_n:.3g} N")
    for column in ("scenario", "seed" if recordings is None else "recording",
                   "true − target: MAE (N)", "coverage before", "coverage after"):
        table.add_column(column)
    for name, entry in result.scenarios.items():
        for seed, row in entry["seeds"].items():
            table.add_row(name, row.get("recording", seed), f"{row['mae_n']:.3f}",
                          f"{row['coverage_before']:.1%}", f"{row['coverage_after']:.1%}")
    console.print(table)
    summary = Table(title="per scenario, mean over its holds")
    for column in ("scenario", "holds", "true − target: MAE (N)", "coverage before",
                   "coverage after"):
        summary.add_column(column)
    for name, row in result.summary().items():
        summary.add_row(name, str(len(result.scenarios[name]["seeds"])), f"{row['mae_n']:.3f}",
                        f"{row['coverage_before']:.1%}", f"{row['coverage_after']:.1%}")
    console.print(summary)
    verb = "measured (not written)" if dry_run else f"written to {observer}"
    lo, hi = result.scale_interval
    drift_lo, drift_hi = result.drift_interval
    drift = (f"drift scale {result.drift_scale:.4g} ({drift_lo:.3g}-{drift_hi:.3g}) over the "
             f"{result.drift_samples} samples with the share's drift" if result.drift_samples else
             f"drift scale kept at {result.drift_scale:.4g}: no sample had the share's drift")
    floor_lo, floor_hi = result.floor_interval
    console.print(f"band scale {result.band_scale:.4g} (90 % over resampled seeds: {lo:.3g}-"
                  f"{hi:.3g}) over {result.samples} hold samples")
    console.print(f"band floor {result.band_floor_n:.4g} N ({floor_lo:.3g}-{floor_hi:.3g})")
    console.print(_temp_factors_line(result))
    console.print(drift)
    console.print(f"{verb}, {time.perf_counter() - start:.0f} s")


def _temp_factors_line(result: BandCalibration) -> str:
    """What the recalibration did with the band's temperature factors, in one line."""
    if not result.factor_intervals:
        kept = ", ".join(f"{f:.3g} at {t:g} °C" for t, f in zip(
            result.band_temps_c, result.band_temp_factors, strict=True)) or "none"
        return f"temperature factors kept ({kept}): the holds were at one temperature"
    spans = ", ".join(f"{f:.3g} ({lo:.3g}-{hi:.3g}) at {t:g} °C" for t, f, (lo, hi) in zip(
        result.band_temps_c, result.band_temp_factors, result.factor_intervals, strict=True))
    return f"temperature factors {spans}"


def _calibrate_hold_command(models: str, targets: str, temps: str, seeds: str,
                            duration_s: float, add: bool) -> str:
    """The ``calibrate-hold`` command line that measures these holds again."""
    duration = f"{duration_s:g}" if float(f"{duration_s:g}") == duration_s else repr(duration_s)
    return shlex.join(["relaxgrip", "calibrate-hold", models, "--targets", targets, "--temps",
                       temps, "--seeds", seeds, "--duration-s", duration,
                       *(["--add"] if add else [])])


#: The twin grid's options and their defaults; ``--recordings`` takes its grid from the plans.
_TWIN_GRID = {"--targets": "1,2,3,4,5,6,7,8", "--temps": "30,35,40,45,50,55",
              "--seeds": "1000-1005", "--duration-s": "280"}


@app.command("calibrate-hold")
def calibrate_hold_command(
    models: Annotated[Path, typer.Argument(
        help="Model directory (relaxgrip train); relax's calibrated error is written into its "
             "manifest.", show_default=False)],
    targets: Annotated[str | None, typer.Option(
        "--targets", help="Target forces of the grid (N), comma-separated. (default: "
                          f"{_TWIN_GRID['--targets']})", show_default=False)] = None,
    temps: Annotated[str | None, typer.Option(
        "--temps", help="Finger temperatures of the grid (°C), comma-separated. (default: "
                        f"{_TWIN_GRID['--temps']})", show_default=False)] = None,
    seeds: Annotated[str | None, typer.Option(
        "--seeds", help="Twin seeds per condition: 1000-1007, 3,5,8 or a mix (take ones not "
                        "used to check). Each run counts about once. (default: "
                        f"{_TWIN_GRID['--seeds']})", show_default=False)] = None,
    duration_s: Annotated[float | None, float_option(
        "--duration-s", help="Hold length (s); the grid's times reach it. (default: "
                             f"{_TWIN_GRID['--duration-s']})", show_default=False)] = None,
    recordings: Annotated[list[Path] | None, typer.Option(
        "--recordings", help="Measure on recorded holds instead of the twin: recordings "
                             "(.mcap) or directories of them, relax or observer holds with a "
                             "force reference, two or more per target and temperature; "
                             "repeat the option for more.", show_default=False)] = None,
    jobs: Annotated[int, int_option("--jobs", help="Holds in parallel.")] = 2,
    add: Annotated[bool, typer.Option(
        "--add", help="Add these holds to the directory's calibration (more seeds at a "
                      "condition, or conditions more) instead of replacing it.")] = False,
    dry_run: Annotated[bool, typer.Option(
        "--dry-run", help="Measure and report; do not rewrite the directory.")] = False,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Measure relax's closed-loop error on a grid of holds; relax takes it off its estimate.

    The holds run on the twin, or, with --recordings, are a lab's own recorded
    holds of its gripper, replayed.
    """
    from relaxgrip.experiments.controlled_hold import check_hold_duration_s
    from relaxgrip.experiments.hold_calibration import (
        calibrate_hold,
        calibration_record,
        condition_name,
        hidden_note,
    )
    from relaxgrip.fileio import check_writable
    from relaxgrip.learning.store import MANIFEST_NAME, load_models, set_hold_bias
    from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
    from relaxgrip.validate import check_jobs, parse_floats, parse_seeds

    if recordings is not None:
        _refuse_twin_options(_TWIN_GRID, (targets, temps, seeds, duration_s))
        if add:
            raise InputError("--add grows a calibration on the twin; with --recordings give "
                             "every recording at once")
    targets = _TWIN_GRID["--targets"] if targets is None else targets
    temps = _TWIN_GRID["--temps"] if temps is None else temps
    seeds = _TWIN_GRID["--seeds"] if seeds is None else seeds
    duration_s = float(_TWIN_GRID["--duration-s"]) if duration_s is None else duration_s
    target_list = parse_floats(targets, "--targets")
    temp_list = parse_floats(temps, "--temps")
    seed_list = parse_seeds(seeds)
    check_hold_duration_s(duration_s, "--duration-s")
    check_jobs(jobs)
    bundle = load_models(models, icfn_feature_schema=ICFN_SCHEMA,
                         rcfn_feature_schema=RCFN_SCHEMA)
    earlier = calibration_record(bundle.manifest) if add else None
    if not dry_run:
        check_writable(models / MANIFEST_NAME, InputError)
    start = time.perf_counter()
    models_note = None
    if recordings is not None:
        from relaxgrip.control.estimators import estimator_provenance
        from relaxgrip.experiments.recorded_calibration import calibration_from_recordings
        from relaxgrip.recording import require_mcap
        from relaxgrip.recording.dataset import recording_files
        from relaxgrip.recording.provenance import differences_note

        require_mcap()
        files = recording_files(recordings)
        # The calibration taken off relax is what this measures anew: not a difference.
        models_note = differences_note(files, estimator_provenance("relax", bundle),
                                       ignore=("calibration",))
        with (console.status("replaying the recorded holds …") if not json_out
              else nullcontext()):
            result = calibration_from_recordings(files, bundle, jobs)
        count = sum(map(len, result.holds.values()))
        command = shlex.join(["relaxgrip", "calibrate-hold", str(models),
                              *(arg for path in recordings for arg in ("--recordings", str(path)))])
        record = {**result.record(), "commands": [command]}
    else:
        count = len(target_list) * len(temp_list) * len(seed_list)  # parse_floats: no repeats
        with (console.status(f"{count} closed-loop holds …") if not json_out
              else nullcontext()):
            result = calibrate_hold(target_list, temp_list, seed_list, duration_s, bundle, jobs,
                                    add_to=earlier)
        # How to measure it again: every command whose holds it holds, in order.
        command = _calibrate_hold_command(str(models), targets, temps, seeds, duration_s, add)
        earlier_commands: list[str] = []
        if earlier is not None:
            stored = earlier.get("commands")
            earlier_commands = (
                [c for c in stored if isinstance(c, str)] if isinstance(stored, list)
                else [_calibrate_hold_command(  # a record from before the list
                    str(models), ",".join(f"{v:g}" for v in earlier["targets_n"]),
                    ",".join(f"{v:g}" for v in earlier["temps_c"]),
                    ",".join(str(v) for v in earlier.get("seeds", [])),
                    float(earlier["duration_s"]), False)])
        record = {**result.record(), "commands": [*earlier_commands, command]}
    if not dry_run:
        set_hold_bias(models, result.bias, record, measured_on=bundle.manifest)
    kept = result.kept()
    note = hidden_note(kept, recorded=recordings is not None) if kept["hidden"] else None
    if json_out:
        emit_json({"models": str(models), "written": not dry_run, "bias": result.bias.to_dict(),
                   **record, "kept": {**kept, "note": note}, "models_note": models_note})
        return
    if models_note is not None:
        err_console.print(f"note: {models_note}", markup=False, highlight=False, soft_wrap=True)
    lines = result.drift_fit.get("conditions", {})
    table = Table(title="relax, estimate − true force over the steady state, uncalibrated "
                        "(the last columns: its line in the ICFN's drift, slope ± SE and "
                        "correlation, and the held force's MAE from the target)")
    columns = ["target (N)", "temperature (°C)", "holds", "mean (N)", "SE (N)"]
    if lines:
        columns += ["drift slope (N/N)", "r"]
    for column in (*columns, "true − target: MAE (N)"):
        table.add_column(column, justify="right")
    summary = result.summary()
    for target in result.targets_n:
        for temp in result.temps_c:
            name = condition_name(target, temp)
            row = summary[name]
            cells = [f"{target:g}", f"{temp:g}", str(len(result.holds[name])),
                     f"{row['est_error_mean_n']:+.3f}", f"{row['se_n']:.3f}"]
            if lines:
                line = lines[name]
                cells += [f"{line['slope']:+.2f} ± {line['slope_se']:.2f}", f"{line['r']:+.2f}"]
            table.add_row(*cells, f"{row['mae_n']:.3f}")
    console.print(table)
    if not lines:
        console.print("no line in the ICFN's drift: some holds did not read it (holds stored "
                      "before it, or recorded without the per-frame ICFN)")
    verb = "measured (not written)" if dry_run else f"written to {models}"
    added = f" added to {sum(map(len, result.holds.values())) - count}" if add else ""
    kind = f"recorded holds of {result.duration_s:g} s" if recordings is not None else "holds"
    if note is not None:
        err_console.print(f"warning: {note}", markup=False, highlight=False, soft_wrap=True)
    console.print(f"{count} {kind}{added}, {verb}, {time.perf_counter() - start:.0f} s")
