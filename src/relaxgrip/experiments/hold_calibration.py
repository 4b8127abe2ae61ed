"""Calibrating ``relax``'s closed-loop error on holds (``relaxgrip calibrate-hold``).

``relax`` holds the force its estimate reads; the estimate is off the true
force by an amount that is mostly the same from run to run at one force and
temperature (:mod:`relaxgrip.learning.hold_bias`).  This runs the closed-loop
hold with the uncalibrated estimator on a grid of targets and temperatures,
on seeds the models are not checked on, against the force ball's truth, and
records the mean of estimate − truth per condition and time bin.  The grid's
force and temperature knots are where the estimator itself reads them (its
``F_inst`` and its finger temperature, averaged over the condition's holds),
so the lookup at run time uses the same readings.

A hold's error is mostly one offset per run, so each knot is as sure as the
number of seeds: its standard error over the seeds is in the record.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import BackendInfo, Command, Observation
from relaxgrip.control import GraspController, check_target_n
from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import (
    PAPER_DURATION_S,
    check_hold_temp_c,
    map_holds,
    run_hold,
)
from relaxgrip.learning.hold_bias import HoldBias
from relaxgrip.learning.store import ModelBundle
from relaxgrip.learning.training import load_default_models
from relaxgrip.perception.features import finger_temperature_c
from relaxgrip.serialize import json_safe
from relaxgrip.twin import TWIN_VERSION
from relaxgrip.validate import check_positive

__all__ = ["DEFAULT_SEEDS", "DEFAULT_TARGETS_N", "DEFAULT_TEMPS_C", "TIME_EDGES_S",
           "HoldCalibration", "calibrate_hold", "time_bins"]

FloatArray = NDArray[np.float64]

#: The grid the shipped models were calibrated on: the issue's 1-8 N and 30-55 °C.
DEFAULT_TARGETS_N = (1.0, 3.0, 5.0, 8.0)
DEFAULT_TEMPS_C = (30.0, 40.0, 48.0, 55.0)
#: Seeds the shipped figures are not measured on (those use 0-47).
DEFAULT_SEEDS = tuple(range(1000, 1008))
#: Edges of the time bins since the onset (s); each bin's mean error sits at its centre
#: on ``log(1 + t)``.  The early bins are short: the error settles over the first 30 s.
TIME_EDGES_S = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0, 190.0, 280.0)


def time_bins(duration_s: float) -> list[tuple[float, float]]:
    """The bins of :data:`TIME_EDGES_S` a hold of ``duration_s`` reaches, the last cut there.

    A hold longer than 280 s has one more, from 280 s to its end.
    """
    edges = [e for e in TIME_EDGES_S if e < duration_s]
    ends = [*edges[1:], duration_s]
    return list(zip(edges, ends, strict=True))


def _bin_centre(lo: float, hi: float) -> float:
    return math.expm1(0.5 * (math.log1p(lo) + math.log1p(hi)))


class _TemperatureTap:
    """Records the finger temperature the estimator reads, every hold frame with an image."""

    def __init__(self) -> None:
        self.temps_c: list[float] = []

    def start(self, info: BackendInfo, controller: GraspController, t_s: float) -> None:
        self.temps_c.clear()

    def step(self, obs: Observation, controller: GraspController, command: Command) -> None:
        percept = controller.percept
        if (math.isfinite(controller.estimate.hold_s) and percept is not None
                and percept.thermal is not None):
            value = finger_temperature_c(percept.thermal)
            if math.isfinite(value):
                self.temps_c.append(value)


def _one(args: tuple[float, float, int, float, ModelBundle]) -> dict[str, Any]:
    """One uncalibrated hold: its error per time bin and what the estimator read."""
    target_n, temp_c, seed, duration_s, models = args
    tap = _TemperatureTap()
    hold = run_hold("relax", target_n, duration_s, temp_c, seed, models, recorder=tap)
    err = hold.estimate_n - hold.truth_n
    bins = []
    for lo, hi in time_bins(duration_s):
        rows = (hold.t_s >= lo) & (hold.t_s <= hi) & np.isfinite(err)
        bins.append(float(np.mean(err[rows])) if rows.any() else math.nan)
    onset = hold.series("f_onset_n")
    onset = onset[np.isfinite(onset)]
    metrics = hold.metrics()
    return {"seed": seed, "bins_n": bins,
            "f_inst_n": float(onset[-1]) if onset.size else math.nan,
            "temp_c": float(np.mean(tap.temps_c)) if tap.temps_c else math.nan,
            "mae_n": metrics["mae_n"], "est_error_mean_n": metrics["est_error_mean_n"]}


@dataclass(frozen=True)
class HoldCalibration:
    """What a calibration measured.

    Attributes
    ----------
    bias : HoldBias
        The grid of mean errors, for the model directory.
    targets_n, temps_c : list of float
        The conditions' targets (N) and temperatures (°C).
    seeds : list of int
    duration_s : float
    holds : dict of str to list of dict
        Per condition (``"5N 40C"``), each seed's hold: its error per time
        bin, ``F_inst``, finger temperature as read, MAE and mean estimate error
        over the steady state.
    twin_version : str
    """

    bias: HoldBias
    targets_n: list[float]
    temps_c: list[float]
    seeds: list[int]
    duration_s: float
    holds: dict[str, list[dict[str, Any]]]
    twin_version: str = TWIN_VERSION

    def summary(self) -> dict[str, dict[str, float]]:
        """Per condition: the steady state's mean estimate error, its SE over the seeds, the MAE."""
        out = {}
        for name, rows in self.holds.items():
            err = np.array([r["est_error_mean_n"] for r in rows])
            se = float(err.std(ddof=1) / math.sqrt(err.size)) if err.size > 1 else math.nan
            out[name] = {"est_error_mean_n": float(err.mean()), "se_n": se,
                         "mae_n": float(np.mean([r["mae_n"] for r in rows]))}
        return out

    def record(self) -> dict[str, Any]:
        """The manifest's record beside the grid (JSON: a figure there is none of is null)."""
        return json_safe({
            "method": "mean of estimate - true force of uncalibrated relax holds per target, "
                      "temperature and time bin (relaxgrip calibrate-hold)",
            "targets_n": self.targets_n, "temps_c": self.temps_c, "seeds": self.seeds,
            "duration_s": self.duration_s, "time_bins_s": time_bins(self.duration_s),
            "twin_version": self.twin_version, "summary": self.summary(), "holds": self.holds,
        })


def _condition(target_n: float, temp_c: float) -> str:
    return f"{target_n:g}N {temp_c:g}C"


def _axis(values: Sequence[float], name: str) -> list[float]:
    out = sorted({float(v) for v in values})
    if not out:
        raise InputError(f"calibrating the hold needs at least one {name}")
    return out


def calibrate_hold(targets_n: Sequence[float] = DEFAULT_TARGETS_N,
                   temps_c: Sequence[float] = DEFAULT_TEMPS_C,
                   seeds: Sequence[int] = DEFAULT_SEEDS,
                   duration_s: float = PAPER_DURATION_S, models: ModelBundle | None = None,
                   n_jobs: int = 1) -> HoldCalibration:
    """Run uncalibrated ``relax`` holds on the grid and measure their mean error.

    Parameters
    ----------
    targets_n, temps_c : sequence of float
        The grid's targets (N) and finger temperatures (°C); every pair is held.
    seeds : sequence of int
        Twin seeds (take ones the models are not checked on).
    duration_s : float
        Hold length (s); the grid's times reach it.
    models : ModelBundle, optional
        The models to calibrate (default: the shipped ones); any calibration
        they carry is not used while measuring.
    n_jobs : int
        Holds in parallel.

    Raises
    ------
    InputError
        An empty axis or no seeds, a target or temperature out of range,
        or conditions whose readings do not order as their setpoints.
    """
    targets = _axis(targets_n, "target")
    temps = _axis(temps_c, "temperature")
    if not seeds:
        raise InputError("calibrating the hold needs at least one seed")
    if min(seeds) < 0:
        raise InputError(f"seeds must be >= 0, got {min(seeds)}")
    for target in targets:
        check_target_n(target)
    for temp in temps:
        check_hold_temp_c(temp)
    check_positive(duration_s, "hold duration")
    bundle = replace(models if models is not None else load_default_models(), hold_bias=None)
    jobs = [(target, temp, int(seed), duration_s, bundle)
            for target in targets for temp in temps for seed in seeds]
    results = map_holds(_one, jobs, n_jobs)
    holds: dict[str, list[dict[str, Any]]] = {}
    for (target, temp, *_), row in zip(jobs, results, strict=True):
        holds.setdefault(_condition(target, temp), []).append(row)
    bins = time_bins(duration_s)
    values = np.empty((len(targets), len(temps), len(bins)))
    f_inst = np.empty((len(targets), len(temps)))
    read_c = np.empty((len(targets), len(temps)))
    for i, target in enumerate(targets):
        for j, temp in enumerate(temps):
            rows = holds[_condition(target, temp)]
            values[i, j] = np.nanmean([r["bins_n"] for r in rows], axis=0)
            f_inst[i, j] = np.nanmean([r["f_inst_n"] for r in rows])
            read_c[i, j] = np.nanmean([r["temp_c"] for r in rows])
    if not (np.all(np.isfinite(values)) and np.all(np.isfinite(f_inst))
            and np.all(np.isfinite(read_c))):
        raise InputError("a calibration condition gave no estimate, onset or temperature")
    forces = f_inst.mean(axis=1)
    readings = read_c.mean(axis=0)
    for name, axis, setpoints in (("onset forces", forces, targets),
                                  ("temperatures", readings, temps)):
        if np.any(np.diff(axis) <= 0):
            raise InputError(f"the holds' {name} as read ({np.round(axis, 3).tolist()}) do not "
                             f"rise with their setpoints ({setpoints}): space them further")
    bias = HoldBias(forces, readings, np.array([_bin_centre(lo, hi) for lo, hi in bins]), values)
    return HoldCalibration(bias, targets, temps, [int(s) for s in seeds], duration_s, holds)
