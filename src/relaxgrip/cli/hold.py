"""``relaxgrip hold``: the paper's 280 s force-controlled hold, one estimator or all three."""

from __future__ import annotations

import math
import time
from contextlib import nullcontext
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json, err_console, float_option, int_option
from relaxgrip.cli._twin import MaterialOption, RigOption, twin_config
from relaxgrip.errors import InputError

if TYPE_CHECKING:
    from relaxgrip.experiments.hold_survey import HoldSurvey

#: The paper's figures (§V-C): MAE, mean signed error, RMSE of the true force from 5 N.
PAPER: dict[str, dict[str, float | tuple[float, float]]] = {
    "fixed": {"mae_n": 0.333, "mean_signed_error_n": 0.606, "rmse_n": 0.643},
    "icfn": {"mae_n": 1.327, "mean_signed_error_n": 1.019, "rmse_n": 1.035},
    "relax": {"mae_n": 0.066, "mean_signed_error_n": -0.036, "rmse_n": 0.102,
              "median_signed_error_n": -0.041, "abs_error_iqr_n": (0.055, 0.076)},
}
PAPER_REDUCTION = {"vs_fixed": 0.802, "vs_icfn": 0.950}
DEFAULT_COMPARE_PLOT = Path("relaxgrip-hold.png")


def _paper(name: str, key: str) -> str:
    value = PAPER.get(name, {}).get(key)
    if value is None:
        return ""
    if isinstance(value, tuple):
        return f" [{value[0]:.3f}, {value[1]:.3f}]"
    return f" [{value:+.3f}]" if "signed" in key else f" [{value:.3f}]"


@app.command("hold")
def hold(
    estimator: Annotated[str, typer.Option(
        "--estimator", help="fixed, icfn, relax or observer.")] = "relax",
    target_n: Annotated[float, float_option("--target-n", help="Target force (N), 0-10.")] = 5.0,
    duration_s: Annotated[float, float_option("--duration-s", help="Hold length (s).")] = 280.0,
    temp_c: Annotated[float, float_option("--temp-c", help="Finger temperature (°C).")] = 40.0,
    seed: Annotated[int | None, int_option(
        "--seed", help="Twin seed (default: 0).", show_default=False)] = None,
    seeds: Annotated[str | None, typer.Option(
        "--seeds", help="Run every one of these twin seeds (0-23, 3,5,8 or a mix) and report "
                        "each figure's mean over them, with its 95 % interval.",
        show_default=False)] = None,
    models: Annotated[Path | None, typer.Option(
        "--models", help="Model directory (default: the shipped models).", show_default=False)
    ] = None,
    observer_dir: Annotated[Path | None, typer.Option(
        "--observer", help="Observer directory for --estimator observer and --compare "
                           "(relaxgrip fit-observer; default: the shipped one).",
        show_default=False)] = None,
    compare: Annotated[bool, typer.Option(
        "--compare", help="Run fixed, icfn, relax and observer on the same seed.")] = False,
    plot: Annotated[Path | None, typer.Option(
        "--plot", help=f"Figure file (.png/.pdf/.svg); --compare default: {DEFAULT_COMPARE_PLOT}.",
        show_default=False)] = None,
    jobs: Annotated[int, int_option(
        "--jobs", help="Parallel holds with --compare or --seeds.")] = 2,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    backend: Annotated[str, typer.Option(
        "--backend", help="twin; emulator: the twin behind the MCU emulator over a pty "
                          "serial link (virtual time); serial:RIG.toml: the gripper that rig "
                          "file names (wall-clock time, scored against its force reference).")
    ] = "twin",
    mcu: Annotated[str, typer.Option(
        "--mcu", help="The emulator's MCU: python (the protocol's state machine) or firmware "
                      "(the compiled firmware in simavr).")] = "python",
    record: Annotated[Path | None, typer.Option(
        "--record", help="Record the run to this MCAP file (not with --compare); an existing "
                         "file only with --overwrite.",
        show_default=False)] = None,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Let --record replace an existing file.")] = False,
    temp_profile: Annotated[str | None, typer.Option(
        "--temp-profile", help="Setpoint over hold time: ramp:FROM_C:TO_C:START_S:OVER_S "
                               "(FROM_C: --temp-c) or step:TO_C:AT_S.",
        show_default=False)] = None,
    target_profile: Annotated[str | None, typer.Option(
        "--target-profile", help="Target over hold time: step:TO_N:AT_S or "
                                 "ramp:FROM_N:TO_N:START_S:OVER_S (FROM_N: --target-n).",
        show_default=False)] = None,
    disturbance: Annotated[str | None, typer.Option(
        "--disturbance", help="Push on the object: push:FORCE_N:AT_S[:FOR_S].",
        show_default=False)] = None,
    budget: Annotated[bool, typer.Option(
        "--budget", help="Split relax's estimate error into the onset force, Eq. 10's "
                         "relaxation and the added closure, against a copy of the twin held "
                         "at the onset's aperture, and the calibration and closed chain of "
                         "models that have them (relax, twin backend).")] = False,
    rig: RigOption = None,
    material: MaterialOption = None,
) -> None:
    """Close on the force ball to the target and hold it, scoring the steady state (100-280 s).

    Ctrl-C, kill (SIGTERM) or a closed terminal stop it: motor stopped, heaters off, the
    recording closed; the figures of the hold so far are printed ("interrupted": true with
    --json) and the exit code is 130.
    """
    from relaxgrip.control import EstimatorKind, check_target_n
    from relaxgrip.experiments.controlled_hold import (
        check_backend,
        check_hold_duration_s,
        check_hold_temp_c,
        check_mcu,
        check_ramp_starts,
        check_scenario_times,
        compare_holds,
        run_hold,
    )
    from relaxgrip.experiments.profiles import (
        parse_disturbance,
        parse_target_profile,
        parse_temp_profile,
    )
    from relaxgrip.learning.observer import load_observer
    from relaxgrip.learning.store import load_models
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
    from relaxgrip.plots.common import check_plot_path
    from relaxgrip.validate import check_jobs, parse_seeds

    # Everything is checked before anything starts.
    if estimator not in {k.value for k in EstimatorKind}:
        raise InputError(f"--estimator must be fixed, icfn, relax or observer, got {estimator!r}")
    temps = None if temp_profile is None else parse_temp_profile(temp_profile)
    targets = None if target_profile is None else parse_target_profile(target_profile)
    push = None if disturbance is None else parse_disturbance(disturbance)
    check_target_n(target_n)
    check_hold_temp_c(temp_c)
    check_hold_duration_s(duration_s, "--duration-s")
    check_scenario_times(duration_s, temp_profile=temps, target_profile=targets,
                         disturbance=push)
    check_ramp_starts(target_n, temp_c, temps, targets)
    if seed is not None and seed < 0:
        raise InputError(f"--seed must be >= 0, got {seed}")
    seed_list = None if seeds is None else parse_seeds(seeds)
    if seed_list is not None:
        if seed is not None:
            raise InputError("--seed runs one seed and --seeds several: give one of them")
        if record is not None or plot is not None or budget:
            raise InputError("--seeds reports figures over seeds: --record, --plot and --budget "
                             "are for one run (relaxgrip budget --seeds gives the budget over "
                             "seeds)")
    check_jobs(jobs)
    serial = backend.startswith("serial:")
    if backend not in ("twin", "emulator") and not serial:
        raise InputError(f"--backend must be twin, emulator or serial:RIG.toml, got {backend!r}")
    check_backend(backend, push)  # a push needs the twin, before --record opens its file
    if serial:
        if rig is not None:
            raise InputError("--rig chooses the twin's gripper; a serial backend is the "
                             "gripper of its own rig file (serial:RIG.toml): give one of them")
        if seed_list is not None or budget:
            raise InputError("a serial rig holds once: --seeds and --budget are the twin's")
        from relaxgrip.hardware.rig_file import load_rig

        load_rig(backend.removeprefix("serial:"))  # its errors before anything starts
    check_mcu(mcu, backend)
    if mcu != "python" and seed_list is not None:
        raise InputError("--mcu firmware runs one hold: give --seed, not --seeds")
    if compare and (temps, targets, push) != (None, None, None):
        raise InputError("--compare runs the standard hold: run each estimator with "
                         "--estimator NAME and the profiles instead")
    if compare and backend != "twin":
        raise InputError("--compare runs on the twin backend only")
    seed = 0 if seed is None else seed
    if budget and (compare or estimator != "relax" or backend != "twin"):
        raise InputError("--budget splits relax's Eq. 10 on the twin: use it with "
                         "--estimator relax on the twin backend, without --compare")
    if record is not None and compare:
        raise InputError("--record records one run: record each estimator with "
                         "--estimator NAME --record FILE instead of --compare")
    if record is not None:
        from relaxgrip.fileio import check_new_file

        check_new_file(record, "--record", overwrite, InputError)
    elif overwrite:
        raise InputError("--overwrite lets --record replace a file: give --record FILE")
    if plot is None and compare and seed_list is None:
        plot = DEFAULT_COMPARE_PLOT
    if plot is not None:
        check_plot_path(plot)
    if observer_dir is not None and not (compare or estimator == "observer"):
        raise InputError("--observer sets the observer estimator's parameters: use it with "
                         "--estimator observer or --compare")
    config = None if serial else twin_config(rig, material=material)
    bundle = load_default_models() if models is None else load_models(
        models, icfn_feature_schema=ICFN_SCHEMA, rcfn_feature_schema=RCFN_SCHEMA)
    if observer_dir is None and models is not None and (models / "observer").is_dir():
        observer_dir = models / "observer"  # a bring-up's model directory carries its observer
    observer = None if observer_dir is None else load_observer(observer_dir)
    start = time.perf_counter()
    if seed_list is not None:
        from relaxgrip.experiments.hold_survey import survey_holds

        names = tuple(EstimatorKind) if compare else (estimator,)
        given = {"temp_profile": temp_profile, "target_profile": target_profile,
                 "disturbance": disturbance}
        with console.status(f"{len(names) * len(seed_list)} holds …") if not json_out \
                else nullcontext():
            survey = survey_holds(names, seed_list, target_n, temp_c, duration_s, bundle,
                                  observer, backend, temps, targets, push,
                                  profile_text={k: v for k, v in given.items() if v is not None},
                                  n_jobs=jobs, config=config)
        if json_out:
            emit_json(survey.to_dict())
            return
        _print_survey(survey, str(seeds), time.perf_counter() - start)
        return
    if compare:
        with console.status("holding with fixed, icfn, relax and observer …") if not json_out \
                else nullcontext():
            comparison = compare_holds(target_n=target_n, duration_s=duration_s, temp_c=temp_c,
                                       seed=seed, models=bundle, n_jobs=jobs,
                                       observer=observer, config=config)
        figure = None
        if plot is not None:
            from relaxgrip.plots.holding import plot_hold_comparison

            figure = plot_hold_comparison(comparison, plot)
        first = next(iter(comparison.holds.values()))
        if json_out:
            emit_json({"twin_version": first.twin_version, "target_n": target_n,
                       "temp_c": temp_c, "seed": seed, "duration_s": duration_s,
                       **comparison.to_dict()})
            return
        _print_table({k: v.to_dict() for k, v in comparison.holds.items()},
                     comparison.reductions(), first.to_dict(), time.perf_counter() - start)
        if figure is not None:
            console.print(f"figure: {figure}")
        return
    from relaxgrip.experiments.controlled_hold import HoldInterrupted

    try:
        with console.status(f"holding with {estimator} …") if not json_out else nullcontext():
            if record is None:
                result = run_hold(estimator, target_n, duration_s, temp_c, seed, bundle,
                                  config=config, backend=backend, temp_profile=temps,
                                  target_profile=targets, disturbance=push, observer=observer,
                                  budget=budget, mcu=mcu)
            else:
                from relaxgrip.recording import McapRecorder

                given = {"temp_profile": temp_profile, "target_profile": target_profile,
                         "disturbance": disturbance}
                scenario = {k: v for k, v in given.items() if v is not None}
                with McapRecorder(record, scenario=scenario) as recorder:
                    result = run_hold(estimator, target_n, duration_s, temp_c, seed, bundle,
                                      config=config, backend=backend, recorder=recorder,
                                      temp_profile=temps, target_profile=targets,
                                      disturbance=push, observer=observer, budget=budget,
                                      mcu=mcu)
    except HoldInterrupted as stopped:
        _print_interrupted(stopped.result, json_out, record, time.perf_counter() - start)
        raise typer.Exit(130) from None
    figure = None
    if plot is not None:
        from relaxgrip.plots.holding import plot_hold

        figure = plot_hold(result, plot)
    if json_out:
        emit_json(result.to_dict())
        return
    _print_table({estimator: result.to_dict()}, {}, result.to_dict(),
                 time.perf_counter() - start)
    if budget:
        parts = result.error_budget()
        lo, hi = result.window
        console.print(f"error budget, estimate − true force over {lo:.4g}–{hi:.4g} s: onset "
                      f"{parts['onset_n']:+.3f} N, Eq. 10 relaxation "
                      f"{parts['relaxation_n']:+.3f} N, added closure {parts['closure_n']:+.3f} N"
                      + (f", calibration {parts['calibration_n']:+.3f} N"
                         if "calibration_n" in parts else "")
                      + (f", closed chain {parts['chain_n']:+.3f} N"
                         if "chain_n" in parts else "")
                      + f" = {parts['total_n']:+.3f} N")
    if figure is not None:
        console.print(f"figure: {figure}")


def _mean_sd(figure: dict[str, Any] | None) -> str:
    """A survey figure as ``mean ± SD`` (the mean alone for one seed, a dash for none)."""
    if figure is None:
        return "–"
    return f"{figure['mean']:+.3f}" + (f" ± {figure['sd']:.3f}" if figure["n"] > 1 else "")


def _print_survey(survey: HoldSurvey, seeds: str, seconds: float) -> None:
    """Per seed each estimator's MAE, then each one's figures over the seeds."""
    from relaxgrip.experiments.controlled_hold import steady_window_s

    lo, hi = steady_window_s(survey.duration_s)
    names = list(survey.runs)
    scenario = "".join(f", {v}" for v in survey.profiles.values())
    per_seed = Table(title=f"MAE of the true force from the target over {lo:.4g}–{hi:.4g} s (N)")
    for col in ("seed", *names):
        per_seed.add_column(col, justify="right")
    for i, seed in enumerate(survey.seeds):
        per_seed.add_row(str(seed), *(f"{survey.runs[n][i]['mae_n']:.3f}" for n in names))
    console.print(per_seed)
    table = Table(title=f"{survey.duration_s:g} s holds at {survey.target_n:g} N, "
                        f"{survey.temp_c:g} °C{scenario}, seeds {seeds} ({len(survey.seeds)}): "
                        "the MAE over seeds (N)",
                  caption="95 % CI: the mean's Student-t interval over the seeds; est − true: "
                          "each run's mean estimate error, mean ± SD over seeds (N); band: the "
                          "share of the hold the 95 % band covers the true force")
    _add_columns(table, ("estimator", "MAE", "95 % CI", "median", "SD", "est − true", "band"))
    summaries = {name: survey.summary(name) for name in names}
    for name, s in summaries.items():
        mae, cover = s["mae_n"], s.get("band_coverage")
        spread = mae["n"] > 1  # one seed has no spread and no interval
        table.add_row(name, f"{mae['mean']:.4f}",
                      f"{mae['ci95'][0]:.3f}–{mae['ci95'][1]:.3f}" if spread else "–",
                      f"{mae['median']:.3f}", f"{mae['sd']:.3f}" if spread else "–",
                      _mean_sd(s.get("est_error_mean_n")),
                      "" if cover is None else f"{cover['mean']:.1%}")
    console.print(table)
    onsets = [f"{name} {_mean_sd(s.get('onset_error_n'))}" for name, s in summaries.items()]
    console.print(f"The true force at the hold's onset less the target, where the closing "
                  f"stopped (N, mean ± SD over seeds): {', '.join(onsets)}")
    reductions = survey.reductions()  # a bootstrap each: computed once
    for key, r in reductions.items():
        paper = PAPER_REDUCTION.get(key)
        ref = f" (paper {paper:.1%})" if paper is not None else ""
        lo, hi = r["ci95"]
        interval = f" [{lo:.1%}, {hi:.1%}]" if math.isfinite(lo) else ""
        console.print(f"MAE reduction of relax {key.replace('_', ' ')}: {r['reduction']:.1%}"
                      f"{interval}{ref}")
    if reductions:
        console.print("(the reductions' 95 % intervals: BCa bootstrap, the seeds resampled in "
                      "pairs)")
    console.print(f"{survey.twin_version}, {seconds:.1f} s")


def _add_columns(table: Table, names: tuple[str, ...]) -> None:
    """The estimator's column first, its names whole (the figures wrap in a narrow terminal)."""
    table.add_column(names[0], no_wrap=True, min_width=len("observer"))
    for col in names[1:]:
        table.add_column(col, justify="right")


def _print_table(rows: dict[str, dict[str, Any]], reductions: dict[str, float],
                 first: dict[str, Any], seconds: float) -> None:
    lo, hi = first["window_s"]
    table = Table(title=f"{first['duration_s']:g} s hold at {first['target_n']:g} N, "
                        f"{first['temp_c']:g} °C, seed {first['seed']}: true force − target over "
                        f"{lo:.4g}–{hi:.4g} s (paper in brackets)")
    _add_columns(table, ("estimator", "MAE (N)", "mean (N)", "median (N)", "RMSE (N)",
                         "IQR of |error| (N)", "estimate − true: mean / RMSE (N)"))
    for name, d in rows.items():
        q25, q75 = d["abs_error_iqr_n"]
        table.add_row(
            name, f"{d['mae_n']:.3f}{_paper(name, 'mae_n')}",
            f"{d['mean_signed_error_n']:+.3f}{_paper(name, 'mean_signed_error_n')}",
            f"{d['median_signed_error_n']:+.3f}{_paper(name, 'median_signed_error_n')}",
            f"{d['rmse_n']:.3f}{_paper(name, 'rmse_n')}",
            f"[{q25:.3f}, {q75:.3f}]{_paper(name, 'abs_error_iqr_n')}",
            f"{d['est_error_mean_n']:+.3f} / {d['est_rmse_n']:.3f}")
    console.print(table)
    for key, value in reductions.items():
        paper = PAPER_REDUCTION.get(key)
        ref = f" (paper {paper:.1%})" if paper is not None else ""
        console.print(f"MAE reduction of relax {key.replace('_', ' ')}: {value:.1%}{ref}")
    for name, d in rows.items():
        if "band_coverage" in d:
            console.print(f"{name}: the 95 % band covers the true force "
                          f"{d['band_coverage']:.1%} of the hold")
    for name, d in rows.items():
        from relaxgrip.control import EventKind
        from relaxgrip.control.phases import Event, PhaseLog

        log = PhaseLog(events=[Event(e["t_s"], EventKind(e["kind"]), e["detail"])
                               for e in d["events"]])
        for line in log.summary(skip=(EventKind.CONTACT, EventKind.HOLD_ONSET)):
            err_console.print(f"{name}: {line}", markup=False, highlight=False)
    console.print(f"{first['twin_version']}, {seconds:.1f} s")


def _print_interrupted(result: Any, json_out: bool, record: Path | None,
                       seconds: float) -> None:
    """The partial result of a hold a stop signal ended (a signal now does not cut it)."""
    import signal

    from relaxgrip.interrupts import STOP_SIGNALS

    previous = {sig: signal.signal(sig, signal.SIG_IGN) for sig in STOP_SIGNALS}
    try:
        d = result.to_dict()
        if json_out:
            emit_json(d)
            return
        if "mae_n" in d:
            _print_table({result.estimator: d}, {}, d, seconds)
        else:
            for line in result.loop.log.summary():
                err_console.print(line, markup=False, highlight=False)
        where = f"; recording {record} closed" if record is not None else ""
        err_console.print(f"interrupted after {result.held_s:.1f} s of the {d['duration_s']:g} s "
                          f"hold: motor stopped, heaters off{where}", markup=False,
                          highlight=False)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@app.command("budget")
def budget_survey(
    seeds: Annotated[str, typer.Option(
        "--seeds", help="Twin seeds: 0-23, 3,5,8 or a mix.")] = "0-23",
    target_n: Annotated[float, float_option("--target-n", help="Target force (N), 0-10.")] = 5.0,
    temp_c: Annotated[float, float_option("--temp-c", help="Finger temperature (°C).")] = 40.0,
    duration_s: Annotated[float, float_option("--duration-s", help="Hold length (s).")] = 280.0,
    models: Annotated[Path | None, typer.Option(
        "--models", help="Model directory (default: the shipped models).", show_default=False)
    ] = None,
    jobs: Annotated[int, int_option("--jobs", help="Holds in parallel.")] = 2,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """relax's error budget over seeds: each part's bias and spread, what the draw explains."""
    from relaxgrip.control import check_target_n
    from relaxgrip.experiments.budget_survey import SCATTER_GROUPS, survey_budget
    from relaxgrip.experiments.controlled_hold import (
        check_hold_duration_s,
        check_hold_temp_c,
        steady_window_s,
    )
    from relaxgrip.learning.store import load_models
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
    from relaxgrip.validate import check_jobs, parse_seeds

    seed_list = parse_seeds(seeds)
    check_target_n(target_n)
    check_hold_temp_c(temp_c)
    check_hold_duration_s(duration_s, "--duration-s")
    check_jobs(jobs)
    bundle = load_default_models() if models is None else load_models(
        models, icfn_feature_schema=ICFN_SCHEMA, rcfn_feature_schema=RCFN_SCHEMA)
    start = time.perf_counter()
    with console.status(f"{len(seed_list)} relax holds with their budgets …") if not json_out \
            else nullcontext():
        survey = survey_budget(seed_list, target_n, temp_c, duration_s, bundle, n_jobs=jobs)
    if json_out:
        emit_json(survey.to_dict())
        return
    parts, r2 = survey.parts(), survey.r2()
    lo, hi = steady_window_s(duration_s)
    table = Table(title=f"relax, {target_n:g} N, {temp_c:g} °C, seeds {seeds}: estimate − "
                        f"true force over {lo:.4g}–{hi:.4g} s",
                  caption="R²: share of the part's spread across seeds that the twin's draw "
                          "predicts, each seed left out of its fit; f0 / f1: that finger's "
                          "relaxing shares and times (the marker is on f0), run: contact "
                          "position and ambient")
    short = {"finger_0": "R² f0", "finger_1": "R² f1", "contact_ambient": "R² run",
             "all": "R² all"}
    for col in ("part", "mean (N)", "SD (N)", *(short[g] for g in SCATTER_GROUPS)):
        table.add_column(col, justify="left" if col == "part" else "right")
    for name, p in parts.items():
        table.add_row(name.removesuffix("_n"), f"{p['mean']:+.3f}", _fmt(p['sd'], ".3f"),
                      *(_fmt(r2[name][g], ".2f") for g in SCATTER_GROUPS))
    console.print(table)
    console.print(f"MAE from the target {survey.column('mae_n').mean():.3f} N; with the bias "
                  "measured on the other seeds taken off "
                  f"{_fmt(survey.bias_free_mae_n(), '.3f')} N")
    _print_observability(survey.observability())
    console.print(f"{survey.twin_version}, {time.perf_counter() - start:.1f} s")


def _fmt(value: float, spec: str) -> str:
    """``value`` in ``spec``, or a dash where there is no figure (NaN)."""
    return format(value, spec) if math.isfinite(value) else "–"


def _print_observability(seen: dict[str, Any]) -> None:
    """The budget survey's second table: what relax reads of its run, against the draw."""
    table = Table(title=f"What relax reads by {seen['at_s']:.4g} s of the hold (the steady "
                        "state's start), across seeds",
                  caption="r: correlation with the log of finger 0's and finger 1's relaxing "
                          "share (the twin's draw), and with the total")
    for col in ("read", "r f0 share", "r f1 share", "r total"):
        table.add_column(col, justify="left" if col == "read" else "right")
    for name, r in seen["correlation"].items():
        label = "total (estimate − true)" if name == "total_n" else name
        table.add_row(label, *(_fmt(r[k], "+.2f") for k in ("finger_0", "finger_1", "total_n")))
    console.print(table)
    mae = seen["corrected_mae_n"]
    console.print(f"A per-run correction fitted (each seed left out) on these reads would leave "
                  f"{_fmt(mae['percepts'], '.3f')} N; on finger 0's true share "
                  f"{_fmt(mae['finger_0_share'], '.3f')} N, on both fingers' "
                  f"{_fmt(mae['both_shares'], '.3f')} N (the bias alone "
                  f"{_fmt(mae['bias'], '.3f')} N)")
