"""Recalibrating the observer's band on closed-loop holds (``relaxgrip calibrate-band``).

The observer's 95 % band is identified on the dataset's fixed-aperture holds
(:meth:`relaxgrip.learning.observer.ObserverModel.fit`); in closed loop its
error is another thing (the ICFN's onset reading, the share fitted online,
a temperature ramp or a new target).  The band is therefore recalibrated the
way it is used: closed-loop holds of the standard hold and of the issue's
scenarios on seeds the models never saw.

The band has two parts, and each gets its own factor, measured where it acts:

* ``band_scale`` on the half-width from the held-out residuals, set on the
  samples where it is the whole band (every hold until the share fit ends:
  the standard hold throughout, the scenarios before they act), as the least
  factor that has ``band_level`` of those samples' ``|estimate - truth|``
  within it;
* ``drift_scale`` on the part that carries the spread of the relaxing share
  over what the branches relax after the fit (a temperature ramp, a new
  target), set on the samples where that part is there, as the least factor
  that, added to the first part at its new scale, has ``band_level`` of them
  inside.

One factor for both (what the band had until then) is set by the pooled
samples, most of them the standard hold's and the scenarios' early ones, and
it leaves the ramp short: the rubbery state's relaxing share scatters more
than the dataset's holds show.  On the twin (the calibrated models, 280 s
holds of the four scenarios, seeds 0-47), calibrated on seeds 12-47 and
checked on seeds 0-11, one factor covered the ramp 92.2 % of the time and the
standard hold 99.1 %; two covered them 94.8 % and 97.2 %, the standard
hold's band 14 % narrower.  Calibrated on each block of 12 seeds instead,
the least-covered scenario of seeds 0-11 had 86.5-98.3 % with two factors
and 83.5-96.1 % with one.  The drift factor is the less sure of the two
(0.63-1.76 over those blocks): a few runs carry a ramp's large errors.  The
ratios do not depend on the scales the observer had while holding: the
identified parts are the recorded ones over them.

Calibrate on seeds nothing was designed on.  Seeds 0-47 carried every design
choice of the estimators and hold with smaller errors than fresh ones (the
standard hold 0.037 against 0.061-0.067 N); the band calibrated on seeds
12-47 covered fresh seeds 3000-3035's standard hold 83.7 % of the time and
their ramp 83.4 %.  The shipped band is calibrated on seeds 3000-3035
(``band_scale`` 0.254, ``drift_scale`` 1.09) and covers seeds 2000-2023's
standard hold, ramp, step and push 96.0 / 98.5 / 99.1 / 97.0 % of the time
(the push with the observer's push rule; 94.5 % before it).

A hold's samples are not independent: most of a closed-loop error is the
run's offset from its onset, so each run counts about once, and a scale is
only as sure as the number of runs.  The calibration therefore reports a
90 % interval of each scale from resampling the seeds (each with all of its
holds).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import HoldResult
from relaxgrip.experiments.hold_calibration import RECORDINGS_SOURCE
from relaxgrip.experiments.scenarios import SCENARIOS, check_scenarios, scenario_holds
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.store import ModelBundle

__all__ = ["DEFAULT_SCENARIOS", "BandCalibration", "BandHold", "BandSamples", "calibrate_band",
           "calibration_of", "fit_scales", "least_covering", "measuring", "seed_intervals"]

FloatArray = NDArray[np.float64]

#: The scenarios the band is calibrated on by default (any of :data:`SCENARIOS` can be).
DEFAULT_SCENARIOS = ("standard", "ramp", "step")


@dataclass(frozen=True)
class BandSamples:
    """Hold samples with a band: the error and the band's two parts as identified.

    Attributes
    ----------
    error_n : ndarray
        ``|estimate - truth|`` (N).
    onset_n : ndarray
        The half-width from the held-out residuals at ``band_scale`` 1 (N).
    drift_n : ndarray
        The relaxing share's part at ``drift_scale`` 1 (N; 0 while the share
        fit runs).
    """

    error_n: FloatArray
    onset_n: FloatArray
    drift_n: FloatArray

    @classmethod
    def of(cls, hold: HoldResult, band_scale: float, drift_scale: float) -> BandSamples:
        """The samples of an ``observer`` hold whose band had these scales."""
        return cls.of_series(hold.series("estimate_n"), hold.series("truth_force_n"),
                             hold.series("band_lo_n"), hold.series("band_hi_n"),
                             hold.series("band_drift_n"), band_scale, drift_scale)

    @classmethod
    def of_series(cls, est: FloatArray, truth: FloatArray, lo: FloatArray, hi: FloatArray,
                  drift: FloatArray, band_scale: float, drift_scale: float) -> BandSamples:
        """The samples of a hold's series: the estimate, the truth, the band (its low and
        high edge and its drift part), the band's scales."""
        onset = (0.5 * (hi - lo) - drift) / band_scale
        ok = (np.isfinite(onset) & (onset > 0) & np.isfinite(drift) & np.isfinite(est)
              & np.isfinite(truth))
        # A part with no scale recorded nothing to learn its size from.
        unit = drift[ok] / drift_scale if drift_scale > 0 else np.zeros(int(ok.sum()))
        return cls(np.abs(est[ok] - truth[ok]), onset[ok], unit)

    @classmethod
    def join(cls, parts: Sequence[BandSamples]) -> BandSamples:
        return cls(*(np.concatenate([getattr(p, name) for p in parts]) if parts else np.zeros(0)
                     for name in ("error_n", "onset_n", "drift_n")))

    @property
    def size(self) -> int:
        return int(self.error_n.size)

    def coverage(self, band_scale: float, drift_scale: float) -> float:
        """Share of the samples inside the band at these scales (nan without samples)."""
        if not self.size:
            return math.nan
        half = band_scale * self.onset_n + drift_scale * self.drift_n
        return float(np.mean(self.error_n <= half))


def least_covering(ratios: FloatArray, level: float) -> float:
    """The least scale at which at least ``level`` of ``ratios`` are inside the band."""
    if ratios.size == 0:
        raise InputError("the holds recorded no band to calibrate")
    k = max(1, math.ceil(level * ratios.size - 1e-9))
    return float(np.partition(ratios, k - 1)[k - 1])


def fit_scales(samples: BandSamples, level: float,
               drift_scale: float | None = None) -> tuple[float, float | None]:
    """The least ``band_scale``, then the least ``drift_scale``, that cover ``level``.

    Parameters
    ----------
    samples : BandSamples
    level : float
        Coverage the band states.
    drift_scale : float, optional
        Returned as it is when no sample has a drift part.

    Returns
    -------
    band_scale : float
        Least covering of ``error / onset`` over the samples without a drift part.
    drift_scale : float or None
        Least covering of ``(error - band_scale onset) / drift`` (0 where the
        onset part covers) over the samples with one.

    Raises
    ------
    InputError
        No sample without a drift part (nothing to set ``band_scale`` on).
    """
    still = samples.drift_n <= 0
    if not still.any():
        raise InputError("no hold sample has the band without its drift part to set the band "
                         "scale on")
    band = least_covering(samples.error_n[still] / samples.onset_n[still], level)
    moving = ~still
    if not moving.any():
        return band, drift_scale
    excess = np.maximum(samples.error_n[moving] - band * samples.onset_n[moving], 0.0)
    return band, least_covering(excess / samples.drift_n[moving], level)


def seed_intervals(samples_by_seed: Sequence[BandSamples], level: float, resamples: int = 200,
                   rng_seed: int = 0) -> tuple[tuple[float, float], tuple[float, float]]:
    """90 % intervals of :func:`fit_scales`' two scales with the seeds resampled (bootstrap).

    Parameters
    ----------
    samples_by_seed : sequence of BandSamples
        Each seed's samples, all of its holds together.
    level : float
        Coverage the band states.
    resamples : int
        Bootstrap draws.
    rng_seed : int
        Seed of the draws (the intervals are reproducible).

    Returns
    -------
    tuple of (lo, hi) for ``band_scale``, then for ``drift_scale``
        Each over the draws that could set it: the drift scale's over those
        with a drift part (nan, nan when none had one).
    """
    rng = np.random.default_rng(rng_seed)
    n = len(samples_by_seed)
    band: list[float] = []
    drift: list[float] = []
    for _ in range(resamples):
        draw = BandSamples.join([samples_by_seed[i] for i in rng.integers(0, n, n)])
        try:
            b, d = fit_scales(draw, level)
        except InputError:  # a draw of seeds that recorded nothing to set the band scale on
            continue
        band.append(b)
        if d is not None:
            drift.append(d)

    def interval(values: list[float]) -> tuple[float, float]:
        if not values:
            return math.nan, math.nan
        lo, hi = np.percentile(values, [5.0, 95.0])
        return float(lo), float(hi)

    return interval(band), interval(drift)


@dataclass(frozen=True)
class BandCalibration:
    """What a recalibration measured.

    Attributes
    ----------
    band_scale : float
        The new scale of the held-out residuals' part (:func:`fit_scales`).
    scale_interval : tuple of float
        Its 90 % interval over resampled seeds (:func:`seed_intervals`).
    drift_scale : float
        The new scale of the relaxing share's part (the previous one when no
        sample had that part).
    drift_interval : tuple of float
        Its 90 % interval (nan, nan without such samples).
    level : float
        Coverage the band states.
    samples : int
        Hold samples with a band.
    drift_samples : int
        Those of them with a drift part.
    seeds : list of int
    previous_scale, previous_drift_scale : float
        The scales the holds ran with.
    scenarios : dict of str to dict
        Per scenario: its profiles, and per seed the MAE (N) and the coverage
        of the hold samples at the old and at the new scales.  Measured on
        recordings (:func:`relaxgrip.experiments.recorded_calibration.
        calibrate_band_on_recordings`), one scenario, ``recorded``, with
        ``source`` ``"recordings"`` and a row per recording, its file name
        under ``recording``.
    """

    band_scale: float
    scale_interval: tuple[float, float]
    drift_scale: float
    drift_interval: tuple[float, float]
    level: float
    samples: int
    drift_samples: int
    seeds: list[int]
    previous_scale: float
    previous_drift_scale: float
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
        recorded = any(entry.get("source") == RECORDINGS_SOURCE
                       for entry in self.scenarios.values())
        holds = "recorded holds replayed" if recorded else "closed-loop holds"
        return {
            "band_scale": self.band_scale, "scale_interval_90": list(self.scale_interval),
            "drift_scale": self.drift_scale,
            "drift_interval_90": [v if math.isfinite(v) else None for v in self.drift_interval],
            "level": self.level,
            "method": f"least band scale with {self.level:g} of |estimate - truth| within the "
                      "identified half-width where it is the whole band, then least drift "
                      "scale with the same share within both parts where the share's drift "
                      f"is there, over {holds}; intervals: the seeds resampled "
                      "(relaxgrip calibrate-band)",
            "seeds": self.seeds, "samples": self.samples, "drift_samples": self.drift_samples,
            "previous_scale": self.previous_scale,
            "previous_drift_scale": self.previous_drift_scale, "scenarios": self.scenarios,
        }


def calibrate_band(observer: ObserverModel, seeds: Sequence[int],
                   scenarios: Sequence[str] = DEFAULT_SCENARIOS, duration_s: float = 280.0,
                   models: ModelBundle | None = None, n_jobs: int = 1) -> BandCalibration:
    """Run the observer's closed-loop holds and set its band's scale from their errors.

    Parameters
    ----------
    observer : ObserverModel
        Fitted observer (its scales are what the holds run with; the result
        does not depend on them).
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
        No seeds, an unknown or repeated scenario, or holds without a band.
    """
    if not seeds:
        raise InputError("calibrating the band needs at least one seed")
    scenarios = check_scenarios(scenarios)
    if len(set(scenarios)) != len(scenarios):  # a repeat would run (and count) its holds twice
        raise InputError(f"scenarios repeat in {','.join(scenarios)}")
    previous = observer.band_scale, observer.drift_scale
    observer = measuring(observer)
    jobs = [(name, seed) for name in scenarios for seed in seeds]
    holds = scenario_holds([("observer", name, seed) for name, seed in jobs], duration_s,
                           models, observer, n_jobs)
    used = observer.band_scale, observer.drift_scale
    measured = [BandHold(name, SCENARIOS[name].to_dict(), seed,
                         {"mae_n": hold.metrics()["mae_n"]}, BandSamples.of(hold, *used))
                for (name, seed), hold in zip(jobs, holds, strict=True)]
    return calibration_of(measured, seeds, observer.band_level, previous)


def measuring(observer: ObserverModel) -> ObserverModel:
    """The observer to run the holds with: a band part at scale 0 records nothing of its
    size, so the drift part gets scale 1 (a copy; the scales set do not depend on it)."""
    if observer.drift_scale > 0:
        return observer
    observer = copy.deepcopy(observer)
    observer.drift_scale = 1.0
    return observer


@dataclass(frozen=True)
class BandHold:
    """One hold's band samples with where the report lists it.

    Attributes
    ----------
    scenario : str
        The report's scenario.
    header : dict
        What the report says of the scenario (its profiles, or its source).
    seed : int
        The seed the hold counts as in the resampled intervals.
    row : dict
        The hold's figures for the report (its MAE, a recording's name).
    samples : BandSamples
    """

    scenario: str
    header: dict[str, Any]
    seed: int
    row: dict[str, Any]
    samples: BandSamples


def calibration_of(holds: Sequence[BandHold], seeds: Sequence[int], level: float,
                   previous: tuple[float, float]) -> BandCalibration:
    """The band's scales set on ``holds`` (:func:`fit_scales`), their intervals with
    ``seeds`` resampled (:func:`seed_intervals`), and each hold's coverage at the
    ``previous`` and the new scales.

    Raises
    ------
    InputError
        No hold sample with a band.
    """
    every = BandSamples.join([h.samples for h in holds])
    if not every.size:
        raise InputError("the holds recorded no band to calibrate")
    band, drift = fit_scales(every, level)
    drift = previous[1] if drift is None else drift
    by_seed = [BandSamples.join([h.samples for h in holds if h.seed == seed]) for seed in seeds]
    band_interval, drift_interval = seed_intervals(by_seed, level)
    report: dict[str, dict[str, Any]] = {}
    for hold in holds:
        entry = report.setdefault(hold.scenario, {**hold.header, "seeds": {}})
        entry["seeds"][str(hold.seed)] = {
            **hold.row,
            "coverage_before": hold.samples.coverage(*previous),
            "coverage_after": hold.samples.coverage(band, drift),
        }
    return BandCalibration(band, band_interval, drift, drift_interval, level, every.size,
                           int(np.count_nonzero(every.drift_n > 0)), list(seeds), *previous,
                           report)
