"""Recalibrating the observer's band on closed-loop holds (``relaxgrip calibrate-band``).

The observer's 95 % band is identified on the dataset's fixed-aperture holds
(:meth:`relaxgrip.learning.observer.ObserverModel.fit`); in closed loop its
error is another thing (the ICFN's onset reading, the share fitted online,
a temperature ramp or a new target).  The band is therefore recalibrated the
way it is used: closed-loop holds of the standard hold and of the issue's
scenarios on seeds the models never saw, and ``band_scale`` set to the least
factor on the *identified* half-width that has ``band_level`` of the samples'
``|estimate - truth|`` within it, so that the stated share lies inside the band.
The ratio does not depend on the scale the observer had while holding: the
identified half-width is the recorded one over that scale.

A hold's samples are not independent: most of a closed-loop error is the
run's offset from its onset, so each run counts about once, and the scale
is only as sure as the number of runs.  The calibration therefore reports a
90 % interval of the scale from resampling the seeds (each with all of its
holds).  On the twin, blocks of 12 seeds gave scales from 0.17 to 0.26
(each block's interval about ±20 %) and 36 seeds 0.224 (0.19-0.25).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import HoldResult
from relaxgrip.experiments.scenarios import SCENARIOS, check_scenarios, scenario_holds
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.store import ModelBundle

__all__ = ["DEFAULT_SCENARIOS", "BandCalibration", "band_ratios", "calibrate_band",
           "least_covering", "seed_interval"]

FloatArray = NDArray[np.float64]

#: The scenarios the band is calibrated on by default (any of :data:`SCENARIOS` can be).
DEFAULT_SCENARIOS = ("standard", "ramp", "step")


def band_ratios(hold: HoldResult, band_scale: float) -> FloatArray:
    """``|estimate - truth|`` over the identified half-width, every hold sample with a band.

    Parameters
    ----------
    hold : HoldResult
        A closed-loop hold of the ``observer`` estimator.
    band_scale : float
        The scale the observer's band had in that hold.
    """
    lo, hi = hold.series("band_lo_n"), hold.series("band_hi_n")
    est, truth = hold.series("estimate_n"), hold.series("truth_force_n")
    half = 0.5 * (hi - lo) / band_scale
    ok = np.isfinite(half) & (half > 0) & np.isfinite(est) & np.isfinite(truth)
    out: FloatArray = np.abs(est[ok] - truth[ok]) / half[ok]
    return out


def least_covering(ratios: FloatArray, level: float) -> float:
    """The least scale at which at least ``level`` of ``ratios`` are inside the band."""
    if ratios.size == 0:
        raise InputError("the holds recorded no band to calibrate")
    k = max(1, math.ceil(level * ratios.size - 1e-9))
    return float(np.partition(ratios, k - 1)[k - 1])


def seed_interval(ratios_by_seed: Sequence[FloatArray], level: float,
                  resamples: int = 200, rng_seed: int = 0) -> tuple[float, float]:
    """90 % interval of :func:`least_covering` with the seeds resampled (bootstrap).

    Parameters
    ----------
    ratios_by_seed : sequence of ndarray
        Each seed's ratios, all of its holds together.
    level : float
        Coverage the band states.
    resamples : int
        Bootstrap draws.
    rng_seed : int
        Seed of the draws (the interval is reproducible).
    """
    rng = np.random.default_rng(rng_seed)
    n = len(ratios_by_seed)
    draws = [least_covering(np.concatenate([ratios_by_seed[i] for i in rng.integers(0, n, n)]),
                            level) for _ in range(resamples)]
    lo, hi = np.percentile(draws, [5.0, 95.0])
    return float(lo), float(hi)


@dataclass(frozen=True)
class BandCalibration:
    """What a recalibration measured.

    Attributes
    ----------
    band_scale : float
        The new scale: the least at which ``level`` of the samples are inside.
    scale_interval : tuple of float
        90 % interval of the scale over resampled seeds (:func:`seed_interval`).
    level : float
        Coverage the band states.
    samples : int
        Hold samples the quantile is over.
    seeds : list of int
    scenarios : dict of str to dict
        Per scenario: its profiles, and per seed the MAE (N) and the coverage
        of the hold samples at the old and at the new scale.
    previous_scale : float
    """

    band_scale: float
    scale_interval: tuple[float, float]
    level: float
    samples: int
    seeds: list[int]
    previous_scale: float
    scenarios: dict[str, dict[str, Any]] = field(default_factory=dict)

    def summary(self) -> dict[str, dict[str, float]]:
        """Per scenario, the mean over its holds of the MAE and of each coverage."""
        out: dict[str, dict[str, float]] = {}
        for name, entry in self.scenarios.items():
            rows = list(entry["seeds"].values())
            out[name] = {key: float(np.mean([row[key] for row in rows]))
                         for key in ("mae_n", "coverage_before", "coverage_after")}
        return out

    def record(self) -> dict[str, Any]:
        """The manifest's ``band_recalibration`` entry."""
        return {
            "band_scale": self.band_scale, "scale_interval_90": list(self.scale_interval),
            "level": self.level,
            "method": f"least scale with {self.level:g} of |estimate - truth| / identified "
                      "half-width within it, over closed-loop holds; interval: the seeds "
                      "resampled (relaxgrip calibrate-band)",
            "seeds": self.seeds, "samples": self.samples,
            "previous_scale": self.previous_scale, "scenarios": self.scenarios,
        }


def _coverage_at(ratios: FloatArray, scale: float) -> float:
    """Coverage of a hold's samples (their :func:`band_ratios`) had the band this scale."""
    return float(np.mean(ratios <= scale)) if ratios.size else math.nan


def calibrate_band(observer: ObserverModel, seeds: Sequence[int],
                   scenarios: Sequence[str] = DEFAULT_SCENARIOS, duration_s: float = 280.0,
                   models: ModelBundle | None = None, n_jobs: int = 1) -> BandCalibration:
    """Run the observer's closed-loop holds and set its band's scale from their errors.

    Parameters
    ----------
    observer : ObserverModel
        Fitted observer (its ``band_scale`` is what the holds run with; the
        result does not depend on it).
    seeds : sequence of int
        Twin seeds (take ones the models were not checked on).
    scenarios : sequence of str
        Names in :data:`relaxgrip.experiments.scenarios.SCENARIOS`.
    duration_s : float
        Hold length (s); the profiles' times are scaled with it from 280 s.
    models : ModelBundle, optional
        ICFN and RCFN (default: the shipped models).
    n_jobs : int
        Holds in parallel.

    Returns
    -------
    BandCalibration
        ``observer`` itself is not changed.

    Raises
    ------
    InputError
        No seeds, an unknown scenario, or holds without a band.
    """
    if not seeds:
        raise InputError("calibrating the band needs at least one seed")
    scenarios = check_scenarios(scenarios)
    jobs = [(name, seed) for name in scenarios for seed in seeds]
    holds = scenario_holds([("observer", name, seed) for name, seed in jobs], duration_s,
                           models, observer, n_jobs)
    used = observer.band_scale
    ratios = [band_ratios(h, used) for h in holds]
    every = np.concatenate(ratios)
    scale = least_covering(every, observer.band_level)
    by_seed = [np.concatenate([r for (_, s), r in zip(jobs, ratios, strict=True) if s == seed])
               for seed in seeds]
    interval = seed_interval(by_seed, observer.band_level)
    report: dict[str, dict[str, Any]] = {}
    for (name, seed), hold, r in zip(jobs, holds, ratios, strict=True):
        entry = report.setdefault(name, {**SCENARIOS[name].to_dict(), "seeds": {}})
        entry["seeds"][str(seed)] = {
            "mae_n": hold.metrics()["mae_n"],
            "coverage_before": _coverage_at(r, used),
            "coverage_after": _coverage_at(r, scale),
        }
    return BandCalibration(scale, interval, observer.band_level, int(every.size), list(seeds),
                           used, report)

