"""Recalibrating the observer's band on closed-loop holds (``relaxgrip calibrate-band``).

The observer's 95 % band is identified on the dataset's fixed-aperture holds
(:meth:`relaxgrip.learning.observer.ObserverModel.fit`); in closed loop its
error is another thing (the ICFN's onset reading, the share fitted online,
a temperature ramp or a new target).  The band is therefore recalibrated the
way it is used: closed-loop holds of the standard hold and of the issue's
scenarios on seeds the models never saw.

The band has three parts, and each is set where it acts:

* ``band_floor_n``, newtons added whatever the force, and ``band_scale`` on
  the half-width from the held-out residuals, set on the samples where the
  two are the whole band (every hold until the share fit ends: the standard
  hold throughout, the scenarios before they act).  The floor is the
  intercept of the ``band_level`` quantile of ``|estimate - truth|`` as a
  line in the identified half-width (:func:`quantile_floor`); the scale then
  the least factor that has ``band_level`` of those samples within the floor
  and it;
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

The floor: the identified half-width is a share of the force, calibrated
at 5 N, while the ICFN's onset error is partly absolute.  On twin v6 the
band calibrated on the 5 N holds alone (scale 0.220) covered the truth of
16 holds at 1 N, 40 °C 67.4 % of the time (7 of them under 90 %), and 91.2 %
at 8 N: one factor on the force covers on the whole, where most samples are.
The default scenarios therefore hold 1 N (``light``) and 8 N (``firm``)
besides the 5 N ones, and the line's two first-order conditions put
``band_level`` of each force's samples under it, as far as a line can.

The temperature factors: the identified half-width and its scale are one
function of the hold's time, and the relaxing share that a hold's error
follows scatters more in the rubbery state.  Calibrated at 40 °C alone,
the band covered seeds 0-7 at 2 N, 52 °C 82.9 % of the time and at 5 N,
55 °C 79.6 % (session 53).  With holds at two or more temperatures (the
default scenarios hold ``hot``, 5 N at 55 °C, and ``warm``, 5 N at 48 °C, the
glass transition), the floor and scale are set
at the temperature with the most samples, and every other temperature held
gets the least factor on the relative part that covers ``band_level`` of
its samples; the observer interpolates the factor at the temperature the
infrared camera reads.

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
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import HoldResult
from relaxgrip.experiments.hold_calibration import RECORDINGS_SOURCE
from relaxgrip.experiments.scenarios import SCENARIOS, check_scenarios, scenario_holds
from relaxgrip.learning.observer import ObserverModel, band_factors
from relaxgrip.learning.store import ModelBundle

__all__ = [
    "DEFAULT_SCENARIOS",
    "INTERVAL_FRAMES",
    "KNOT_REACH_K",
    "BandCalibration",
    "BandHold",
    "BandSamples",
    "BandScales",
    "calibrate_band",
    "calibration_of",
    "fit_scales",
    "least_covering",
    "measuring",
    "quantile_floor",
    "seed_intervals",
]

FloatArray = NDArray[np.float64]

#: The scenarios the band is calibrated on by default (any of :data:`SCENARIOS` can be).
DEFAULT_SCENARIOS = ("standard", "ramp", "step", "light", "firm", "hot", "warm")


class BandScales(NamedTuple):
    """What a recalibration sets of the band (:class:`ObserverModel`'s parameters).

    Attributes
    ----------
    band_scale : float
        Factor on the half-width from the held-out residuals.
    drift_scale : float
        Factor on the relaxing share's part.
    floor_n : float
        Half-width in newtons added to both (``band_floor_n``).
    temps_c, temp_factors : tuple of float
        Factors on the relative part at finger temperatures (``band_temps_c``,
        ``band_temp_factors``; none: 1 everywhere).
    """

    band_scale: float
    drift_scale: float
    floor_n: float
    temps_c: tuple[float, ...] = ()
    temp_factors: tuple[float, ...] = ()

    @classmethod
    def of(cls, observer: ObserverModel) -> BandScales:
        return cls(observer.band_scale, observer.drift_scale, observer.band_floor_n,
                   observer.band_temps_c, observer.band_temp_factors)

    def factor(self, temp_c: FloatArray) -> FloatArray:
        """The relative part's factor at each temperature (°C), as the observer has it
        (:func:`band_factors`)."""
        return band_factors(self.temps_c, self.temp_factors, temp_c)


@dataclass(frozen=True)
class BandSamples:
    """Hold samples with a band: the error and the band's parts as identified.

    Attributes
    ----------
    error_n : ndarray
        ``|estimate - truth|`` (N).
    onset_n : ndarray
        The half-width from the held-out residuals at ``band_scale`` 1 (N).
    drift_n : ndarray
        The relaxing share's part at ``drift_scale`` 1 (N; 0 while the share
        fit runs).
    temp_c : ndarray, optional
        The finger temperature (°C; nan where none was read, and everywhere
        without it).
    """

    error_n: FloatArray
    onset_n: FloatArray
    drift_n: FloatArray
    temp_c: FloatArray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        if self.temp_c.size == 0 and self.error_n.size:  # none read
            object.__setattr__(self, "temp_c", np.full(self.error_n.shape, np.nan))

    @classmethod
    def of(cls, hold: HoldResult, scales: BandScales) -> BandSamples:
        """The samples of an ``observer`` hold whose band had these scales (the
        temperature the infrared camera read of both fingers)."""
        temp = 0.5 * (hold.series("ir_temp_0_c") + hold.series("ir_temp_1_c"))
        return cls.of_series(hold.series("estimate_n"), hold.series("truth_force_n"),
                             hold.series("band_lo_n"), hold.series("band_hi_n"),
                             hold.series("band_drift_n"), scales, temp)

    @classmethod
    def of_series(cls, est: FloatArray, truth: FloatArray, lo: FloatArray, hi: FloatArray,
                  drift: FloatArray, scales: BandScales,
                  temp_c: FloatArray | float) -> BandSamples:
        """The samples of a hold's series: the estimate, the truth, the band (its low and
        high edge and its drift part), the band's scales, the finger temperature.

        The relative part is recovered through ``scales``' temperature factors
        at ``temp_c``: exactly when the hold ran without them (:func:`measuring`).
        """
        temp_c = np.broadcast_to(np.asarray(temp_c, dtype=np.float64), est.shape)
        onset = ((0.5 * (hi - lo) - drift - scales.floor_n)
                 / (scales.band_scale * scales.factor(temp_c)))
        ok = (np.isfinite(onset) & (onset > 0) & np.isfinite(drift) & np.isfinite(est)
              & np.isfinite(truth))
        # A part with no scale recorded nothing to learn its size from.
        unit = (drift[ok] / scales.drift_scale if scales.drift_scale > 0
                else np.zeros(int(ok.sum())))
        return cls(np.abs(est[ok] - truth[ok]), onset[ok], unit, temp_c[ok].copy())

    @classmethod
    def join(cls, parts: Sequence[BandSamples]) -> BandSamples:
        return cls(*(np.concatenate([getattr(p, name) for p in parts]) if parts else np.zeros(0)
                     for name in ("error_n", "onset_n", "drift_n", "temp_c")))

    def every(self, stride: int) -> BandSamples:
        """Every ``stride``-th sample."""
        return BandSamples(self.error_n[::stride], self.onset_n[::stride],
                           self.drift_n[::stride], self.temp_c[::stride])

    @property
    def size(self) -> int:
        return int(self.error_n.size)

    def coverage(self, scales: BandScales) -> float:
        """Share of the samples inside the band at these scales (nan without samples)."""
        if not self.size:
            return math.nan
        half = (scales.floor_n + scales.band_scale * scales.factor(self.temp_c) * self.onset_n
                + scales.drift_scale * self.drift_n)
        return float(np.mean(self.error_n <= half))


def least_covering(ratios: FloatArray, level: float) -> float:
    """The least scale at which at least ``level`` of ``ratios`` are inside the band."""
    if ratios.size == 0:
        raise InputError("the holds recorded no band to calibrate")
    k = max(1, math.ceil(level * ratios.size - 1e-9))
    return float(np.partition(ratios, k - 1)[k - 1])


def _weighted_quantile(values: FloatArray, weights: FloatArray, level: float) -> float:
    """The least value with at least ``level`` of the weight at or below it."""
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(weights[order])
    return float(values[order][min(int(np.searchsorted(cum, level * cum[-1])), cum.size - 1)])


def quantile_floor(error_n: FloatArray, onset_n: FloatArray, level: float) -> float:
    """The intercept (>= 0, N) of the ``level`` quantile of the error as a line in the
    identified half-width: ``floor + scale * onset`` minimising the pinball loss.

    The loss's first-order conditions put ``level`` of the samples under the
    line both on the whole and weighted by ``onset``: with holds at two
    forces, ``level`` of each's, as far as a line can.  The least covering
    share alone, a factor on the force, covers on the whole, mostly where
    the samples are.  For a given floor the best scale is the
    ``onset``-weighted quantile of ``(error - floor) / onset``, and the
    profiled loss is convex in the floor: a bounded scalar search.
    """
    if error_n.size == 0:
        raise InputError("the holds recorded no band to calibrate")

    def loss(floor: float) -> float:
        ratio = (error_n - floor) / onset_n
        r = ratio - _weighted_quantile(ratio, onset_n, level)
        return float(np.sum(onset_n * np.where(r >= 0, level * r, (level - 1.0) * r)))

    top = float(np.quantile(error_n, level))
    if top <= 0:
        return 0.0
    best = optimize.minimize_scalar(loss, bounds=(0.0, top), method="bounded",
                                    options={"xatol": 1e-5 * top})
    # The bounded search never evaluates the bound itself: no floor is a candidate too, and
    # the one kept where a floor does no better (one force: a floor is a scale there).
    none = loss(0.0)
    return float(best.x) if float(best.fun) < none - 1e-9 * abs(none) else 0.0


#: Samples within this of a held temperature are its holds' (K): the infrared reading
#: of a held finger scatters by a few tenths of a kelvin.
KNOT_REACH_K = 2.0
#: The least temperature factor: where the floor alone covers a temperature's holds, the
#: relative part all but gone rather than below zero.
_MIN_FACTOR = 0.05


def fit_scales(samples: BandSamples, level: float, drift_scale: float | None = None,
               temps_c: Sequence[float] = (),
               kept: tuple[tuple[float, ...], tuple[float, ...]] = ((), ()),
               ) -> tuple[BandScales, bool]:
    """The band's floor and ``band_scale``, its temperature factors, then the least
    ``drift_scale``, that cover ``level``.

    Parameters
    ----------
    samples : BandSamples
    level : float
        Coverage the band states.
    drift_scale : float, optional
        Kept when no sample has a drift part (default: 1).
    temps_c : sequence of float
        The temperatures the holds were held at (°C).  With two or more, each
        gets a factor, set on the samples within :data:`KNOT_REACH_K` of it
        without a drift part: 1 at the one with the most, where the floor and
        ``band_scale`` are set; elsewhere the least covering of ``(error -
        floor) / (band_scale onset)``.
    kept : (temperatures, factors)
        The factors with fewer than two temperatures: kept, and applied to
        the samples the floor and scale are set on.

    Returns
    -------
    scales : BandScales
        ``floor_n``: :func:`quantile_floor`; ``band_scale``: the least covering
        of ``(error - floor) / onset`` (``level`` of them inside, whatever the
        line's fit), both over the samples without a drift part (at the base
        temperature); the temperature factors; ``drift_scale``: the least
        covering of ``(error - floor - band_scale factor onset) / drift`` (0
        where the rest covers) over the samples with one.
    drift_set : bool
        Whether any sample had a drift part to set ``drift_scale`` on.

    Raises
    ------
    InputError
        No sample without a drift part (nothing to set ``band_scale`` on), or
        none at one of ``temps_c``.
    """
    still = samples.drift_n <= 0
    if not still.any():
        raise InputError("no hold sample has the band without its drift part to set the band "
                         "scale on")
    error, onset, temp = samples.error_n[still], samples.onset_n[still], samples.temp_c[still]
    knots = sorted({float(t) for t in temps_c})
    if len(knots) >= 2:
        near = [np.abs(temp - knot) <= KNOT_REACH_K for knot in knots]
        for knot, mask in zip(knots, near, strict=True):
            if not mask.any():
                raise InputError(f"no hold sample at {knot:g} °C to set the band's factor there")
        base = int(np.argmax([np.count_nonzero(mask) for mask in near]))
        floor, band = _floor_and_scale(error[near[base]], onset[near[base]], level)
        temps, factors = tuple(knots), tuple(
            1.0 if k == base else max(_MIN_FACTOR, least_covering(
                (error[mask] - floor) / (band * onset[mask]), level))
            for k, mask in enumerate(near))
    else:
        temps, factors = kept
        floor, band = _floor_and_scale(error, onset * band_factors(temps, factors, temp), level)
    first = BandScales(band, 1.0 if drift_scale is None else drift_scale, floor, temps, factors)
    moving = ~still
    if not moving.any():
        return first, False
    part = first.band_scale * first.factor(samples.temp_c[moving]) * samples.onset_n[moving]
    excess = np.maximum(samples.error_n[moving] - floor - part, 0.0)
    return first._replace(drift_scale=least_covering(excess / samples.drift_n[moving],
                                                     level)), True


def _floor_and_scale(error: FloatArray, onset: FloatArray, level: float) -> tuple[float, float]:
    """:func:`quantile_floor`, then the least ``band_scale`` covering ``level`` with it."""
    floor = quantile_floor(error, onset, level)
    band = least_covering((error - floor) / onset, level)
    if band <= 0:  # the floor alone covers: keep a relative part of the line's
        floor = 0.0
        band = least_covering(error / onset, level)
    return floor, band


Interval = tuple[float, float]


#: The resampled fits of :func:`seed_intervals` use every k-th frame of each seed, at
#: most about this many in all: a floor fitted on 1.2 million frames took 8 s, on 50 000
#: 0.26 s, and frames 33 ms apart in one run carry little the others do not.
INTERVAL_FRAMES = 50_000


def seed_intervals(samples_by_seed: Sequence[BandSamples], level: float, resamples: int = 200,
                   rng_seed: int = 0, frames: int = INTERVAL_FRAMES,
                   temps_c: Sequence[float] = (),
                   kept: tuple[tuple[float, ...], tuple[float, ...]] = ((), ()),
                   ) -> tuple[Interval, Interval, Interval, list[Interval]]:
    """90 % intervals of :func:`fit_scales`' scales with the seeds resampled (bootstrap).

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
    frames : int
        Each seed's samples are thinned to every k-th, one k for all, so that
        about this many are left in all.
    temps_c, kept
        As :func:`fit_scales` takes them.

    Returns
    -------
    tuple of (lo, hi) for ``band_scale``, ``drift_scale``, the floor (N); list for the factors
        Each over the draws that could set it: the drift scale's over those
        with a drift part (nan, nan when none had one); one per temperature
        held when there are two or more (none with fewer: the factors are kept).
    """
    rng = np.random.default_rng(rng_seed)
    n = len(samples_by_seed)
    stride = max(1, math.ceil(sum(x.size for x in samples_by_seed) / max(frames, 1)))
    if stride > 1:
        samples_by_seed = [x.every(stride) for x in samples_by_seed]
    band: list[float] = []
    drift: list[float] = []
    floor: list[float] = []
    factors: list[tuple[float, ...]] = []
    held = len({float(t) for t in temps_c})
    for _ in range(resamples):
        draw = BandSamples.join([samples_by_seed[i] for i in rng.integers(0, n, n)])
        try:
            scales, drift_set = fit_scales(draw, level, temps_c=temps_c, kept=kept)
        except InputError:  # a draw of seeds that recorded nothing to set a scale on
            continue
        band.append(scales.band_scale)
        floor.append(scales.floor_n)
        if held >= 2:
            factors.append(scales.temp_factors)
        if drift_set:
            drift.append(scales.drift_scale)

    def interval(values: list[float]) -> Interval:
        if not values:
            return math.nan, math.nan
        lo, hi = np.percentile(values, [5.0, 95.0])
        return float(lo), float(hi)

    each = [interval([f[k] for f in factors]) for k in range(held)] if held >= 2 else []
    return interval(band), interval(drift), interval(floor), each


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
    band_floor_n : float
        The new floor of the band (N; :func:`quantile_floor`).
    floor_interval : tuple of float
        Its 90 % interval.
    level : float
        Coverage the band states.
    samples : int
        Hold samples with a band.
    drift_samples : int
        Those of them with a drift part.
    seeds : list of int
    previous_scale, previous_drift_scale, previous_floor_n : float
        The scales and floor the holds ran with.
    band_temps_c, band_temp_factors : tuple of float
        The new temperature factors (:func:`fit_scales`; the previous ones
        when the holds had fewer than two temperatures).
    factor_intervals : list of tuple of float
        Their 90 % intervals (none when kept).
    previous_temps_c, previous_temp_factors : tuple of float
        The temperature factors the observer had.
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
    band_floor_n: float
    floor_interval: tuple[float, float]
    level: float
    samples: int
    drift_samples: int
    seeds: list[int]
    previous_scale: float
    previous_drift_scale: float
    previous_floor_n: float
    band_temps_c: tuple[float, ...] = ()
    band_temp_factors: tuple[float, ...] = ()
    factor_intervals: list[tuple[float, float]] = field(default_factory=list)
    previous_temps_c: tuple[float, ...] = ()
    previous_temp_factors: tuple[float, ...] = ()
    scenarios: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def scales(self) -> BandScales:
        """The new scales, floor and temperature factors."""
        return BandScales(self.band_scale, self.drift_scale, self.band_floor_n,
                          self.band_temps_c, self.band_temp_factors)

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
            "band_floor_n": self.band_floor_n, "floor_interval_90_n": list(self.floor_interval),
            "band_temps_c": list(self.band_temps_c),
            "band_temp_factors": list(self.band_temp_factors),
            "temp_factor_intervals_90": [list(i) for i in self.factor_intervals],
            "level": self.level,
            "method": f"floor: intercept of the {self.level:g} quantile of |estimate - truth| "
                      "as a line in the identified half-width (least pinball loss), then least "
                      f"band scale with {self.level:g} of |estimate - truth| within the floor "
                      "and the identified half-width, both where it is the whole band at the "
                      "temperature with the most holds, then at each other temperature held the "
                      "least factor on the identified half-width with the same share within, "
                      "then least drift scale with the same share within all parts where the "
                      f"share's drift is there, over {holds}; intervals: the seeds resampled, "
                      f"every k-th frame, about {INTERVAL_FRAMES} in all "
                      "(relaxgrip calibrate-band)",
            "seeds": self.seeds, "samples": self.samples, "drift_samples": self.drift_samples,
            "previous_scale": self.previous_scale,
            "previous_drift_scale": self.previous_drift_scale,
            "previous_floor_n": self.previous_floor_n,
            "previous_temps_c": list(self.previous_temps_c),
            "previous_temp_factors": list(self.previous_temp_factors),
            "scenarios": self.scenarios,
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
    previous = BandScales.of(observer)
    observer = measuring(observer)
    jobs = [(name, seed) for name in scenarios for seed in seeds]
    holds = scenario_holds([("observer", name, seed) for name, seed in jobs], duration_s,
                           models, observer, n_jobs)
    used = BandScales.of(observer)
    measured = [BandHold(name, SCENARIOS[name].to_dict(), seed,
                         {"mae_n": hold.metrics()["mae_n"]}, BandSamples.of(hold, used))
                for (name, seed), hold in zip(jobs, holds, strict=True)]
    return calibration_of(measured, seeds, observer.band_level, previous,
                          [SCENARIOS[name].temp_c for name in scenarios])


def measuring(observer: ObserverModel) -> ObserverModel:
    """The observer to run the holds with (a copy where it differs; the scales set do not
    depend on it): a band part at scale 0 records nothing of its size, so the drift part
    gets scale 1, and without temperature factors the relative part is recovered exactly
    whatever temperature the observer read."""
    if observer.drift_scale > 0 and not observer.band_temp_factors:
        return observer
    observer = copy.deepcopy(observer)
    if observer.drift_scale <= 0:
        observer.drift_scale = 1.0
    observer.band_temps_c, observer.band_temp_factors = (), ()
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
                   previous: BandScales, temps_c: Sequence[float] = ()) -> BandCalibration:
    """The band's scales, floor and temperature factors set on ``holds`` held at
    ``temps_c`` (:func:`fit_scales`), their intervals with ``seeds`` resampled
    (:func:`seed_intervals`), and each hold's coverage at the ``previous`` and the new
    ones.

    Raises
    ------
    InputError
        No hold sample with a band.
    """
    every = BandSamples.join([h.samples for h in holds])
    if not every.size:
        raise InputError("the holds recorded no band to calibrate")
    kept = (previous.temps_c, previous.temp_factors)
    scales, _ = fit_scales(every, level, previous.drift_scale, temps_c, kept)
    by_seed = [BandSamples.join([h.samples for h in holds if h.seed == seed]) for seed in seeds]
    band_interval, drift_interval, floor_interval, factor_intervals = seed_intervals(
        by_seed, level, temps_c=temps_c, kept=kept)
    report: dict[str, dict[str, Any]] = {}
    for hold in holds:
        entry = report.setdefault(hold.scenario, {**hold.header, "seeds": {}})
        entry["seeds"][str(hold.seed)] = {
            **hold.row,
            "coverage_before": hold.samples.coverage(previous),
            "coverage_after": hold.samples.coverage(scales),
        }
    return BandCalibration(
        scales.band_scale, band_interval, scales.drift_scale, drift_interval, scales.floor_n,
        floor_interval, level, every.size, int(np.count_nonzero(every.drift_n > 0)),
        list(seeds), previous.band_scale, previous.drift_scale, previous.floor_n,
        scales.temps_c, scales.temp_factors, factor_intervals, previous.temps_c,
        previous.temp_factors, report)
