"""Calibrating ``relax``'s closed-loop error on holds (``relaxgrip calibrate-hold``).

``relax`` holds the force its estimate reads; the estimate is off the true
force by an amount that is mostly the same from run to run at one force and
temperature (:mod:`relaxgrip.learning.hold_bias`).  This runs the closed-loop
hold with the uncalibrated estimator on a grid of targets and temperatures,
on seeds the models are not checked on, against the force ball's truth, and
takes each condition's mean of estimate − truth per time bin, with its
standard error over the seeds.  The conditions sit where the estimator
itself reads them (its ``F_inst`` and its finger temperature), so the lookup
at run time uses the same readings.

The error changes irregularly with force and temperature, and a condition's
mean is only as sure as its number of seeds (a hold's error is mostly one
offset per run).  So the means are not interpolated as they are: a Gaussian
process over force and temperature (:func:`smooth_bias`), each mean counted
with its own standard error, gives the table on the conditions and the
midpoints between them, shrinking what the seeds do not establish towards no
correction.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import BackendInfo, Command, Observation
from relaxgrip.control import GraspController, check_target_n
from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import (
    PAPER_DURATION_S,
    check_hold_duration_s,
    check_hold_temp_c,
    map_holds,
    run_hold,
    steady_window_s,
)
from relaxgrip.learning.hold_bias import MAX_DRIFT_SLOPE, HoldBias, IcfnDrift, drift_windows
from relaxgrip.learning.store import HOLD_BIAS_KEY, ModelBundle, model_checksums
from relaxgrip.learning.training import load_default_models
from relaxgrip.perception.features import finger_temperature_c
from relaxgrip.serialize import json_safe
from relaxgrip.twin import SAME_RUNS_AS, TWIN_VERSION
from relaxgrip.validate import check_seeds

__all__ = ["DEFAULT_SEEDS", "DEFAULT_TARGETS_N", "DEFAULT_TEMPS_C", "MIN_BIN_S", "MIN_SE_N",
           "RECORDINGS_SOURCE", "TIME_EDGES_S",
           "HoldCalibration", "calibrate_hold", "calibration_from_holds", "calibration_record",
           "condition_name", "drift_line", "hidden_note", "hold_drift_windows", "hold_row",
           "icfn_drift_n", "smooth_bias", "time_bins"]

FloatArray = NDArray[np.float64]

#: The grid the shipped models were calibrated on: 1-8 N and 30-55 °C.  It is dense
#: because the error is irregular: a grid of 1, 3, 5, 8 N read 6.5 N, 35 °C worse than
#: no calibration.
DEFAULT_TARGETS_N = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0)
DEFAULT_TEMPS_C = (30.0, 35.0, 40.0, 45.0, 50.0, 55.0)
#: Seeds the shipped figures are not measured on (those use 0-47).
DEFAULT_SEEDS = tuple(range(1000, 1006))
#: What a calibration measured on recordings carries where one on the twin has its version.
RECORDINGS_SOURCE = "recordings"
#: Edges of the time bins since the onset (s); each bin's mean error sits at its centre
#: on ``log(1 + t)``.  The early bins are short: the error settles over the first 30 s.
TIME_EDGES_S = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0, 190.0, 280.0)
#: The shortest last bin (s): 15 frames at the camera's 30 Hz.
MIN_BIN_S = 0.5


def time_bins(duration_s: float) -> list[tuple[float, float]]:
    """The bins of :data:`TIME_EDGES_S` a hold of ``duration_s`` reaches, the last cut there.

    A hold longer than 280 s has one more, from 280 s to its end.  A last
    bin shorter than :data:`MIN_BIN_S` joins the one before (a sliver of a
    bin may hold no frame at all).
    """
    edges = [e for e in TIME_EDGES_S if e == 0.0 or e < duration_s - MIN_BIN_S]
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


def hold_drift_windows(duration_s: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """The ICFN drift's windows in a hold of ``duration_s`` (s since the onset).

    Read at the steady state's start (100 s of a 280 s hold), from which the
    correction counts in full (:func:`relaxgrip.learning.hold_bias.drift_windows`).
    """
    return drift_windows(steady_window_s(duration_s)[0],
                         min(1.0, duration_s / PAPER_DURATION_S))


def icfn_drift_n(t_s: FloatArray, icfn_n: FloatArray,
                 windows: tuple[tuple[float, float], tuple[float, float]]) -> float:
    """A hold's ICFN drift as the estimator reads it (N; nan where a window has no reading).

    ``t_s`` is the time since the onset, ``icfn_n`` the per-frame ICFN,
    ``windows`` the early and late ones (:func:`hold_drift_windows` for a
    calibration hold).
    """
    means = []
    for lo, hi in windows:
        values = icfn_n[(t_s >= lo - 1e-9) & (t_s <= hi + 1e-9)]
        values = values[np.isfinite(values)]
        means.append(float(values.mean()) if values.size else math.nan)
    return means[1] - means[0]


def hold_row(t_s: FloatArray, estimate_n: FloatArray, truth_n: FloatArray,
             f_onset_n: FloatArray, temps_c: Sequence[float], target_n: float,
             duration_s: float, icfn_n: FloatArray | None = None) -> dict[str, Any]:
    """One uncalibrated hold as a calibration stores it, from its series since the onset.

    Parameters
    ----------
    t_s : ndarray
        Time since the hold's onset of each period (s); periods past
        ``duration_s`` are left out.
    estimate_n : ndarray
        The uncalibrated estimate, the closed chain's reading blended in: the
        table corrects what the controller is given.
    truth_n : ndarray
        The true force (N; nan where there is no reference).
    f_onset_n : ndarray
        The estimator's ``F_inst`` (nan before it has one).
    temps_c : sequence of float
        The finger temperature the estimator read through the hold.
    icfn_n : ndarray, optional
        The per-frame ICFN, for its drift (:func:`icfn_drift_n`).

    Returns
    -------
    dict
        The mean of estimate − truth per time bin (``bins_n``), the last
        ``F_inst`` and the mean temperature as read, over the steady state
        the MAE of the truth from the target and the mean estimate error,
        and with ``icfn_n`` the ICFN's drift (``icfn_drift_n``).

    Raises
    ------
    InputError
        No true force over the steady state.
    """
    keep = (t_s >= 0.0) & (t_s <= duration_s + 1e-9)
    t, est, truth = t_s[keep], estimate_n[keep], truth_n[keep]
    err = est - truth
    bins = []
    for lo, hi in time_bins(duration_s):
        rows = (t >= lo) & (t <= hi) & np.isfinite(err)
        bins.append(float(np.mean(err[rows])) if rows.any() else math.nan)
    lo, hi = steady_window_s(duration_s)
    window = (t >= lo - 1e-9) & (t <= hi + 1e-9) & np.isfinite(truth)
    if not window.any():
        raise InputError(f"no true force over the hold's steady state ({lo:.4g}-{hi:.4g} s "
                         "after the onset)")
    est_err = est[window] - truth[window]
    est_err = est_err[np.isfinite(est_err)]
    onset = f_onset_n[keep]
    onset = onset[np.isfinite(onset)]
    row = {"bins_n": bins, "f_inst_n": float(onset[-1]) if onset.size else math.nan,
           "temp_c": float(np.mean(temps_c)) if len(temps_c) else math.nan,
           "mae_n": float(np.mean(np.abs(truth[window] - target_n))),
           "est_error_mean_n": float(np.mean(est_err)) if est_err.size else math.nan}
    if icfn_n is not None:
        row["icfn_drift_n"] = icfn_drift_n(t, icfn_n[keep], hold_drift_windows(duration_s))
    return row


def _one(args: tuple[float, float, int, float, ModelBundle]) -> dict[str, Any]:
    """One uncalibrated hold: its error per time bin and what the estimator read."""
    target_n, temp_c, seed, duration_s, models = args
    tap = _TemperatureTap()
    hold = run_hold("relax", target_n, duration_s, temp_c, seed, models, recorder=tap)
    row = hold_row(hold.t_s, hold.estimate_n, hold.truth_n, hold.series("f_onset_n"),
                   tap.temps_c, target_n, duration_s, hold.series("icfn_n"))
    return {"seed": seed, **row}


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
        Every seed a condition was held on (holds added to a calibration
        can give conditions different seeds: ``holds`` says which).
    duration_s : float
    holds : dict of str to list of dict
        Per condition (``"5N 40C"``), each seed's hold: its error per time
        bin, ``F_inst``, finger temperature as read, MAE and mean estimate error
        over the steady state.
    kernels : list of str
        Per time bin, the Gaussian process :func:`smooth_bias` fitted.
    drift_fit : dict
        The line in the ICFN's drift (:class:`~relaxgrip.learning.hold_bias.IcfnDrift`):
        its windows (``early_s``, ``late_s``), the kernels smoothing its mean
        and slope, and per condition :func:`drift_line`; empty when the holds
        did not read it.
    twin_version : str
        The twin the holds ran on, or :data:`RECORDINGS_SOURCE` for recorded
        holds (:mod:`relaxgrip.experiments.recorded_calibration`).
    """

    bias: HoldBias
    targets_n: list[float]
    temps_c: list[float]
    seeds: list[int]
    duration_s: float
    holds: dict[str, list[dict[str, Any]]]
    kernels: list[str] = field(default_factory=list)
    drift_fit: dict[str, Any] = field(default_factory=dict)
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

    def kept(self) -> dict[str, Any]:
        """What the correction keeps of each condition's error over the steady state.

        The fit shrinks a condition's mean towards no correction as far as its
        standard error hides it (:func:`smooth_bias`): a condition alone, of
        mean ``m`` and standard error ``se`` (N), keeps ``1 - se²/m²`` of it,
        and nothing once ``se >= |m|``.  With too few seeds the calibration
        then stores almost nothing, though its conditions' means are large.
        Over the steady state (:func:`steady_window_s`), each hold's error per
        time bin (the one the table corrects: less the closed chain's
        addition) counts by its bin's overlap with it, and so does the
        correction at the condition's onset force and temperature as read.

        Returns
        -------
        dict
            ``steady_state_s``: the interval (s).  ``conditions``: per
            condition its ``holds``, their mean error ``error_n`` and its
            standard error ``se_n``, the correction taken off there
            ``correction_n``, and :meth:`summary`'s ``est_error_mean_n``
            beside them, the table's mean (the closed chain's addition in
            it) (N).  ``hidden``: the conditions whose correction
            keeps less than half of a mean larger than :data:`MIN_SE_N`,
            largest mean first; each of them also has
            ``seeds_to_keep_half``, the seeds per condition at which the
            rule above keeps half of a mean this large at this scatter (no
            more than ``holds`` when the other conditions, not its scatter,
            shrank it).
        """
        bins = time_bins(self.duration_s)
        lo, hi = steady_window_s(self.duration_s)
        weights = np.array([max(0.0, min(b, hi) - max(a, lo)) for a, b in bins])
        centres = [_bin_centre(a, b) for a, b in bins]
        conditions: dict[str, dict[str, Any]] = {}
        summary = self.summary()
        for name, rows in self.holds.items():
            errors = np.array([r["bins_n"] for r in rows], dtype=np.float64)
            counted = np.where(np.isfinite(errors), weights, 0.0)
            total = counted.sum(axis=1)
            per_hold = (np.nan_to_num(errors) * counted).sum(axis=1)[total > 0] / total[total > 0]
            force = float(np.nanmean([r["f_inst_n"] for r in rows]))
            temp = float(np.nanmean([r["temp_c"] for r in rows]))
            correction = [self.bias.at(force, temp, t) for t in centres]
            mean = float(per_hold.mean()) if per_hold.size else math.nan
            se = (float(per_hold.std(ddof=1) / math.sqrt(per_hold.size)) if per_hold.size > 1
                  else math.nan)
            conditions[name] = {"holds": int(per_hold.size), "error_n": mean, "se_n": se,
                                "correction_n": float(np.dot(weights, correction)
                                                      / weights.sum()),
                                "est_error_mean_n": summary[name]["est_error_mean_n"]}
        hidden = sorted((name for name, c in conditions.items()
                         if abs(c["error_n"]) > MIN_SE_N
                         and abs(c["correction_n"]) < 0.5 * abs(c["error_n"])),
                        key=lambda name: -abs(conditions[name]["error_n"]))
        for name in hidden:
            c = conditions[name]
            # se² ≤ m²/2 keeps half; the scatter per hold, se²·holds, stays as measured.
            c["seeds_to_keep_half"] = (
                math.ceil(2.0 * c["holds"] * (c["se_n"] / c["error_n"]) ** 2)
                if math.isfinite(c["se_n"]) else None)
        return {"steady_state_s": [lo, hi], "conditions": conditions, "hidden": hidden}

    def record(self) -> dict[str, Any]:
        """The manifest's record beside the grid (JSON: a figure there is none of is null)."""
        holds = ("recorded holds replayed with relax uncalibrated"
                 if self.twin_version == RECORDINGS_SOURCE else "uncalibrated relax holds")
        return json_safe({
            "method": f"mean of estimate - true force of {holds} per target, "
                      "temperature and time bin, smoothed over force and temperature by "
                      "Gaussian-process regression with each mean's standard error as its "
                      "noise (relaxgrip calibrate-hold)"
                      + ("; and per condition the line of each hold's steady-state error over "
                         "its per-frame ICFN's drift by the steady state's start, its mean "
                         "drift and slope smoothed the same way" if self.drift_fit else ""),
            "kernels": self.kernels,
            "targets_n": self.targets_n, "temps_c": self.temps_c, "seeds": self.seeds,
            "duration_s": self.duration_s, "time_bins_s": time_bins(self.duration_s),
            "twin_version": self.twin_version, "summary": self.summary(), "holds": self.holds,
            "icfn_drift": self.drift_fit or None,
        })


#: The least standard error a condition's mean is given (N): a bin's own frame noise.
MIN_SE_N = 0.005


def _refined(knots: FloatArray) -> FloatArray:
    """The knots with the midpoints between them."""
    mids = 0.5 * (knots[1:] + knots[:-1])
    return np.sort(np.concatenate([knots, mids]))


def smooth_bias(points: FloatArray, means: FloatArray, ses: FloatArray, at_forces: FloatArray,
                at_temps: FloatArray) -> tuple[FloatArray, str]:
    """Gaussian-process regression of the conditions' mean errors over force and temperature.

    Each condition's mean counts with its own noise (its standard error over
    the seeds, at least :data:`MIN_SE_N`); the length scales and the size of
    the error are fitted by marginal likelihood, and the prior mean is zero.
    So a condition measured no better than its scatter is shrunk towards its
    neighbours and towards no correction, and between conditions further
    apart than the error stays alike the calibration fades to none: on the
    twin a grid of 1, 3, 5 and 8 N found no length scale longer than its
    bounds (0.3 N, 1 K), and read linearly between its knots it had made
    6.5 N, 35 °C and 2 N, 52 °C worse than no calibration.

    Parameters
    ----------
    points : ndarray, shape (n, 2)
        Each condition's onset force (N) and finger temperature (°C) as read.
    means, ses : ndarray, shape (n,)
        Its mean error (N) and that mean's standard error (N).
    at_forces, at_temps : ndarray
        The grid to evaluate on.

    Returns
    -------
    values : ndarray, shape (forces, temps)
        The posterior mean on the grid (N).
    kernel : str
        The fitted kernel, for the record.
    """
    import warnings

    from sklearn.exceptions import ConvergenceWarning  # type: ignore[import-untyped]
    from sklearn.gaussian_process import GaussianProcessRegressor  # type: ignore[import-untyped]
    from sklearn.gaussian_process.kernels import RBF  # type: ignore[import-untyped]
    from sklearn.gaussian_process.kernels import ConstantKernel as Constant

    noise = np.maximum(np.nan_to_num(ses, nan=MIN_SE_N), MIN_SE_N) ** 2
    kernel = Constant(0.05**2, (1e-6, 1.0)) * RBF([2.0, 8.0], [(0.3, 30.0), (1.0, 100.0)])
    gp = GaussianProcessRegressor(kernel, alpha=noise, n_restarts_optimizer=2, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        gp.fit(points, means)
    grid = np.array([(f, t) for f in at_forces for t in at_temps])
    values: FloatArray = np.asarray(gp.predict(grid), dtype=np.float64).reshape(
        at_forces.size, at_temps.size)
    return values, str(gp.kernel_)


def hidden_note(kept: Mapping[str, Any], recorded: bool = False) -> str:
    """One line on the conditions whose correction keeps less than half of their error.

    Parameters
    ----------
    kept : mapping
        :meth:`HoldCalibration.kept`, with at least one ``hidden`` condition.
    recorded : bool
        The holds were recordings (more are recorded, not added with ``--add``).

    Returns
    -------
    str
        The largest such error beside what the correction takes off there
        (and the table's mean, the closed chain's addition in it), and why:
        its scatter (with about the seeds that would keep half of it) or the
        other conditions the fit shrank it with.
    """
    conditions = kept["conditions"]
    name = kept["hidden"][0]
    c = conditions[name]
    lo, hi = kept["steady_state_s"]
    unit, more = ("holds", "record more holds") if recorded else ("seeds", "add seeds with --add")
    head = (f"the correction keeps less than half of the error at {len(kept['hidden'])} of "
            f"{len(conditions)} conditions: over the steady state ({lo:.4g}-{hi:.4g} s) it takes "
            f"off {c['correction_n']:+.2g} N at {name}, where the holds' error without the "
            f"closed chain's addition (the part it corrects; the table's mean, with it: "
            f"{c['est_error_mean_n']:+.3f} N) averaged {c['error_n']:+.3f} N")
    seeds = c.get("seeds_to_keep_half")
    if seeds is not None and seeds > c["holds"]:
        return (f"{head}, hidden by their scatter (SE {c['se_n']:.3f} N over {c['holds']} "
                f"{unit}); about {seeds} {unit} per condition would keep half of a mean this "
                f"large ({more})")
    return (f"{head} (SE {c['se_n']:.3f} N over {c['holds']} {unit}), shrunk with the other "
            f"conditions, whose means are smaller or more scattered ({more} there)")


def condition_name(target_n: float, temp_c: float) -> str:
    """A condition of the grid as the record names it: ``"5N 40C"``."""
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
                   n_jobs: int = 1, add_to: Mapping[str, Any] | None = None) -> HoldCalibration:
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
    add_to : mapping, optional
        An earlier calibration's record (:func:`calibration_record` of the
        models' manifest): its holds are kept and these added, so that a
        lab's calibration grows where it holds most (more seeds at its
        working condition, a condition more).  The grid is then the union of
        both, and every condition of it needs holds.

    Raises
    ------
    InputError
        An empty axis or fewer than two seeds without ``add_to``, a seed
        given twice, a target or temperature out of range, conditions whose
        readings do not order as their setpoints, or holds to add that do
        not fit the earlier ones (another hold length or twin, a seed a
        condition already has).
    """
    new_targets = _axis(targets_n, "target")
    new_temps = _axis(temps_c, "temperature")
    if add_to is None and len(seeds) < 2:
        raise InputError("calibrating the hold needs at least two seeds: how sure each "
                         "condition's mean is comes from their spread")
    if not seeds:
        raise InputError("adding to the calibration needs at least one seed")
    check_seeds(seeds)  # one hold counted as two: no spread, a mean taken as sure
    for target in new_targets:
        check_target_n(target)
    for temp in new_temps:
        check_hold_temp_c(temp)
    check_hold_duration_s(duration_s)
    targets, temps = new_targets, new_temps
    holds: dict[str, list[dict[str, Any]]] = {}
    if add_to is not None:
        holds = _holds_to_add_to(add_to, new_targets, new_temps, seeds, duration_s)
        targets = _axis([*new_targets, *add_to["targets_n"]], "target")
        temps = _axis([*new_temps, *add_to["temps_c"]], "temperature")
        new = {condition_name(f, t) for f in new_targets for t in new_temps}
        missing = [name for name in (condition_name(f, t) for f in targets for t in temps)
                   if name not in new and name not in holds]
        if missing:
            raise InputError(f"with these holds the grid would lack the condition {missing[0]}:"
                             " hold every target at every temperature")
        thin = sorted(name for name in new if len(holds.get(name, [])) + len(seeds) < 2)
        if thin:
            raise InputError(f"the condition {thin[0]} would have holds on one seed: a new "
                             "condition needs at least two")
    bundle = replace(models if models is not None else load_default_models(), hold_bias=None)
    jobs = [(target, temp, int(seed), duration_s, bundle)
            for target in new_targets for temp in new_temps for seed in seeds]
    results = map_holds(_one, jobs, n_jobs)
    for (target, temp, *_), row in zip(jobs, results, strict=True):
        holds.setdefault(condition_name(target, temp), []).append(row)
    every = sorted({int(r["seed"]) for rows in holds.values() for r in rows})
    return calibration_from_holds(targets, temps, every, duration_s, holds)


#: What each stored hold of a calibration record carries.
_HOLD_FIELDS = ("seed", "bins_n", "f_inst_n", "temp_c", "mae_n", "est_error_mean_n")


def calibration_record(manifest: Mapping[str, Any]) -> dict[str, Any]:
    """The calibration a model directory's manifest carries, checked to add holds to.

    Raises
    ------
    InputError
        None there, one measured on other models than the manifest's, or a
        record without its holds.
    """
    section = manifest.get(HOLD_BIAS_KEY)
    record = section.get("record") if isinstance(section, dict) else None
    if not isinstance(record, dict):
        raise InputError("the models carry no hold calibration to add to (run calibrate-hold "
                         "without --add)")
    if record.get("model_sha256") != model_checksums(manifest):
        raise InputError("the models' hold calibration was measured on other models (trained "
                         "since); run calibrate-hold without --add")
    holds = record.get("holds")
    duration = record.get("duration_s")
    ok = (isinstance(holds, dict) and _numbers(duration) and _numbers(record.get("targets_n"))
          and _numbers(record.get("temps_c")))
    if ok and isinstance(holds, dict) and isinstance(duration, (int, float)):
        bins = len(time_bins(float(duration)))
        ok = all(isinstance(rows, list) and all(
            isinstance(r, dict) and set(_HOLD_FIELDS) <= r.keys() and isinstance(r["seed"], int)
            and _numbers(r["bins_n"], bins) for r in rows) for rows in holds.values())
    if not ok:
        raise InputError("the models' hold calibration record lacks its holds, grid or hold "
                         "length, or has them malformed; run calibrate-hold without --add")
    return dict(record)


def _numbers(value: Any, length: int | None = None) -> bool:
    """A number, or a list of numbers or nulls (``length`` long if given; a null is a nan)."""
    if length is None and not isinstance(value, list):
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return (isinstance(value, list) and (length is None or len(value) == length)
            and all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))
                    for v in value))


def _stored(row: Mapping[str, Any]) -> dict[str, Any]:
    """A hold as the record stores it, its nulls (JSON's nan) read back as nan."""
    def num(v: Any) -> Any:
        return math.nan if v is None else v

    return {k: [num(x) for x in v] if k == "bins_n" else num(v) for k, v in row.items()}


def _holds_to_add_to(record: Mapping[str, Any], targets: list[float], temps: list[float],
                     seeds: Sequence[int], duration_s: float) -> dict[str, list[dict[str, Any]]]:
    """The earlier calibration's holds, checked against the holds to add."""
    if not math.isclose(float(record["duration_s"]), duration_s):
        raise InputError(f"the earlier calibration held {record['duration_s']:g} s, not "
                         f"{duration_s:g} s: add holds of its length")
    # A calibration hold (no push, the arm still) runs on these as on this twin.
    if record.get("twin_version") not in (TWIN_VERSION, *SAME_RUNS_AS):
        raise InputError(f"the earlier calibration ran on {record.get('twin_version')}, not "
                         f"{TWIN_VERSION}: calibrate anew")
    holds: dict[str, list[dict[str, Any]]] = {
        name: [_stored(r) for r in rows] for name, rows in record["holds"].items()}
    for target in targets:
        for temp in temps:
            name = condition_name(target, temp)
            there = sorted({int(r["seed"]) for r in holds.get(name, [])} & set(map(int, seeds)))
            if there:
                raise InputError(f"the condition {name} already has seed {there[0]}: add "
                                 "other seeds")
    return holds


def calibration_from_holds(targets: list[float], temps: list[float], seeds: list[int],
                           duration_s: float, holds: dict[str, list[dict[str, Any]]]
                           ) -> HoldCalibration:
    """The calibration of holds already run (:meth:`HoldCalibration.holds`' form).

    Raises
    ------
    InputError
        A condition of the grid without holds or with fewer than two, one
        that gave no estimate, or readings that do not order as their
        setpoints.
    """
    for target in targets:
        for temp in temps:
            if len(holds.get(condition_name(target, temp), [])) < 2:
                raise InputError(f"the condition {condition_name(target, temp)} needs holds on "
                                 "at least two seeds")
    bins = time_bins(duration_s)
    shape = (len(targets), len(temps))
    means, ses = np.empty((*shape, len(bins))), np.empty((*shape, len(bins)))
    f_inst, read_c = np.empty(shape), np.empty(shape)
    for i, target in enumerate(targets):
        for j, temp in enumerate(temps):
            name = condition_name(target, temp)
            errors = np.array([r["bins_n"] for r in holds[name]], dtype=np.float64)
            counts = np.isfinite(errors).sum(axis=0)
            if counts.min() < 2:
                raise InputError(f"in the condition {name}, fewer than two seeds gave an "
                                 "estimate in every time bin")
            means[i, j] = np.nanmean(errors, axis=0)
            ses[i, j] = np.nanstd(errors, axis=0, ddof=1) / np.sqrt(counts)
            f_inst[i, j] = np.nanmean([r["f_inst_n"] for r in holds[name]])
            read_c[i, j] = np.nanmean([r["temp_c"] for r in holds[name]])
    if not (np.all(np.isfinite(f_inst)) and np.all(np.isfinite(read_c))):
        raise InputError("a calibration condition gave no onset force or temperature")
    forces = f_inst.mean(axis=1)
    readings = read_c.mean(axis=0)
    for name, axis, setpoints in (("onset forces", forces, targets),
                                  ("temperatures", readings, temps)):
        if np.any(np.diff(axis) <= 0):
            raise InputError(f"the holds' {name} as read ({np.round(axis, 3).tolist()}) do not "
                             f"rise with their setpoints ({setpoints}): space them further")
    points = np.column_stack([f_inst.ravel(), read_c.ravel()])
    at_f, at_t = _refined(forces), _refined(readings)
    values = np.empty((at_f.size, at_t.size, len(bins)))
    kernels = []
    for k in range(len(bins)):
        values[:, :, k], kernel = smooth_bias(points, means[:, :, k].ravel(),
                                              ses[:, :, k].ravel(), at_f, at_t)
        kernels.append(kernel)
    drift, drift_fit = _fit_drift(targets, temps, holds, points, at_f, at_t, duration_s)
    bias = HoldBias(at_f, at_t, np.array([_bin_centre(lo, hi) for lo, hi in bins]), values,
                    drift)
    return HoldCalibration(bias, targets, temps, seeds, duration_s, holds, kernels, drift_fit)


#: The standard error a slope on fewer than three holds, or on drifts all alike,
#: is given: no slope at all is established there.
_UNKNOWN_SLOPE_SE = 10.0


def drift_line(drifts: FloatArray, errors: FloatArray) -> dict[str, float]:
    """One condition's least-squares line of steady-state error over ICFN drift.

    Returns
    -------
    dict
        ``holds``; the drifts' mean ``mean_n`` and its standard error
        ``mean_se_n`` (N); the ``slope`` (N per N), its standard error
        ``slope_se`` (:data:`_UNKNOWN_SLOPE_SE` on fewer than three holds or
        no spread in the drift) and the correlation ``r`` (nan without spread).
    """
    n = drifts.size
    mean = float(drifts.mean())
    dx, dy = drifts - mean, errors - errors.mean()
    sxx, syy = float(dx @ dx), float(dy @ dy)
    mean_se = math.sqrt(sxx / (n - 1) / n) if n > 1 else math.nan
    if sxx <= 1e-12:
        return {"holds": n, "mean_n": mean, "mean_se_n": mean_se, "slope": 0.0,
                "slope_se": _UNKNOWN_SLOPE_SE, "r": math.nan}
    slope = float(dx @ dy) / sxx
    r = float(dx @ dy) / math.sqrt(sxx * syy) if syy > 0 else math.nan
    slope_se = _UNKNOWN_SLOPE_SE
    if n > 2:
        residual = max(syy - slope * slope * sxx, 0.0)
        slope_se = min(math.sqrt(residual / (n - 2) / sxx), _UNKNOWN_SLOPE_SE)
    return {"holds": n, "mean_n": mean, "mean_se_n": mean_se, "slope": slope,
            "slope_se": slope_se, "r": r}


def _fit_drift(targets: list[float], temps: list[float], holds: Mapping[str, list[dict[str, Any]]],
               points: FloatArray, at_f: FloatArray, at_t: FloatArray, duration_s: float
               ) -> tuple[IcfnDrift | None, dict[str, Any]]:
    """The line in the ICFN's drift per condition, smoothed as the means are (:func:`smooth_bias`).

    None (and an empty record) unless every hold read its drift: holds
    recorded without it, or added to a calibration from before it.
    """
    lines = {}
    for target in targets:
        for temp in temps:
            name = condition_name(target, temp)
            rows = holds[name]
            drifts = np.array([r.get("icfn_drift_n", math.nan) for r in rows], dtype=np.float64)
            errors = np.array([r["est_error_mean_n"] for r in rows], dtype=np.float64)
            if not (np.all(np.isfinite(drifts)) and np.all(np.isfinite(errors))):
                return None, {}
            lines[name] = drift_line(drifts, errors)
    fits = list(lines.values())
    tables = {}
    kernels = {}
    for key, se_key in (("mean_n", "mean_se_n"), ("slope", "slope_se")):
        tables[key], kernels[key] = smooth_bias(
            points, np.array([f[key] for f in fits]),
            np.nan_to_num(np.array([f[se_key] for f in fits]), nan=_UNKNOWN_SLOPE_SE),
            at_f, at_t)
    early, late = hold_drift_windows(duration_s)
    drift = IcfnDrift(at_f, at_t, early, late, tables["mean_n"],
                      np.clip(tables["slope"], -MAX_DRIFT_SLOPE, MAX_DRIFT_SLOPE))
    return drift, {"early_s": list(early), "late_s": list(late), "kernels": kernels,
                   "conditions": lines}
