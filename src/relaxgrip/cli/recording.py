"""``relaxgrip replay``, ``relaxgrip recover`` and ``relaxgrip dataset from-recordings``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from relaxgrip.cli._app import app, console, emit_json, err_console, float_option, int_option
from relaxgrip.cli.learning import dataset_app
from relaxgrip.errors import InputError

if TYPE_CHECKING:
    from relaxgrip.learning.store import ModelBundle
    from relaxgrip.recording.replay import ReplayResult


def _models(models: Path | None, recordings: list[Path]) -> ModelBundle:
    """The models in ``models``, or those the recordings ran with (the shipped ones for
    recordings that do not name theirs)."""
    from relaxgrip.learning.store import load_models
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
    from relaxgrip.recording.provenance import recorded_models

    if models is not None:
        return load_models(models, icfn_feature_schema=ICFN_SCHEMA,
                           rcfn_feature_schema=RCFN_SCHEMA)
    return recorded_models(recordings) or load_default_models()


@app.command("replay")
def replay_cmd(
    recording: Annotated[Path, typer.Argument(help="MCAP recording.", show_default=False)],
    models: Annotated[Path | None, typer.Option(
        "--models", help="Model directory (default: the models the recording ran with, "
                         "if they are still where it names them, or the shipped ones).",
        show_default=False)] = None,
    observer_dir: Annotated[Path | None, typer.Option(
        "--observer", help="Observer directory for an observer recording (relaxgrip "
                           "fit-observer; default: the one the recording ran with).",
        show_default=False)] = None,
    plot: Annotated[Path | None, typer.Option(
        "--plot", help="Figure of recorded and replayed estimate (.png/.pdf/.svg).",
        show_default=False)] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Re-run perception and estimation on a recording and compare with what it recorded."""
    from relaxgrip.learning.observer import load_observer
    from relaxgrip.plots.common import check_plot_path
    from relaxgrip.recording.provenance import recorded_observer
    from relaxgrip.recording.reader import read_replayable_session
    from relaxgrip.recording.replay import replay

    if plot is not None:
        check_plot_path(plot)
    read_replayable_session(recording)  # a file it cannot replay is said before its models
    observer = (recorded_observer([recording]) if observer_dir is None
                else load_observer(observer_dir))
    result = replay(recording, _models(models, [recording]), observer=observer)
    if plot is not None:
        _plot_replay(result, plot)
    if json_out:
        emit_json(result.to_dict())
        return
    m = result.metrics()
    console.print(
        f"{recording}: {m['periods']} periods, estimator {result.estimator}\n"
        f"estimate: max |recorded - replayed| {m['estimate_max_abs_diff_n']:.4f} N, mean "
        f"{m['estimate_mean_abs_diff_n']:.4f} N over {m['estimate_compared']} periods; "
        f"valid in the same periods: {m['estimate_valid_agreement']:.1%}\n"
        f"ICFN per frame: max {m['icfn_max_abs_diff_n']:.4f} N, mean "
        f"{m['icfn_mean_abs_diff_n']:.4f} N; marker status agreement "
        f"{m['marker_status_agreement']:.1%}")
    differ = [d for d in result.models_differ if d != "calibration"]
    if differ:
        console.print(f"replayed with other models than the recording ran with "
                      f"({', '.join(differ)} differ): the differences include theirs")
    if m["calibration_valid_agreement"] < 1.0:
        console.print("the calibration taken off the estimate was not the same: the model "
                      "directory was calibrated (relaxgrip calibrate-hold) differently from the "
                      "recording's")
    if plot is not None:
        console.print(f"figure: {plot}")


def _plot_replay(result: ReplayResult, path: Path) -> None:
    """Recorded and replayed estimate (and the truth) over time."""
    import numpy as np

    from relaxgrip.plots.common import new_figure, save_figure

    fig = new_figure(8, 4)
    ax = fig.add_subplot()
    ax.plot(result.t_s, result.recorded_n, label="recorded estimate", lw=1.5)
    ax.plot(result.t_s, result.replayed_n, "--", label="replayed estimate", lw=1.0)
    if result.truth_n.size and bool(np.isfinite(result.truth_n).any()):
        ax.plot(result.t_s, result.truth_n, color="k", alpha=0.5, lw=0.8, label="truth")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force (N)")
    ax.set_title(f"replay of {Path(result.path).name} ({result.estimator})")
    ax.legend()
    save_figure(fig, path)


@app.command("recover")
def recover_cmd(
    recording: Annotated[Path, typer.Argument(help="Killed (truncated) recording.",
                                              show_default=False)],
    out: Annotated[Path, typer.Argument(help="Complete MCAP file to write.",
                                        show_default=False)],
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Rewrite what a killed recording holds (every complete chunk) as a complete MCAP file."""
    from relaxgrip.recording.reader import recover

    report = recover(recording, out)
    if json_out:
        emit_json({"recording": str(recording), "out": str(out),
                   "was_complete": report.complete, "messages": report.messages,
                   "channels": report.channels, "end_s": report.end_s,
                   "damaged_chunks": report.damaged_chunks,
                   "expected_messages": report.expected_messages,
                   "lost_messages": report.lost_messages,
                   "stopped_early": report.stopped_early,
                   "lost_start_s": report.lost_start_s})
        return
    state = "was complete" if report.complete else "was truncated"
    damage = []
    if report.damaged_chunks:
        damage.append(f"{report.damaged_chunks} damaged chunk(s) skipped")
    if report.complete and report.stopped_early:
        damage.append("its records break off before the end")
    if report.lost_messages:
        damage.append(f"{report.lost_messages} of its {report.expected_messages} "
                      "messages lost")
    if report.lost_start_s is not None:
        damage.append(f"its start, up to {report.lost_start_s:.2f} s, with the marker's zero: "
                      "it can be read, not replayed")
    if damage:
        state = f"{state} but damaged ({'; '.join(damage)})"
    console.print(f"{recording} {state}: {report.messages} messages on {report.channels} "
                  f"channels up to {report.end_s:.2f} s written to {out}", soft_wrap=True)


@dataset_app.command("from-recordings")
def dataset_from_recordings_cmd(
    recordings: Annotated[list[Path], typer.Argument(
        help="Recordings (.mcap) or directories of them.", show_default=False)],
    out: Annotated[Path, typer.Option("--out", help="Dataset directory to write.",
                                      show_default=False)],
    seed: Annotated[int, int_option("--seed", help="Seed of the split by recording.")] = 0,
    icfn_every_s: Annotated[float, float_option(
        "--icfn-every-s", help="Loop time between ICFN samples (s).")] = 0.5,
    json_out: Annotated[bool, typer.Option("--json", help="Print the manifest as JSON.")] = False,
) -> None:
    """Turn recordings with a force ground truth into a dataset for ``relaxgrip train``."""
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.recording.dataset import dataset_from_recordings

    if seed < 0:
        raise InputError(f"--seed must be >= 0, got {seed}")
    # Only perception is used of the replay (the labels are the force reference's).
    manifest = dataset_from_recordings(recordings, out, load_default_models(), seed=seed,
                                       icfn_every_s=icfn_every_s)
    if json_out:
        emit_json(manifest)
        return
    counts = manifest["counts"]
    for path, note in manifest["notes"].items():
        err_console.print(f"{path}: {note}", markup=False, highlight=False, soft_wrap=True)
    for warning in manifest["warnings"]:
        err_console.print(f"warning: {warning}", markup=False, highlight=False, soft_wrap=True)
    console.print(f"{out}: {counts['icfn_samples']} ICFN samples, {counts['rcfn_sequences']} "
                  f"RCFN sequences from {len(manifest['notes'])} recordings; README.md "
                  "describes every column")
