"""The closed-loop calibrations on recorded holds (``calibrate-hold`` and ``calibrate-band``
with ``--recordings``).

:func:`~relaxgrip.experiments.hold_calibration.calibrate_hold` and
:func:`~relaxgrip.experiments.band_calibration.calibrate_band` measure on the
twin, which is right for the twin and for the models trained on its data.  A
lab's own gripper, with its own models, has its own errors: these measure
them on the lab's recordings of regulated holds (``relax`` or ``observer``)
with a force reference (the twin's truth, or a force sensor's
``/relaxgrip/force_ref`` channel).  Each recording's frames are perceived
again and the estimator replayed on them
(:func:`~relaxgrip.recording.replay.replay_periods`); on lossless frames the
replayed series are the loop's bit for bit, so a calibration on recordings
of the twin's holds is the twin's calibration of those holds.

* :func:`calibration_from_recordings`: ``relax`` replayed uncalibrated; each
  recording is one hold of the grid, its target and temperature the recorded
  plan's, and every target needs holds at every temperature, two or more of
  each.  The recorded controller acted on its own estimate, which may have
  been calibrated: the replay follows the closure it made, not the one an
  uncalibrated controller would have made.  On twelve 100 s holds that moved
  a condition's mean by 0.002-0.010 N (docs/hold-experiments.md, session 39).
* :func:`calibrate_band_on_recordings`: the ``observer`` replayed as it
  holds; each recording a seed of the band's intervals.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.experiments.band_calibration import (
    BandCalibration,
    BandHold,
    BandSamples,
    BandScales,
    calibration_of,
    measuring,
)
from relaxgrip.experiments.controlled_hold import map_holds
from relaxgrip.experiments.hold_calibration import (
    MIN_BIN_S,
    RECORDINGS_SOURCE,
    HoldCalibration,
    calibration_from_holds,
    condition_name,
    hold_row,
)
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.store import ModelBundle
from relaxgrip.perception.features import finger_temperature_c
from relaxgrip.recording.dataset import recording_files, truth_force_n
from relaxgrip.recording.reader import malformed_fields, read_replayable_session
from relaxgrip.recording.replay import replay_periods

__all__ = ["RECORDED_SCENARIO", "RecordedHold", "calibrate_band_on_recordings",
           "calibration_from_recordings", "recorded_hold", "recorded_plan"]

FloatArray = NDArray[np.float64]

#: Estimators whose recordings are regulated holds the calibrations take.
REGULATED = ("relax", "observer")
#: The one scenario of a band calibration on recordings, a row per recording.
RECORDED_SCENARIO = "recorded"


@dataclass(frozen=True)
class RecordedHold:
    """One recording's hold, an estimator replayed on it (:func:`recorded_hold`).

    Attributes
    ----------
    path : Path
    target_n, temp_c : float
        The recorded plan's target (N) and finger temperature (°C; nan for a
        plan by stiffness mode).
    length_s : float
        How long the hold was to last: the plan's ``hold_s``, or where the
        recording's hold ended when the plan held until released.
    t_s : ndarray
        Time since the hold's onset of each period from the onset on (s).
    estimate_n : ndarray
        The replayed estimate (N).
    truth_n : ndarray
        The force reference (N; nan in a period without one).
    f_onset_n : ndarray
        The estimator's ``F_inst`` (N; nan before it has one).
    temps_c : list of float
        The finger temperature the estimator read, each period of the hold
        with an infrared percept.
    band_lo_n, band_hi_n, band_drift_n : ndarray
        The ``observer``'s band and its drift part (N; nan for ``relax``).
    ir_temp_c : ndarray
        The temperature loop's reading of the fingers, their mean (°C; nan
        where none was recorded): the twin's holds place the band's samples
        by it (:meth:`relaxgrip.experiments.band_calibration.BandSamples.of`).
    icfn_n : ndarray
        The per-frame ICFN as replayed (N), for its drift.
    """

    path: Path
    target_n: float
    temp_c: float
    length_s: float
    t_s: FloatArray
    estimate_n: FloatArray
    truth_n: FloatArray
    f_onset_n: FloatArray
    temps_c: list[float]
    band_lo_n: FloatArray
    band_hi_n: FloatArray
    band_drift_n: FloatArray
    ir_temp_c: FloatArray
    icfn_n: FloatArray

    def within(self, duration_s: float) -> NDArray[np.bool_]:
        """The periods of the hold's first ``duration_s`` (from its onset on)."""
        return self.t_s <= duration_s + 1e-9

    def row(self, duration_s: float) -> dict[str, Any]:
        """The hold as a calibration stores it (:func:`hold_row`), over ``duration_s``.

        Raises
        ------
        InputError
            No force reference over the hold's steady state.
        """
        try:
            row = hold_row(self.t_s, self.estimate_n, self.truth_n,
                           self.f_onset_n, self.temps_c, self.target_n, duration_s, self.icfn_n)
        except InputError as exc:
            raise InputError(f"{self.path}: {exc}") from None
        return {**row, "recording": self.path.name}


def recorded_plan(path: Path) -> tuple[float, float, float]:
    """A recording's hold as planned, from its session message alone: target (N),
    finger temperature (°C; nan for a plan by stiffness mode) and length (s; inf: held
    until released).

    Raises
    ------
    InputError
        Not a replayable recording, or one of another estimator than
        ``relax`` or ``observer``.
    """
    session = read_replayable_session(path)
    estimator = session.get("estimator")
    if estimator not in REGULATED:
        raise InputError(f"{path}: a {estimator} hold; the calibrations take holds regulated "
                         f"by {' or '.join(REGULATED)}")
    plan = session.get("plan")
    scenario = session.get("scenario") or {}
    if isinstance(scenario, dict) and scenario:
        given = ", ".join(f"--{k.replace('_', '-')} {v}" for k, v in scenario.items())
        raise InputError(f"{path}: a hold with {given}; the calibrations take holds at their "
                         "plan's constant target and temperature")
    with malformed_fields(path):
        if not isinstance(plan, dict):
            raise TypeError(f"the session's plan is {type(plan).__name__}, not an object")
        temp_c = plan["temp_c"]
        return (float(plan["target_n"]), math.nan if temp_c is None else float(temp_c),
                float(plan["hold_s"]))


def recorded_hold(path: Path, models: ModelBundle, estimator: str = "relax",
                  observer: ObserverModel | None = None) -> RecordedHold:
    """Replay one recording's hold with ``models``' ``estimator``.

    Parameters
    ----------
    path : Path
    models : ModelBundle
        As the estimator is to run: strip their calibration for ``relax``'s
        own (:func:`calibration_from_recordings` does).
    estimator : {"relax", "observer"}
    observer : ObserverModel, optional
        The observer's parameters (default: the shipped ones).

    Raises
    ------
    InputError
        As :func:`recorded_plan`; no hold in the recording, or more than one;
        a hold that ended before its plan's length; no force reference in it.
    """
    target_n, temp_c, hold_s = recorded_plan(path)
    onset_s = end_s = math.nan
    onsets = 0
    rows: list[tuple[float, ...]] = []
    temps: list[float] = []
    with malformed_fields(path):
        for period, percept, estimate in replay_periods(path, models, estimator=estimator,
                                                        observer=observer):
            for event in period.events:
                if event["kind"] == "hold_onset":
                    onsets += 1
                    onset_s = float(event["t_s"])
                elif event["kind"] == "phase" and event["detail"] == "release":
                    end_s = float(event["t_s"])
            if onsets == 0:
                continue
            _check_constant(path, period.messages, target_n, temp_c, period.t_s - onset_s)
            rows.append((period.t_s - onset_s, estimate.force_n,
                         truth_force_n(period.messages), estimate.f_onset_n,
                         estimate.band_lo_n, estimate.band_hi_n, estimate.band_drift_n,
                         _reading_c(period.messages), estimate.f_icfn_n))
            if math.isfinite(estimate.hold_s) and percept.thermal is not None:
                value = finger_temperature_c(percept.thermal)
                if math.isfinite(value):
                    temps.append(value)
    if onsets != 1:
        raise InputError(f"{path}: {onsets} holds in the recording; calibrating takes one hold "
                         "per recording" if onsets else f"{path}: the recording has no hold")
    cols = np.array(rows, dtype=np.float64).reshape(-1, 9)
    after = cols[:, 0] >= 0.0
    cols = cols[after]
    reached = float(cols[-1, 0]) if cols.size else 0.0
    length = hold_s if math.isfinite(hold_s) else (
        end_s - onset_s if math.isfinite(end_s) else reached)
    if reached < length - MIN_BIN_S:
        raise InputError(f"{path}: the hold was recorded for {reached:.1f} s of its "
                         f"{length:.4g} s")
    if not np.isfinite(cols[:, 2]).any():
        raise InputError(f"{path}: no force reference (the twin's truth or a force sensor's "
                         "/relaxgrip/force_ref) in the hold")
    t, force, truth, f_onset, lo, hi, drift, read_c, icfn = cols.T
    return RecordedHold(path, target_n, temp_c, float(length), t, force, truth,
                        f_onset, temps, lo, hi, drift, read_c, icfn)


def _reading_c(messages: dict[str, Any]) -> float:
    """The temperature loop's reading of the fingers in a period, their mean (°C; nan
    without one)."""
    read = messages.get("/relaxgrip/temperature", {}).get("ir_temp_c")
    try:
        return 0.5 * (float(read[0]) + float(read[1]))
    except (TypeError, IndexError, ValueError):  # none recorded (null), or not a pair
        return math.nan


def _check_constant(path: Path, messages: dict[str, Any], target_n: float, temp_c: float,
                    hold_s: float) -> None:
    """Refuse a hold whose target or setpoint left the plan's (an operator's change on the
    dashboard): the calibrations bin holds by their plan's target and temperature."""
    target = messages.get("/relaxgrip/phase", {}).get("target_n")  # not in older recordings
    if target is not None and abs(float(target) - target_n) > 1e-3:
        raise InputError(f"{path}: the hold's target went from {target_n:g} to "
                         f"{float(target):.2f} N {hold_s:.1f} s into it; the calibrations take "
                         "holds at their plan's constant target and temperature")
    setpoint = messages.get("/relaxgrip/temperature", {}).get("setpoint_c")
    if setpoint is not None and math.isfinite(temp_c) and abs(float(setpoint) - temp_c) > 0.01:
        raise InputError(f"{path}: the hold's setpoint went from {temp_c:g} to "
                         f"{float(setpoint):.2f} °C {hold_s:.1f} s into it; the calibrations "
                         "take holds at their plan's constant target and temperature")


def _replayed(args: tuple[Path, ModelBundle, str, ObserverModel | None]) -> RecordedHold:
    return recorded_hold(*args)


def _recorded_grid(paths: Sequence[Path | str]) -> tuple[list[Path], list[float], list[float]]:
    """The recordings ``paths`` name and their grid's targets (N) and temperatures (°C), the
    plans checked before any is replayed.

    Raises
    ------
    InputError
        As :func:`recorded_plan` for any recording; a plan by stiffness mode;
        a target lacking a temperature or a condition with fewer than two
        recordings.
    """
    files = recording_files(paths)
    plans = [recorded_plan(path) for path in files]
    for path, (_, temp, _) in zip(files, plans, strict=True):
        if math.isnan(temp):
            raise InputError(f"{path}: the hold's plan gives a stiffness mode, not a "
                             "temperature; the calibration's grid takes holds at a set "
                             "temperature")
    targets = sorted({target for target, _, _ in plans})
    temps = sorted({temp for _, temp, _ in plans})
    for target in targets:
        for temp in temps:
            count = sum((t, c) == (target, temp) for t, c, _ in plans)
            if count < 2:
                raise InputError(
                    f"the recordings hold {target:g} N at {temp:g} °C {count} time(s): every "
                    "target of the grid needs holds at every temperature, two or more each")
    return files, targets, temps


def calibration_from_recordings(paths: Sequence[Path | str], models: ModelBundle,
                                n_jobs: int = 1) -> HoldCalibration:
    """``relax``'s closed-loop error measured on recorded holds (see the module).

    Parameters
    ----------
    paths : sequence of Path
        Recordings (``.mcap``; a directory stands for the ``*.mcap`` in it),
        one regulated hold each.
    models : ModelBundle
        The models to calibrate; any calibration they carry is not used.
    n_jobs : int
        Recordings replayed in parallel.

    Returns
    -------
    HoldCalibration
        Over the grid of the recordings' targets and temperatures, every hold
        cut at the shortest one's length; each hold's ``seed`` is its place in
        the recordings' order and ``recording`` its file name.

    Raises
    ------
    InputError
        As :func:`recorded_hold` for any recording, and a grid with a target
        lacking a temperature or a condition with fewer than two recordings.
    """
    files, targets, temps = _recorded_grid(paths)
    bundle = replace(models, hold_bias=None)
    holds = map_holds(_replayed, [(path, bundle, "relax", None) for path in files], n_jobs)
    duration = min(h.length_s for h in holds)
    by_condition: dict[str, list[dict[str, Any]]] = {}
    for seed, hold in enumerate(holds):
        name = condition_name(hold.target_n, hold.temp_c)
        by_condition.setdefault(name, []).append({"seed": seed, **hold.row(duration)})
    result = calibration_from_holds(targets, temps, list(range(len(holds))), duration,
                                    by_condition)
    return replace(result, twin_version=RECORDINGS_SOURCE)


def calibrate_band_on_recordings(observer: ObserverModel, paths: Sequence[Path | str],
                                 models: ModelBundle, n_jobs: int = 1) -> BandCalibration:
    """The observer's band scales set on recorded holds, as :func:`calibrate_band` sets them
    on the twin's.

    Each recording's frames are perceived again and the ``observer`` with
    ``models`` (their calibration included, as it holds) replayed on them;
    its error against the force reference over the hold, against the two
    parts of its band, sets the scales.  Each recording counts as a seed of
    the resampled intervals; the report's one scenario, ``recorded``, has a
    row per recording.

    Parameters
    ----------
    observer : ObserverModel
        Fitted observer; the result does not depend on its scales.
    paths : sequence of Path
        Recordings (a directory stands for the ``*.mcap`` in it), each one
        ``relax`` or ``observer`` hold with a force reference.
    models : ModelBundle
        ICFN and RCFN the observer reads.
    n_jobs : int
        Recordings replayed in parallel.

    Raises
    ------
    InputError
        As :func:`recorded_hold`; no band in the holds (:func:`calibration_of`).
    """
    files = recording_files(paths)
    for path in files:  # every plan checked before any replay
        recorded_plan(path)
    previous = BandScales.of(observer)
    observer = measuring(observer)
    used = BandScales.of(observer)
    holds = map_holds(_replayed, [(path, models, "observer", observer) for path in files], n_jobs)
    measured = []
    for seed, hold in enumerate(holds):
        keep = hold.within(hold.length_s)
        samples = BandSamples.of_series(
            hold.estimate_n[keep], hold.truth_n[keep], hold.band_lo_n[keep],
            hold.band_hi_n[keep], hold.band_drift_n[keep], used, hold.ir_temp_c[keep])
        row = {"recording": hold.path.name, "mae_n": hold.row(hold.length_s)["mae_n"]}
        measured.append(BandHold(RECORDED_SCENARIO, {"source": RECORDINGS_SOURCE}, seed, row,
                                 samples))
    # The plans' temperatures (a plan by stiffness mode has none): holds at two or more set
    # the band's temperature factors.
    temps = [hold.temp_c for hold in holds if math.isfinite(hold.temp_c)]
    return calibration_of(measured, range(len(holds)), observer.band_level, previous, temps)
