"""Least-squares fits of measured force-relaxation curves (paper Eqs. 4 and 9–10).

Two models are fitted to the force recorded while a displacement is held:

* the reduced model ``F(t) = F_inst - K (1 - e^{-t/tau})`` (Eqs. 9–10), and
* the Prony series ``F(t) = F_eq + sum_i k_i e^{-t/tau_i}`` (Eq. 4 in force
  units, see :func:`relaxgrip.physics.viscoelastic.prony_force`).

Both are sums of decaying exponentials plus a constant, so for fixed
relaxation times the amplitudes are a linear least-squares problem.  The fits
use variable projection (Golub & Pereyra): the amplitudes are eliminated
exactly and only ``log tau`` is searched, globally (a dense grid for one term,
a multi-start continuation for ``N`` terms) and then locally by
:func:`scipy.optimize.least_squares` with the exact variable-projection
Jacobian.  The result is the least-squares optimum over relaxation times in
``[tau_lo, tau_hi]``: ``tau_lo`` is the shortest sampling interval of the
data and ``tau_hi`` ten times the record length (shorter or longer modes
cannot be told apart from a jump or from a constant plus a linear drift).

Amplitudes are not constrained in sign: a negative ``k_i`` is a rising mode.
On relaxation data every amplitude of the optimum is usually positive, but
forcing the sign would turn a true optimum into a constrained one.

A third fit serves the RCFN's labels: :func:`osculating_reduced`, the
Eq. 10 curve that touches a hold at one instant (same force, same slope).
Several modes relax at once in a real finger, and one exponential over the
whole hold cannot follow the fast start and the slow tail together (on the
twin's 280 s holds the best such fit correlates 0.98 with the curve); the
touching curve at each instant is exact where it is used, so an RCFN that
predicts it frame by frame reconstructs the whole hold.

Two objectives are available, see :func:`quadrature_weights`:
``weighting="time"`` minimises the trapezoidal ``int (F_model - F)^2 dt``,
the norm of the paper's NRMSE (§V-B), so that densely sampled stretches of a
record do not dominate; ``weighting="sample"`` is the plain sum of squares.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.errors import InputError
from relaxgrip.physics.viscoelastic import prony_force, reduced_force

FloatArray = NDArray[np.float64]
Weighting = Literal["time", "sample"]

__all__ = [
    "MAX_DURATION_S",
    "MAX_FORCE_N",
    "MAX_PRONY_TERMS",
    "WEIGHTINGS",
    "PronyFit",
    "ReducedFit",
    "UnidentifiableError",
    "Weighting",
    "find_hold",
    "find_hold_start",
    "fit_prony",
    "fit_reduced",
    "osculating_reduced",
    "quadrature_weights",
]

WEIGHTINGS: tuple[str, ...] = get_args(Weighting)

#: The most terms :func:`fit_prony` fits.  Each term about triples the global search
#: (5 terms take seconds, 8 minutes), and a hold's relaxation times, which must lie
#: decades apart to be told apart, rarely show more; the observer takes 1-5 as well.
MAX_PRONY_TERMS = 5
#: The largest force (N) and record duration (s) a fit takes: ten times the capacity
#: of the largest test machines, and three centuries.  Beyond them a record is not a
#: relaxation test (a unit slipped, or a value was corrupted), and far beyond them
#: the squared forces and time weights of the objective overflow float64.
MAX_FORCE_N = 1e9
MAX_DURATION_S = 1e10

# Relaxation-time search range: [shortest sampling interval, _TAU_HI_FACTOR x record length].
_TAU_HI_FACTOR = 10.0
# Grid density of the one-term global search and of the multi-start seeds (points per decade).
_GRID_PER_DECADE = 8
_SEEDS_PER_DECADE = 2
# How many candidate solutions survive each level of the N-term continuation.
_BEAM_WIDTH = 3
# Seeds whose new tau lies within this factor of an existing one are skipped: the two
# basis columns would be nearly collinear and the start carries no new information.
_MIN_SEED_RATIO = 1.5
#: A Prony fit's relaxation times must lie this factor apart, and its amplitudes
#: within this many force ranges of the hold: else two terms have merged.
_MIN_TERM_RATIO = 1.05
_MAX_AMPLITUDE_RANGES = 10.0
#: Records of more samples are searched on this many pooled bins (:meth:`_Problem.coarse`).
_COARSE_ABOVE = 20_000
_COARSE_BINS = 2_000
#: Samples within this share of the step of the plateau show its recording resolution.
_NEAR_PLATEAU = 0.01
#: Changes of the smallest size on a plateau that make it a recording's resolution.
_MIN_COUNTS = 3
_LSQ_TOL = 1e-12
_MAX_NFEV = 400


class UnidentifiableError(InputError):
    """A Prony series with more terms than the hold shows.

    Attributes
    ----------
    n_terms : int
        The number of terms that could not be told apart (a fit of more
        terms fails on its way through this many).
    """

    def __init__(self, message: str, n_terms: int) -> None:
        super().__init__(message)
        self.n_terms = n_terms


@dataclass(frozen=True)
class ReducedFit:
    """Least-squares fit of the reduced model ``F_inst - K (1 - e^{-t/tau})`` (Eqs. 9–10).

    Attributes
    ----------
    f_inst_n : float
        Instantaneous force at ``t = 0`` (N).
    k_n : float
        Relaxation magnitude ``K`` (N); positive for a decaying force.
    tau_s : float
        Relaxation time ``tau`` (s).
    objective : float
        Minimised objective: ``int (F_model - F)^2 dt`` (N² s) for
        ``weighting="time"``, ``sum (F_model - F)^2`` (N²) for ``"sample"``.
    weighting : str
        The weighting the fit minimised, ``"time"`` or ``"sample"``.
    """

    f_inst_n: float
    k_n: float
    tau_s: float
    objective: float
    weighting: str

    def predict(self, t_s: ArrayLike) -> FloatArray:
        """Evaluate the fitted model.

        Parameters
        ----------
        t_s : array_like
            Times since the hold start (s).

        Returns
        -------
        ndarray
            Model force (N), same shape as ``t_s``.
        """
        return reduced_force(t_s, self.f_inst_n, self.k_n, self.tau_s)


@dataclass(frozen=True)
class PronyFit:
    """Least-squares fit of the Prony series ``F_eq + sum_i k_i e^{-t/tau_i}`` (Eq. 4).

    Attributes
    ----------
    f_eq_n : float
        Equilibrium (fully relaxed) force ``F_eq`` (N).
    k_n : tuple of float
        Branch amplitudes ``k_i`` (N), in the order of ``tau_s``.
    tau_s : tuple of float
        Relaxation times ``tau_i`` (s), ascending.
    objective : float
        Minimised objective, see :attr:`ReducedFit.objective`.
    weighting : str
        The weighting the fit minimised, ``"time"`` or ``"sample"``.
    """

    f_eq_n: float
    k_n: tuple[float, ...]
    tau_s: tuple[float, ...]
    objective: float
    weighting: str

    @property
    def f_inst_n(self) -> float:
        """Instantaneous force ``F_eq + sum_i k_i`` at ``t = 0`` (N)."""
        return self.f_eq_n + math.fsum(self.k_n)

    def predict(self, t_s: ArrayLike) -> FloatArray:
        """Evaluate the fitted series.

        Parameters
        ----------
        t_s : array_like
            Times since the hold start (s).

        Returns
        -------
        ndarray
            Model force (N), same shape as ``t_s``.
        """
        return prony_force(t_s, self.f_eq_n, self.k_n, self.tau_s)


def quadrature_weights(t_s: ArrayLike, weighting: str = "time") -> FloatArray:
    """Weights ``w`` such that ``sum_i w_i g(t_i)^2`` is the fit objective.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Strictly increasing sample times (s).
    weighting : {"time", "sample"}
        ``"time"``: trapezoidal quadrature weights, so ``sum w g^2`` is the
        trapezoid rule for ``int g^2 dt`` on the (possibly non-uniform) grid.
        ``"sample"``: all ones, the plain sum of squares.

    Returns
    -------
    ndarray, shape (n,)
        Non-negative weights (s for ``"time"``, dimensionless for ``"sample"``).

    Raises
    ------
    ValueError
        If ``weighting`` is unknown or ``t_s`` is not a 1-D array of at least
        two strictly increasing finite times.
    """
    t = _as_times(t_s)
    if weighting == "sample":
        return np.ones_like(t)
    if weighting != "time":
        raise ValueError(f"weighting must be one of {', '.join(WEIGHTINGS)}, got {weighting!r}")
    dt = np.diff(t)
    w = np.zeros_like(t)
    w[:-1] += 0.5 * dt
    w[1:] += 0.5 * dt
    return w


def find_hold(
    t_s: ArrayLike,
    displacement: ArrayLike,
    *,
    rel_tol: float = 1e-3,
    noise_factor: float = 5.0,
    min_samples: int = 10,
    min_duration_s: float = 1.0,
) -> tuple[int, int]:
    """The hold phase of a step-and-hold record: ``(start, stop)`` sample indices.

    The plateau is the median of the last quarter of the samples, along
    their trend where the displacement creeps by at most 1 % of the step over
    the record (a clamp that gives a little).  A sample
    is *in band* when the running median of the displacement (five samples:
    one glitching sample is not a change of displacement) lies within
    ``rel_tol |step| + noise_factor sigma`` of it, where ``step`` is the
    plateau minus the initial displacement and ``sigma`` a robust noise
    estimate: the scaled median absolute deviation of the first differences
    on the plateau, and at least the recording's resolution where most of
    those differences are zero (a displacement logged in encoder counts: the
    smallest non-zero one is a count).  The hold is the longest run of in-band
    samples: it starts after a ramp's overshoot has settled, and it ends
    where the record leaves the plateau again (a test machine unloading at
    the end), which is cut.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Strictly increasing sample times (s).
    displacement : array_like, shape (n,)
        Displacement at ``t_s``, any length unit.
    rel_tol : float
        Settling tolerance relative to the step height.
    noise_factor : float
        Multiple of the noise estimate added to the tolerance.
    min_samples : int
        Fewest samples the hold phase may have.
    min_duration_s : float
        Shortest duration the hold phase may have (s).

    Returns
    -------
    (int, int)
        Index of the first sample of the hold, and one past its last.

    Raises
    ------
    relaxgrip.errors.InputError
        If the record has no hold phase: no displacement step (the plateau
        equals the starting displacement, e.g. both are zero), the
        displacement never settles, or the settled part is shorter than
        ``min_samples`` samples or ``min_duration_s`` seconds.
    ValueError
        If the arrays are malformed (not 1-D, different lengths, non-finite,
        time not strictly increasing).
    """
    t = _as_times(t_s)
    x = np.asarray(displacement, dtype=np.float64)
    if x.shape != t.shape:
        raise ValueError(f"displacement has shape {x.shape}, t_s has shape {t.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("displacement contains non-finite values")
    n = t.size
    if n < min_samples:
        raise InputError(f"no hold phase: only {n} samples, need at least {min_samples}")

    m = max(min_samples, n // 4)
    tail, tail_t = x[-m:], t[-m:]
    plateau = float(np.median(tail))
    step = plateau - float(x[0])
    # A hold whose displacement creeps (a fixture or a clamp that gives a little) is
    # held along its trend: the slope between the medians of the tail's two halves,
    # taken where it moves the level by at most _NEAR_PLATEAU of the step over the
    # whole record (more is a displacement still on its way, which never settles).
    half = m // 2
    rate = ((float(np.median(tail[half:])) - float(np.median(tail[:half])))
            / (float(np.median(tail_t[half:])) - float(np.median(tail_t[:half]))))
    if not abs(rate) * float(t[-1] - t[0]) <= _NEAR_PLATEAU * abs(step):
        rate = 0.0
    level = plateau + rate * (t - float(np.median(tail_t)))
    d_tail = np.diff(tail)
    # MAD of first differences: insensitive to a slow drift, sqrt(2) undoes the differencing.
    sigma = 1.4826 * float(np.median(np.abs(d_tail - np.median(d_tail)))) / math.sqrt(2.0)
    # A displacement logged in counts mostly does not change from one sample to the
    # next on the plateau, and when it does, by a count: the resolution, below which
    # the noise estimate cannot go (a ramp changes at every sample, and is no plateau).
    # A count recurs: a change seen once is no resolution (the first step of an
    # unloading sampled finely, which would widen the band to the ramp).
    near = np.abs(tail - level[-m:]) <= _NEAR_PLATEAU * abs(step)
    changes = np.abs(d_tail[near[1:] & near[:-1]])
    counts = changes[changes > 0.0]
    if counts.size and counts.size <= 0.5 * changes.size:
        count = float(np.min(counts))
        if np.count_nonzero(counts <= 1.5 * count) >= _MIN_COUNTS:
            sigma = max(sigma, count)
    noise_band = noise_factor * sigma
    # Below this the step is lost in rounding of the recorded values.
    resolution = 64.0 * np.finfo(np.float64).eps * max(float(np.max(np.abs(x))), 1e-300)
    if abs(step) <= max(noise_band, resolution):
        raise InputError(
            f"no hold phase: the displacement ends at {plateau:.6g}, where it started "
            f"({x[0]:.6g}); there is no step to hold"
        )
    band = rel_tol * abs(step) + noise_band
    inside = np.abs(_running_median(x, 5) - level) <= band
    if not inside.any():
        raise InputError(
            f"no hold phase: the displacement never settles (last sample {x[-1]:.6g}, "
            f"plateau {plateau:.6g} ± {band:.3g})"
        )
    # Runs of in-band samples: the longest is the hold.
    edges = np.flatnonzero(np.diff(np.concatenate(([0], inside.view(np.int8), [0]))))
    starts, stops = edges[0::2], edges[1::2]
    longest = int(np.argmax(stops - starts))
    start, stop = int(starts[longest]), int(stops[longest])
    n_hold = stop - start
    hold_s = float(t[stop - 1] - t[start])
    if n_hold < min_samples or hold_s < min_duration_s:
        need = f"need at least {min_samples} samples and {min_duration_s:g} s"
        if not inside[-1]:
            raise InputError(
                f"no hold phase: the displacement never settles (last sample {x[-1]:.6g}, "
                f"plateau {plateau:.6g} ± {band:.3g}; in band for at most {n_hold} samples "
                f"at a time, {need})"
            )
        raise InputError(
            f"no hold phase: the displacement settles at {plateau:.6g} only for the last "
            f"{n_hold} samples ({hold_s:.3g} s); {need}"
        )
    return start, stop


def find_hold_start(t_s: ArrayLike, displacement: ArrayLike, **kwargs: Any) -> int:
    """Index of the first sample of the hold phase (:func:`find_hold`'s start)."""
    return find_hold(t_s, displacement, **kwargs)[0]


def _running_median(x: FloatArray, width: int) -> FloatArray:
    """Centred running median of odd ``width`` (the ends use the samples there are)."""
    if x.size < width:
        return x.copy()
    from scipy.ndimage import median_filter

    out: FloatArray = median_filter(x, size=width, mode="nearest")
    return out


def fit_reduced(
    t_s: ArrayLike, f_n: ArrayLike, weighting: str = "time", f_inst_n: float | None = None
) -> ReducedFit:
    """Least-squares fit of the reduced relaxation model (Eqs. 9–10).

    ``F_inst - K (1 - e^{-t/tau}) = (F_inst - K) + K e^{-t/tau}`` is a one-term
    Prony series; its ``log tau`` is searched on a dense grid over the whole
    admissible range (the variable-projection objective of one term is cheap
    to evaluate everywhere), and every local minimum of the grid is refined.

    With ``f_inst_n`` given, the curve is anchored there and only ``K`` and
    ``tau`` are fitted: the form in which Eq. 10 is used, where ``F_inst``
    comes from elsewhere (the force at the hold onset, or the ICFN).

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Strictly increasing times since the hold start (s).
    f_n : array_like, shape (n,)
        Measured force (N).
    weighting : {"time", "sample"}
        Objective, see :func:`quadrature_weights`.
    f_inst_n : float, optional
        Fixed instantaneous force ``F_inst`` (N); fitted when ``None``.

    Returns
    -------
    ReducedFit
        The optimum; ``K`` is unconstrained in sign, ``tau`` lies in
        ``[tau_lo, tau_hi]`` (see the module notes).

    Raises
    ------
    relaxgrip.errors.InputError
        If there are fewer samples than the 3 parameters, the force is
        constant (``K`` and ``tau`` are then undetermined), or the force or
        the record's duration exceeds :data:`MAX_FORCE_N` or
        :data:`MAX_DURATION_S`.
    ValueError
        If the arrays are malformed or ``weighting`` is unknown.
    """
    if f_inst_n is not None:
        anchor = float(f_inst_n)
        if not math.isfinite(anchor):
            raise ValueError(f"f_inst_n must be finite, got {f_inst_n}")
        anchored = _Problem.build(t_s, f_n, n_params=2, weighting=weighting, anchor=anchor)
        fit = anchored.best_one_term()
        return ReducedFit(
            f_inst_n=anchor,
            k_n=float(fit.coef[0]),
            tau_s=float(np.exp(fit.log_tau[0])),
            objective=fit.objective,
            weighting=weighting,
        )
    problem = _Problem.build(t_s, f_n, n_params=3, weighting=weighting)
    best = problem.best_one_term()
    f_eq, k = (float(c) for c in best.coef)
    return ReducedFit(
        f_inst_n=f_eq + k,
        k_n=k,
        tau_s=float(np.exp(best.log_tau[0])),
        objective=best.objective,
        weighting=weighting,
    )


def osculating_reduced(
    t_s: ArrayLike,
    f_n: ArrayLike,
    f_inst_n: float,
    at_s: ArrayLike,
    window_s: float = 2.0,
    min_t_s: float = 1.0,
) -> tuple[FloatArray, FloatArray]:
    """The Eq. 10 curves that touch a hold at the times ``at_s``: same force and slope there.

    At each time ``t`` the curve's force and slope come from a local quadratic
    (Savitzky–Golay over ``window_s``); ``F_inst (1 - kappa (1 - e^{-t/tau}))``
    matches both when ``tau (e^{t/tau} - 1) = y / y'`` with ``y = 1 - F/F_inst``
    the relaxed share and ``y'`` its rate, solved for ``tau`` by bisection (the
    left side falls from infinity to ``t`` as ``tau`` grows), then
    ``kappa = y / (1 - e^{-t/tau})``.  ``tau`` is capped at ten times the
    record (a relaxation that slow is a straight line here).

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Strictly increasing times since the hold onset (s), at least 5 samples.
    f_n : array_like, shape (n,)
        Force (N).
    f_inst_n : float
        Force at the onset, the anchor of Eq. 10 (N), > 0.
    at_s : array_like, shape (m,)
        Times at which to touch the curve (s); times below ``min_t_s`` take the
        curve at ``min_t_s`` (at the onset itself nothing has relaxed yet and
        the pair is undetermined), times past the record its end.
    window_s : float
        Width of the local quadratic (s).
    min_t_s : float
        Earliest time touched (s), > 0.

    Returns
    -------
    kappa, tau_s : ndarray, shape (m,)
        Relaxing share and relaxation time; nan where the force is not
        relaxing there (rising, or not below ``f_inst_n``).

    Raises
    ------
    ValueError
        Malformed arrays or parameters.
    """
    t = _as_times(t_s)
    f = np.asarray(f_n, dtype=np.float64)
    at = np.asarray(at_s, dtype=np.float64)
    if f.shape != t.shape or t.size < 5:
        raise ValueError(f"need matching t_s and f_n of >= 5 samples, got {t.shape}, {f.shape}")
    if not (np.isfinite(f).all() and np.isfinite(at).all() and at.ndim == 1):
        raise ValueError("f_n and at_s must be finite, at_s one-dimensional")
    if not (math.isfinite(f_inst_n) and f_inst_n > 0 and window_s > 0 and min_t_s > 0):
        raise ValueError("f_inst_n, window_s and min_t_s must be > 0")
    from scipy.signal import savgol_filter

    # A uniform grid at the record's median interval, for the Savitzky-Golay filter.
    dt = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    fg = np.interp(grid, t, f)
    n = min(max(5, 2 * round(0.5 * window_s / dt) + 1), grid.size - (1 - grid.size % 2))
    value = savgol_filter(fg, n, 2, mode="interp")
    slope = savgol_filter(fg, n, 2, deriv=1, delta=dt, mode="interp")
    tk = np.clip(at, max(min_t_s, t[0]), t[-1])
    y = 1.0 - np.interp(tk, grid, value) / f_inst_n
    rate = -np.interp(tk, grid, slope) / f_inst_n
    ok = (y > 0) & (rate > 0)
    # With u = t / tau: (e^u - 1) / u = q, increasing in u from 1 at u -> 0.
    q = np.where(ok, y / np.where(ok, rate, 1.0) / tk, 2.0)
    u_min = tk / (_TAU_HI_FACTOR * (t[-1] - t[0]))
    lo, hi = np.log(u_min), np.full(tk.size, np.log(60.0))
    lo = np.minimum(lo, hi)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        u = np.exp(mid)
        above = np.expm1(u) / u > q
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    u = np.exp(0.5 * (lo + hi))
    tau = tk / u
    kappa = y / -np.expm1(-u)
    nan = np.full(tk.size, np.nan)
    return np.where(ok, kappa, nan), np.where(ok, tau, nan)


def fit_prony(
    t_s: ArrayLike, f_n: ArrayLike, n_terms: int = 3, weighting: str = "time"
) -> PronyFit:
    """Least-squares fit of an ``n_terms`` Prony series (Eq. 4).

    Global search by continuation: the best one-term solutions (dense grid)
    are extended by one relaxation time at a time, each new time seeded at
    every point of a log-spaced grid spanning ``[tau_lo, tau_hi]``; every
    seed, plus ``n_terms`` times log-spaced over the record, is refined by a
    local variable-projection solve, and the best few survive to the next
    level.  This finds the global optimum on relaxation data, whose modes are
    spread over decades, and on every synthetic case in the test-suite.

    Parameters
    ----------
    t_s : array_like, shape (n,)
        Strictly increasing times since the hold start (s).
    f_n : array_like, shape (n,)
        Measured force (N).
    n_terms : int
        Number of exponential terms, 1 to :data:`MAX_PRONY_TERMS`.
    weighting : {"time", "sample"}
        Objective, see :func:`quadrature_weights`.

    Returns
    -------
    PronyFit
        The optimum, relaxation times ascending; amplitudes are unconstrained
        in sign, relaxation times lie in ``[tau_lo, tau_hi]``.

    Raises
    ------
    relaxgrip.errors.InputError
        If there are fewer samples than the ``2 n_terms + 1`` parameters, the
        force is constant, the force or the record's duration exceeds
        :data:`MAX_FORCE_N` or :data:`MAX_DURATION_S`, or the hold does not
        hold ``n_terms`` distinct terms: every fit merges two relaxation times
        (within a factor 1.05, or with amplitudes over ten times the force's
        range, which cancel).
    ValueError
        If ``n_terms`` is not an integer from 1 to :data:`MAX_PRONY_TERMS`,
        the arrays are malformed or ``weighting`` is unknown.
    """
    if (isinstance(n_terms, bool) or not isinstance(n_terms, int | np.integer)
            or not 1 <= n_terms <= MAX_PRONY_TERMS):
        raise ValueError(f"n_terms must be an integer from 1 to {MAX_PRONY_TERMS}, "
                         f"got {n_terms!r}")
    problem = _Problem.build(t_s, f_n, n_params=2 * int(n_terms) + 1, weighting=weighting)
    if problem.t_s.size > _COARSE_ABOVE:
        # A long record: the global search on pooled samples, the last solve on all.
        best = problem.refine(problem.coarse(_COARSE_BINS).best_n_terms(int(n_terms)).log_tau)
    else:
        best = problem.best_n_terms(int(n_terms))
    order = np.argsort(best.log_tau)
    return PronyFit(
        f_eq_n=float(best.coef[0]),
        k_n=tuple(float(k) for k in best.coef[1:][order]),
        tau_s=tuple(float(tau) for tau in np.exp(best.log_tau[order])),
        objective=best.objective,
        weighting=weighting,
    )


def _as_times(t_s: ArrayLike) -> FloatArray:
    """Validate a 1-D array of at least two strictly increasing finite times."""
    t = np.asarray(t_s, dtype=np.float64)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"t_s must be a 1-D array of at least 2 times, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("t_s contains non-finite values")
    with np.errstate(over="ignore"):  # times of opposite huge signs: inf is still > 0
        increasing = bool(np.all(np.diff(t) > 0))
    if not increasing:
        raise ValueError("t_s must be strictly increasing")
    return t


@dataclass(frozen=True)
class _Solution:
    """Relaxation times with their optimal amplitudes and objective."""

    log_tau: FloatArray
    coef: FloatArray
    objective: float


@dataclass(frozen=True)
class _Projection:
    """Variable projection at fixed ``log tau``: amplitudes, residual, Jacobian."""

    coef: FloatArray
    resid: FloatArray
    jac: FloatArray


@dataclass(frozen=True)
class _Problem:
    """A weighted exponential-sum least-squares problem ``min ||sqrt(w) (A c - f)||``.

    Free: ``A = [1, e^{-t/tau_1}, ...]`` (a constant and one column per term).
    Anchored at ``F(0) = anchor``: the target is ``f - anchor`` and the columns
    are ``e^{-t/tau_j} - 1``, which vanish at ``t = 0`` (no constant).
    """

    t_s: FloatArray
    sqrt_w: FloatArray
    target: FloatArray
    log_tau_lo: float
    log_tau_hi: float
    anchored: bool = False
    f_range: float = math.inf

    @classmethod
    def build(
        cls,
        t_s: ArrayLike,
        f_n: ArrayLike,
        n_params: int,
        weighting: str,
        anchor: float | None = None,
    ) -> _Problem:
        t = _as_times(t_s)
        f = np.asarray(f_n, dtype=np.float64)
        if f.shape != t.shape:
            raise ValueError(f"f_n has shape {f.shape}, t_s has shape {t.shape}")
        if not np.all(np.isfinite(f)):
            raise ValueError("f_n contains non-finite values")
        if t.size < n_params:
            raise InputError(
                f"cannot fit {n_params} parameters to {t.size} samples: need at least {n_params}"
            )
        if np.ptp(f) == 0.0:
            raise InputError("the force is constant: there is no relaxation to fit")
        # Checked before any arithmetic: squares of larger values overflow, with warnings.
        peak = max(float(np.max(np.abs(f))), 0.0 if anchor is None else abs(anchor))
        if peak > MAX_FORCE_N:
            raise InputError(f"the force reaches {peak:.3g} N, beyond any relaxation test "
                             f"(a fit takes at most {MAX_FORCE_N:g} N)")
        duration = float(t[-1]) - float(t[0])
        if not duration <= MAX_DURATION_S:  # also inf: t_s of opposite huge signs
            raise InputError(f"the record lasts {duration:.3g} s, beyond any relaxation test "
                             f"(a fit takes at most {MAX_DURATION_S:g} s)")
        sqrt_w = np.sqrt(quadrature_weights(t, weighting))
        return cls(
            t_s=t,
            sqrt_w=sqrt_w,
            target=sqrt_w * (f if anchor is None else f - anchor),
            log_tau_lo=math.log(float(np.min(np.diff(t)))),
            log_tau_hi=math.log(_TAU_HI_FACTOR * float(t[-1] - t[0])),
            anchored=anchor is not None,
            f_range=float(np.ptp(f)),
        )

    def coarse(self, n_bins: int) -> _Problem:
        """The problem on the samples pooled into ``n_bins`` log-spaced time bins.

        Each bin keeps its samples' total weight at their weighted mean time
        and force, so the objective is the full one less each bin's spread
        about its mean, which an exponential sum varies too little within a
        bin to see.  The relaxation-time bounds stay the full problem's.
        """
        w = self.sqrt_w**2
        f = self.target / self.sqrt_w
        edges = np.geomspace(max(float(self.t_s[1]), 1e-9), float(self.t_s[-1]), n_bins)
        group = np.searchsorted(edges, self.t_s, side="left")
        total = np.bincount(group, weights=w)
        keep = total > 0
        mean_t = np.bincount(group, weights=w * self.t_s)[keep] / total[keep]
        mean_f = np.bincount(group, weights=w * f)[keep] / total[keep]
        sqrt_w = np.sqrt(total[keep])
        return _Problem(t_s=mean_t, sqrt_w=sqrt_w, target=sqrt_w * mean_f,
                        log_tau_lo=self.log_tau_lo, log_tau_hi=self.log_tau_hi,
                        anchored=self.anchored, f_range=self.f_range)

    def log_grid(self, per_decade: int) -> FloatArray:
        """Log-spaced relaxation times over the admissible range (natural log)."""
        decades = (self.log_tau_hi - self.log_tau_lo) / math.log(10.0)
        return np.linspace(
            self.log_tau_lo, self.log_tau_hi, max(2, math.ceil(decades * per_decade))
        )

    def project(self, log_tau: FloatArray) -> _Projection:
        """Eliminate the amplitudes at fixed ``log tau`` (Golub–Pereyra).

        Returns the optimal amplitudes ``c``, the weighted residual
        ``r = A c - b`` and its exact derivative with respect to ``log tau``:
        ``dr/dθ_j = P⊥ D_j c - (A⁺)ᵀ D_jᵀ r``, where ``D_j = dA/dθ_j`` is
        non-zero only in the column of term ``j``.
        """
        tau = np.exp(log_tau)
        decay = np.exp(-self.t_s[:, None] / tau)
        if self.anchored:
            a = self.sqrt_w[:, None] * (decay - 1.0)
        else:
            a = np.column_stack([self.sqrt_w, self.sqrt_w[:, None] * decay])
        first_term = 0 if self.anchored else 1  # column of the first exponential
        # dA/dθ_j for θ_j = log tau_j: d/dθ e^{-t e^{-θ}} = (t / tau) e^{-t / tau}.
        d = self.sqrt_w[:, None] * decay * (self.t_s[:, None] / tau)
        u, s, vt = np.linalg.svd(a, full_matrices=False)
        rank = int(np.sum(s > s[0] * a.shape[0] * np.finfo(np.float64).eps))
        u, s, vt = u[:, :rank], s[:rank], vt[:rank]
        coef = vt.T @ ((u.T @ self.target) / s)
        resid = a @ coef - self.target
        dc = d * coef[first_term:]
        first = dc - u @ (u.T @ dc)
        # (A⁺)ᵀ e_j = U S⁻¹ Vᵀ e_j for the term's column j, scaled by the scalar d_jᵀ r.
        second = (u / s) @ vt[:, first_term:] * (d.T @ resid)
        return _Projection(coef=coef, resid=resid, jac=first - second)

    def evaluate(self, log_tau: FloatArray) -> _Solution:
        """Objective and amplitudes at fixed relaxation times."""
        p = self.project(log_tau)
        return _Solution(log_tau=log_tau, coef=p.coef, objective=float(p.resid @ p.resid))

    def refine(self, log_tau0: FloatArray) -> _Solution:
        """Local variable-projection solve from ``log_tau0`` (bounded trust region)."""
        # Imported here: scipy.optimize costs ~0.2 s at start-up of every CLI command.
        from scipy.optimize import least_squares

        lo, hi = self.log_tau_lo, self.log_tau_hi
        # trf needs a strictly feasible start.
        margin = 1e-9 * (hi - lo)
        x0 = np.clip(log_tau0, lo + margin, hi - margin)
        cache: dict[bytes, _Projection] = {}

        def projection(x: FloatArray) -> _Projection:
            key = x.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = self.project(x)
            return cache[key]

        fun: Callable[[FloatArray], FloatArray] = lambda x: projection(x).resid  # noqa: E731
        jac: Callable[[FloatArray], FloatArray] = lambda x: projection(x).jac  # noqa: E731
        res = least_squares(
            fun,
            x0,
            jac=jac,
            bounds=(lo, hi),
            method="trf",
            ftol=_LSQ_TOL,
            xtol=_LSQ_TOL,
            gtol=_LSQ_TOL,
            max_nfev=_MAX_NFEV,
        )
        start, end = self.evaluate(x0), self.evaluate(np.asarray(res.x, dtype=np.float64))
        return end if end.objective <= start.objective else start

    def best_one_term(self, keep: int = 1) -> _Solution:
        """Global one-term optimum: dense grid, refine every grid-local minimum."""
        return self._one_term_candidates(keep)[0]

    def _one_term_candidates(self, keep: int) -> list[_Solution]:
        grid = self.log_grid(_GRID_PER_DECADE)
        values = np.array([self.evaluate(np.array([g])).objective for g in grid])
        is_min = np.ones(grid.size, dtype=bool)
        is_min[1:] &= values[1:] <= values[:-1]
        is_min[:-1] &= values[:-1] <= values[1:]
        refined = [self.refine(np.array([g])) for g in grid[is_min]]
        return _distinct_best(refined, keep)

    def best_n_terms(self, n_terms: int) -> _Solution:
        """Global ``n_terms`` optimum by multi-start continuation (see :func:`fit_prony`)."""
        beam = self._one_term_candidates(_BEAM_WIDTH)
        seeds = self.log_grid(_SEEDS_PER_DECADE)
        for level in range(2, n_terms + 1):
            span = np.linspace(self.log_tau_lo, math.log(float(self.t_s[-1] - self.t_s[0])), level)
            starts = [span]
            for sol in beam:
                starts.extend(
                    np.sort(np.append(sol.log_tau, g))
                    for g in seeds
                    if np.min(np.abs(sol.log_tau - g)) > math.log(_MIN_SEED_RATIO)
                )
            refined = [self.refine(s) for s in starts]
            admissible = [sol for sol in refined if self.admissible(sol)]
            if not admissible:
                worst = min(refined, key=lambda sol: sol.objective)
                order = np.argsort(worst.log_tau)
                taus = ", ".join(f"{math.exp(v):.4g}" for v in worst.log_tau[order])
                amps = ", ".join(f"{k:+.4g}" for k in worst.coef[-level:][order])
                raise UnidentifiableError(
                    f"a {level}-term Prony series is not identifiable on this hold: its best "
                    f"fits put relaxation times together (tau {taus} s) with amplitudes that "
                    f"cancel ({amps} N); fit fewer terms", level)
            beam = _distinct_best(admissible, _BEAM_WIDTH)
        return beam[0]

    def admissible(self, sol: _Solution) -> bool:
        """Whether a solution's terms are distinct: relaxation times a factor apart and
        amplitudes within reason (coinciding times take huge cancelling amplitudes)."""
        log_tau = np.sort(sol.log_tau)
        amps = np.abs(sol.coef[-log_tau.size:])
        return bool(np.all(np.diff(log_tau) >= math.log(_MIN_TERM_RATIO))
                    and np.all(amps <= _MAX_AMPLITUDE_RANGES * self.f_range))


def _distinct_best(solutions: list[_Solution], keep: int) -> list[_Solution]:
    """The ``keep`` lowest-objective solutions with distinct relaxation-time sets."""
    chosen: list[_Solution] = []
    for sol in sorted(solutions, key=lambda s: s.objective):
        key = np.sort(sol.log_tau)
        if all(not np.allclose(key, np.sort(c.log_tau), atol=1e-3) for c in chosen):
            chosen.append(sol)
        if len(chosen) == keep:
            break
    return chosen
