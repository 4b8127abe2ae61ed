"""``relaxgrip calibrate MODELDIR``: the observer's calibration on a dozen regulated holds.

The ``observer`` runs uncalibrated (its other parts on) through up to
:data:`MAX_HOLDS` holds, on the twin (:func:`twin_holds`) or replayed on a
lab's recordings (:func:`recorded_holds`), and its estimate is compared with
the **force reference**'s readings (``force_ref``: the force sensor in the
object, noisy as a lab has it; never the twin's truth).  The error model and
the split-conformal band are fitted on those holds
(:func:`relaxgrip.learning.calibration.fit_calibration`) and written into the
model directory's manifest (:func:`relaxgrip.learning.store.set_calibration`).

The twin's holds span the operating range: 1, 5 and 8 N at 40 and 55 °C, two
seeds each from the design seeds (:data:`DEFAULT_SEEDS`), 280 s each: twelve
holds, an hour of a lab's time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from relaxgrip.control import EstimatorKind
from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import (
    PAPER_DURATION_S,
    HoldResult,
    map_holds,
    run_hold,
    steady_window_s,
)
from relaxgrip.learning.calibration import Calibration, CalibrationHold, fit_calibration
from relaxgrip.learning.store import ModelBundle, set_calibration
from relaxgrip.twin import TwinConfig

__all__ = [
    "DEFAULT_CONDITIONS",
    "DEFAULT_SEEDS",
    "MAX_HOLDS",
    "CalibrationRun",
    "calibrate",
    "calibration_hold",
    "recorded_holds",
    "require_calibration",
    "twin_holds",
]

#: Most holds a calibration takes: an hour of 280 s holds.
MAX_HOLDS = 12
#: The twin's calibration conditions (target N, temperature °C), each held on two seeds.
DEFAULT_CONDITIONS = ((1.0, 40.0), (5.0, 40.0), (8.0, 40.0),
                      (1.0, 55.0), (5.0, 55.0), (8.0, 55.0))
#: Design seeds of the twin's calibration holds (figures are reported on seeds >= 5000).
DEFAULT_SEEDS = tuple(range(1000, 1012))


@dataclass(frozen=True)
class CalibrationRun:
    """A calibration and the holds it was fitted on.

    Attributes
    ----------
    calibration : Calibration
        The fitted coefficients, band and record.
    holds : list of CalibrationHold
        The holds, as the fit read them.
    written : Path or None
        The manifest written (None for a dry run).
    """

    calibration: Calibration
    holds: list[CalibrationHold]
    written: Path | None

    def to_dict(self) -> dict[str, Any]:
        """The ``relaxgrip calibrate --json`` object."""
        return {**self.calibration.to_dict(),
                "written": None if self.written is None else str(self.written)}


def uncalibrated(models: ModelBundle) -> ModelBundle:
    """``models`` without their calibration: the observer the holds measure."""
    return replace(models, calibration=None)


def require_calibration(models: ModelBundle, estimator: EstimatorKind | str) -> None:
    """Refuse the ``observer`` on a model directory without a calibration.

    Raises
    ------
    InputError
        Naming the directory and the command that calibrates it.
    """
    if EstimatorKind(estimator) is EstimatorKind.OBSERVER and models.calibration is None:
        where = models.directory if models.directory is not None else "the models"
        raise InputError(f"{where} has no calibration: the observer needs one "
                         f"(relaxgrip calibrate {where})")


def calibration_hold(name: str, hold_s: np.ndarray, estimate_n: np.ndarray,
                     f_onset_n: np.ndarray, k_n: np.ndarray, tau_s: np.ndarray,
                     force_ref_n: np.ndarray, duration_s: float) -> CalibrationHold:
    """One hold's series as the calibration reads them.

    Raises
    ------
    InputError
        No ``F_inst`` in the hold, or no force reference reading.
    """
    onset = f_onset_n[np.isfinite(f_onset_n)]
    if onset.size == 0:
        raise InputError(f"{name}: the estimator gave no onset force in the hold")
    if not np.isfinite(force_ref_n).any():
        raise InputError(f"{name}: no force reference reading (force_ref) in the hold")
    with np.errstate(invalid="ignore"):
        relaxed = k_n * -np.expm1(-hold_s / tau_s)
    return CalibrationHold(name, hold_s, estimate_n, float(onset[-1]), relaxed, force_ref_n,
                           steady_window_s(duration_s))


def _from_result(result: HoldResult, name: str) -> CalibrationHold:
    f_onset, k, tau, ref = (result.series(c) for c in ("f_onset_n", "k_n", "tau_s",
                                                       "force_ref_n"))
    return calibration_hold(name, result.t_s, result.estimate_n, f_onset, k, tau, ref,
                            result.duration_s)


def _run(args: tuple[float, float, int, float, ModelBundle, TwinConfig | None]
         ) -> CalibrationHold:
    target, temp, seed, duration, models, config = args
    result = run_hold(EstimatorKind.OBSERVER, target, duration, temp, seed, models,
                      config=config)
    return _from_result(result, f"seed {seed}, {target:g} N, {temp:g} °C")


def twin_holds(models: ModelBundle, seeds: Sequence[int] = DEFAULT_SEEDS,
               conditions: Sequence[tuple[float, float]] = DEFAULT_CONDITIONS,
               duration_s: float = PAPER_DURATION_S, n_jobs: int = 1,
               config: TwinConfig | None = None) -> list[CalibrationHold]:
    """The uncalibrated observer's holds on the twin: seed ``i`` at condition ``i`` mod the
    conditions' count."""
    bundle = uncalibrated(models)
    jobs = [(*conditions[i % len(conditions)], seed, duration_s, bundle, config)
            for i, seed in enumerate(seeds)]
    return map_holds(_run, jobs, n_jobs)


def recorded_holds(paths: Sequence[Path | str], models: ModelBundle,
                   n_jobs: int = 1) -> list[CalibrationHold]:
    """The uncalibrated observer replayed on recorded regulated holds with a force reference.

    Each recording holds one hold; its force reference is the
    ``/relaxgrip/force_ref`` channel (the mean of its readings in each period).

    Raises
    ------
    InputError
        No recording, a recording without a hold or without a force reference.
    """
    from relaxgrip.recording.dataset import recording_files

    files = recording_files(paths)
    if not files:
        raise InputError("no recordings to calibrate on")
    bundle = uncalibrated(models)
    return map_holds(_replayed, [(path, bundle) for path in files], n_jobs)


def _replayed(args: tuple[Path, ModelBundle]) -> CalibrationHold:
    from relaxgrip.recording.reader import malformed_fields
    from relaxgrip.recording.replay import replay_periods

    path, models = args
    onset = math.nan
    rows: list[tuple[float, ...]] = []
    with malformed_fields(path):
        for period, _, est in replay_periods(path, models, estimator="observer"):
            for event in period.events:
                if event["kind"] == "hold_onset":
                    onset = float(event["t_s"])
            if math.isnan(onset) or period.messages["/relaxgrip/phase"]["phase"] != "hold":
                continue
            ref = period.get("/relaxgrip/force_ref")
            readings = [] if ref is None else [float(v) for v in ref["force_n"]]
            rows.append((period.t_s - onset, est.force_n, est.f_onset_n, est.k_n, est.tau_s,
                         float(np.mean(readings)) if readings else math.nan))
    if not rows:
        raise InputError(f"{path}: the recording has no hold")
    t, force, f_onset, k, tau, ref = np.array(rows, dtype=np.float64).T
    return calibration_hold(str(path), t, force, f_onset, k, tau, ref, float(t[-1]))


def calibrate(models_dir: Path, models: ModelBundle, *, seeds: Sequence[int] | None = None,
              recordings: Sequence[Path | str] | None = None,
              duration_s: float = PAPER_DURATION_S, n_jobs: int = 1, dry_run: bool = False,
              command: str = "", config: TwinConfig | None = None) -> CalibrationRun:
    """Calibrate the observer of ``models`` (loaded from ``models_dir``) and write it there.

    On the twin (``seeds``, default :data:`DEFAULT_SEEDS`) or on ``recordings``;
    nothing is written with ``dry_run``.

    Raises
    ------
    InputError
        Both or more holds than :data:`MAX_HOLDS`; fewer than the fit needs; a
        hold without a force reference; the directory's models changed while
        the holds ran.
    """
    if recordings is not None and seeds is not None:
        raise InputError("calibrate on twin seeds or on recordings, not both")
    if recordings is not None:
        from relaxgrip.recording.dataset import recording_files

        files = recording_files(recordings)
        if len(files) > MAX_HOLDS:
            raise InputError(f"{len(files)} recordings: a calibration takes at most "
                             f"{MAX_HOLDS} holds")
        holds = recorded_holds(files, models, n_jobs)
        source: dict[str, Any] = {"source": "recordings"}
    else:
        chosen = tuple(DEFAULT_SEEDS if seeds is None else seeds)
        if len(chosen) > MAX_HOLDS:
            raise InputError(f"{len(chosen)} seeds: a calibration takes at most {MAX_HOLDS} "
                             "holds")
        from relaxgrip.learning.calibration import MIN_HOLDS

        if len(chosen) < MIN_HOLDS:
            raise InputError(f"{len(chosen)} seed(s): a calibration needs at least "
                             f"{MIN_HOLDS} holds")
        holds = twin_holds(models, chosen, duration_s=duration_s, n_jobs=n_jobs, config=config)
        source = {"source": "twin", "seeds": list(chosen), "duration_s": duration_s,
                  "conditions": [list(c) for c in DEFAULT_CONDITIONS]}
    calibration = fit_calibration(holds, {**source, "command": command})
    written = None if dry_run else set_calibration(models_dir, calibration, models.manifest)
    return CalibrationRun(calibration, holds, written)
