"""Identify a :class:`~relaxgrip.physics.material.Material` from multi-temperature measurements.

The fit runs in four steps, all pure functions of arrays:

1. **Shift factors** (:func:`pair_shift`, :func:`shift_factors`): each pair of
   neighbouring temperatures is overlapped in log-log by sliding the warmer
   curve along the log-time (log-frequency) axis; the shift that minimises the
   squared difference of the log moduli (E, or E' and E'' together) where both
   curves are defined is the pair's.  Its standard error is the Gauss–Newton
   one, ``sigma_r^2 / sum (d log y / d log x)^2``: flat curves (a glassy
   plateau) give large errors.  The pairs chain from the reference
   temperature, their variances add.
2. **Shift law** (:func:`fit_shift_law`, :func:`select_shift_law`): each law of
   :data:`~relaxgrip.physics.material.SHIFT_MODELS` is fitted to the shift
   factors, weighted by their variances; the physical laws (WLF, Arrhenius,
   two-regime) compete on leave-one-temperature-out error and the best is
   kept (the polynomial's error is reported for comparison).
3. **Prony series** (:func:`fit_prony_nnls`, :func:`select_terms`): for 1, 2,
   ... terms, non-negative least squares on relaxation times log-spaced over
   the master curve starts a fit of moduli (``>= 0``) and times together on
   the log residual; the fewest terms whose master-curve error reaches the
   master curve's own scatter (:func:`data_scatter_log10`) are kept.  In the
   frequency domain E' and E'' are fitted together.
4. **Joint refinement** (:func:`refine`): the law's parameters and the Prony
   series together, on the log residual of the whole temperature-dependent
   model against every measured point; the law's standard errors come from
   its Jacobian.

Measurements are :class:`Measurements`: sets of one temperature each, in the
time domain (``x`` = time, s; ``y`` = E(t), Pa) or the frequency domain
(``x`` = angular frequency, rad/s; ``y`` = E', ``y2`` = E'', Pa).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares, minimize_scalar, nnls

from relaxgrip.errors import InputError
from relaxgrip.physics.material import SHIFT_PARAMS, Material, ShiftLaw, log10_shift

FloatArray = NDArray[np.float64]

__all__ = [
    "DOMAINS",
    "PHYSICAL_SHIFT_MODELS",
    "MeasuredSet",
    "Measurements",
    "PronyChoice",
    "ShiftFactors",
    "ShiftLawFit",
    "data_scatter_log10",
    "fit_prony_nnls",
    "fit_shift_law",
    "master_rms_log10",
    "model_residuals_log10",
    "pair_shift",
    "refine",
    "select_shift_law",
    "select_terms",
    "shift_factors",
]

DOMAINS = ("time", "freq")
#: The laws the fit chooses among; ``poly`` is fitted and reported for comparison.
PHYSICAL_SHIFT_MODELS = ("wlf", "arrhenius", "two_regime")
#: Fewest points of each curve where two neighbouring sets overlap after shifting.
MIN_OVERLAP_POINTS = 3
#: Floor of a shift factor's standard error in a law fit (decades): interpolation error.
SIGMA_FLOOR_DECADES = 0.02
_GRID_STEP = 0.05
#: Term selection stops when this many more terms improved the error by less than STALL_GAIN.
STALL_COUNTS = 3
STALL_GAIN = 0.05


@dataclass(frozen=True)
class MeasuredSet:
    """Measurements at one temperature.

    Attributes
    ----------
    temp_c : float
        Mean temperature of the set (°C).
    x : ndarray
        Time (s, time domain) or angular frequency (rad/s), increasing.
    y : ndarray
        E(t) or E'(w) (Pa), > 0.
    y2 : ndarray or None
        E''(w) (Pa), > 0, frequency domain only.
    label : str
        How errors name the set (file and set number).
    """

    temp_c: float
    x: FloatArray
    y: FloatArray
    y2: FloatArray | None
    label: str


@dataclass(frozen=True)
class Measurements:
    """Measured sets of one domain and one kind of modulus, sorted by temperature.

    Attributes
    ----------
    domain : str
        ``"time"`` or ``"freq"``.
    modulus : str
        ``"E"`` (tensile) or ``"G"`` (shear).
    sets : tuple of MeasuredSet
        Ordered by increasing temperature.
    sources : tuple of str
        The files they came from.
    """

    domain: str
    modulus: str
    sets: tuple[MeasuredSet, ...]
    sources: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.domain not in DOMAINS:
            raise ValueError(f"domain must be one of {DOMAINS}, got {self.domain!r}")
        temps = [s.temp_c for s in self.sets]
        if temps != sorted(temps):
            raise ValueError("sets must be ordered by temperature")

    @property
    def sign(self) -> float:
        """Reduced coordinate ``u = log10 x + sign * log10 a_T``: +1 frequency, -1 time."""
        return 1.0 if self.domain == "freq" else -1.0

    @property
    def temps_c(self) -> FloatArray:
        """Set temperatures (°C)."""
        return np.array([s.temp_c for s in self.sets])

    @property
    def n_points(self) -> int:
        """Number of measured values (E' and E'' count separately)."""
        return sum(s.y.size + (0 if s.y2 is None else s.y2.size) for s in self.sets)


def _curves(s: MeasuredSet) -> list[FloatArray]:
    out = [np.log10(s.y)]
    if s.y2 is not None:
        out.append(np.log10(s.y2))
    return out


def _shift_curves(s: MeasuredSet) -> list[FloatArray]:
    # E (or E') only: a loss modulus carries secondary (beta) relaxations in the glassy
    # state that change its level with temperature, which a horizontal shift cannot follow.
    return [np.log10(s.y)]


def _overlap_residuals(u_a: FloatArray, ya: list[FloatArray], u_b: FloatArray,
                       yb: list[FloatArray]) -> tuple[FloatArray, FloatArray] | None:
    """Residuals and local slopes where two curves (log x, [log y]) overlap, both ways."""
    lo, hi = max(u_a[0], u_b[0]), min(u_a[-1], u_b[-1])
    in_a = (u_a >= lo) & (u_a <= hi)
    in_b = (u_b >= lo) & (u_b <= hi)
    if in_a.sum() < MIN_OVERLAP_POINTS or in_b.sum() < MIN_OVERLAP_POINTS:
        return None
    res, slope = [], []
    for c_a, c_b in zip(ya, yb, strict=True):
        res.append(c_a[in_a] - np.interp(u_a[in_a], u_b, c_b))
        slope.append(np.interp(u_a[in_a], u_b, np.gradient(c_b, u_b)))
        res.append(np.interp(u_b[in_b], u_a, c_a) - c_b[in_b])
        slope.append(np.interp(u_b[in_b], u_a, np.gradient(c_a, u_a)))
    return np.concatenate(res), np.concatenate(slope)


def pair_shift(cold: MeasuredSet, warm: MeasuredSet, sign: float) -> tuple[float, float]:
    """Shift ``d = log10 a_T(warm) - log10 a_T(cold)`` overlapping two sets, and its error.

    Parameters
    ----------
    cold, warm : MeasuredSet
        Neighbouring sets (the warmer relaxes faster: ``d < 0`` normally).
    sign : float
        +1 in the frequency domain, -1 in the time domain
        (:attr:`Measurements.sign`).

    Returns
    -------
    d : float
        The shift (decades).
    sigma : float
        Its standard error (decades); ``inf`` where the overlap carries no slope.

    Raises
    ------
    relaxgrip.errors.InputError
        The two sets' moduli do not overlap (no horizontal shift superposes
        them), or no shift overlaps :data:`MIN_OVERLAP_POINTS` points of each.
    """
    ya, yb = _shift_curves(cold), _shift_curves(warm)
    if not any(min(a.max(), b.max()) >= max(a.min(), b.min()) for a, b in zip(ya, yb, strict=True)):
        raise InputError(
            f"{cold.label} ({cold.temp_c:.1f} °C) and {warm.label} ({warm.temp_c:.1f} °C) "
            f"do not overlap enough to shift: their moduli span "
            f"{10 ** ya[0].min():.4g}-{10 ** ya[0].max():.4g} Pa and "
            f"{10 ** yb[0].min():.4g}-{10 ** yb[0].max():.4g} Pa")
    u_a = np.log10(cold.x)
    u_b0 = np.log10(warm.x)
    span = (u_a[-1] - u_a[0]) + (u_b0[-1] - u_b0[0])

    def cost(d: float) -> float:
        got = _overlap_residuals(u_a, ya, u_b0 + sign * d, yb)
        return math.inf if got is None else float(np.mean(got[0] ** 2))

    grid = np.arange(-span, span + _GRID_STEP, _GRID_STEP)
    costs = np.array([cost(float(d)) for d in grid])
    if not np.isfinite(costs).any():
        raise InputError(
            f"{cold.label} ({cold.temp_c:.1f} °C) and {warm.label} ({warm.temp_c:.1f} °C) "
            f"do not overlap enough to shift: fewer than {MIN_OVERLAP_POINTS} points of each "
            "meet at any shift")
    k = int(np.argmin(costs))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-6})
    d = float(res.x) if res.fun <= costs[k] else float(grid[k])
    got = _overlap_residuals(u_a, ya, u_b0 + sign * d, yb)
    assert got is not None
    r, slope = got
    n = r.size
    s2 = float(np.sum(r**2)) / max(n - 1, 1)
    info = float(np.sum(slope**2))
    sigma = math.sqrt(s2 / info) if info > 0 else math.inf
    return d, sigma


@dataclass(frozen=True)
class ShiftFactors:
    """Shift factors of every set relative to one measured set.

    Attributes
    ----------
    temps_c : ndarray
        Set temperatures (°C).
    log_at : ndarray
        ``log10 a_T`` relative to set ``anchor`` (decades).
    sigma : ndarray
        Standard errors (decades), 0 at the anchor.
    anchor : int
        Index of the set the shifts are relative to.
    pair_shifts : ndarray
        The neighbouring pairs' shifts (decades), ``len(sets) - 1``.
    """

    temps_c: FloatArray
    log_at: FloatArray
    sigma: FloatArray
    anchor: int
    pair_shifts: FloatArray


def shift_factors(meas: Measurements, anchor: int) -> ShiftFactors:
    """Chain the neighbouring pairs' shifts from set ``anchor`` (see :func:`pair_shift`)."""
    n = len(meas.sets)
    d = np.zeros(n - 1)
    s = np.zeros(n - 1)
    for i in range(n - 1):
        d[i], s[i] = pair_shift(meas.sets[i], meas.sets[i + 1], meas.sign)
    log_at = np.concatenate([[0.0], np.cumsum(d)])
    var = np.concatenate([[0.0], np.cumsum(s**2)])
    log_at -= log_at[anchor]
    var = np.abs(var - var[anchor])
    return ShiftFactors(meas.temps_c, log_at, np.sqrt(var), anchor, d)


@dataclass(frozen=True)
class ShiftLawFit:
    """One shift law fitted to shift factors.

    Attributes
    ----------
    model : str
        The law.
    params : ndarray
        Its parameters (order of :data:`~relaxgrip.physics.material.SHIFT_PARAMS`).
    sigma : ndarray
        Their standard errors.
    rms_decades : float
        Weighted RMS of the fit's residuals (decades).
    heldout_decades : float
        Weighted RMS of leave-one-temperature-out prediction errors (decades).
    """

    model: str
    params: FloatArray
    sigma: FloatArray
    rms_decades: float
    heldout_decades: float


def _initial(model: str, temps: FloatArray, log_at: FloatArray, ref_c: float) -> list[FloatArray]:
    """Starting points for a law's fit (a few, the best fit of them wins)."""
    slope = np.polyfit(temps - ref_c, log_at, 1)[0]  # decades per K, < 0
    c1_c2 = max(-slope, 1e-3)
    tk = ref_c + 273.15
    ea = max(c1_c2 * np.log(10) * 8.314462618 * tk**2, 1e3)
    span = float(temps.max() - temps.min())
    if model == "wlf":
        return [np.array([c1_c2 * c2, c2]) for c2 in (30.0, 60.0, 120.0, 300.0)
                if c2 > ref_c - temps.min() + 1.0] or [np.array([c1_c2 * 2 * span, 2 * span])]
    if model == "arrhenius":
        return [np.array([ea])]
    if model == "poly":
        return [np.array([slope, 0.0, 0.0, 0.0])]
    starts = []
    for tg in np.quantile(temps, [0.3, 0.5, 0.7]):
        for c2 in (30.0, 60.0, 120.0):
            starts.append(np.array([c1_c2 * c2, c2, tg, ea]))
    return starts


def _bounds(model: str, temps: FloatArray, ref_c: float) -> tuple[list[float], list[float]]:
    if model == "wlf":  # pole below the coldest temperature
        return [1e-6, ref_c - temps.min() + 0.5], [1e4, 1e5]
    if model == "arrhenius":
        return [1.0], [1e8]
    if model == "poly":
        return [-np.inf] * 4, [np.inf] * 4
    return [1e-6, 1e-3, float(temps.min()), 1.0], [1e4, 1e5, float(temps.max()), 1e8]


def _law_fit(model: str, temps: FloatArray, obs: FloatArray, w: FloatArray, anchor_c: float,
             ref_c: float, starts: list[FloatArray] | None = None
             ) -> tuple[FloatArray, FloatArray, float]:
    """Weighted fit of ``law(T; ref) - law(anchor; ref)`` to ``obs``; params, cov, rss."""
    def resid(p: FloatArray) -> FloatArray:
        pred = log10_shift(model, p, temps, ref_c) - log10_shift(model, p, anchor_c, ref_c)
        return np.asarray((pred - obs) * w, dtype=np.float64)

    lo, hi = _bounds(model, temps, ref_c)
    best: Any = None
    for x0 in starts if starts is not None else _initial(model, temps, obs, anchor_c):
        x0 = np.clip(x0, np.array(lo) + 1e-9, np.array(hi) - 1e-9)
        try:
            r = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", max_nfev=2000)
        except ValueError:
            continue
        if best is None or r.cost < best.cost:
            best = r
    if best is None:
        raise ValueError(f"cannot fit the {model} law")
    dof = max(temps.size - len(best.x), 1)
    s2 = 2.0 * best.cost / dof
    # Weighted residuals: a reduced chi-square below 1 does not shrink the errors.
    return best.x, _param_sigma(best.jac, max(s2, 1.0)), 2.0 * best.cost


def _param_sigma(jac: FloatArray, s2: float) -> FloatArray:
    """Standard errors ``sqrt(diag(s2 (J^T J)^-1))``, with the columns scaled first."""
    norms = np.linalg.norm(jac, axis=0)
    norms[norms == 0] = 1.0
    js = jac / norms
    cov = np.linalg.pinv(js.T @ js) * s2
    return np.asarray(np.sqrt(np.clip(np.diag(cov), 0.0, None)) / norms, dtype=np.float64)


def fit_shift_law(model: str, sf: ShiftFactors, ref_temp_c: float) -> ShiftLawFit:
    """Fit one law to shift factors, weighted by their variances, with leave-one-out error.

    Parameters
    ----------
    model : str
        A law of :data:`~relaxgrip.physics.material.SHIFT_MODELS`.
    sf : ShiftFactors
        The measured shift factors (relative to their anchor set).
    ref_temp_c : float
        The law's reference temperature (°C).

    Returns
    -------
    ShiftLawFit
        Parameters, standard errors, the weighted RMS and the held-out RMS.
    """
    temps, obs = sf.temps_c, sf.log_at
    sig = np.maximum(sf.sigma, SIGMA_FLOOR_DECADES)
    w = 1.0 / sig
    anchor_c = float(temps[sf.anchor])
    p, sigma, rss = _law_fit(model, temps, obs, w, anchor_c, ref_temp_c)
    rms = math.sqrt(rss / float(np.sum(w**2)))
    errs, weights = [], []
    for k in range(temps.size):
        if k == sf.anchor:
            continue
        keep = np.arange(temps.size) != k
        try:
            pk, _, _ = _law_fit(model, temps[keep], obs[keep], w[keep], anchor_c, ref_temp_c,
                                starts=[p])
            pred = float(log10_shift(model, pk, temps[k], ref_temp_c)
                         - log10_shift(model, pk, anchor_c, ref_temp_c))
        except ValueError:
            pred = math.inf
        errs.append(pred - obs[k])
        weights.append(w[k] ** 2)
    e, ww = np.array(errs), np.array(weights)
    heldout = math.sqrt(float(np.sum(ww * e**2) / np.sum(ww))) if e.size else math.nan
    return ShiftLawFit(model, p, sigma, rms, heldout)


def select_shift_law(sf: ShiftFactors, ref_temp_c: float,
                     models: tuple[str, ...] = tuple(SHIFT_PARAMS)
                     ) -> tuple[str, list[ShiftLawFit]]:
    """Fit every law; the physical one of least held-out error is chosen.

    Returns
    -------
    chosen : str
        The chosen law's name (one of :data:`PHYSICAL_SHIFT_MODELS` when any was fitted).
    fits : list of ShiftLawFit
        Every law's fit, in the order of ``models``.
    """
    fits = [fit_shift_law(m, sf, ref_temp_c) for m in models]
    candidates = [f for f in fits if f.model in PHYSICAL_SHIFT_MODELS] or fits
    chosen = min(candidates, key=lambda f: (f.heldout_decades, len(f.params)))
    return chosen.model, fits


def _design(domain: str, u: FloatArray, taus: FloatArray) -> tuple[FloatArray, FloatArray | None]:
    """Basis functions of E_inf and each term at reduced coordinates ``u`` (log10 x)."""
    x = 10.0**u
    if domain == "time":
        return np.column_stack([np.ones_like(x), np.exp(-x[:, None] / taus)]), None
    wt = x[:, None] * taus
    stor = np.column_stack([np.ones_like(x), wt * wt / (1.0 + wt * wt)])
    loss = np.column_stack([np.zeros_like(x), wt / (1.0 + wt * wt)])
    return stor, loss


def fit_prony_nnls(domain: str, u: FloatArray, y: FloatArray, y2: FloatArray | None,
                   taus: FloatArray) -> tuple[float, FloatArray]:
    """Non-negative ``E_inf`` and moduli on fixed ``taus`` minimising relative error.

    Parameters
    ----------
    domain : str
        ``"time"`` or ``"freq"``.
    u : ndarray
        Reduced coordinates ``log10(t / a_T)`` or ``log10(w a_T)``.
    y, y2 : ndarray
        E(t) or E' (Pa), and E'' (Pa) in the frequency domain.
    taus : ndarray
        Relaxation times (s) at the reference temperature.

    Returns
    -------
    e_inf : float
        Equilibrium modulus (Pa).
    moduli : ndarray
        Prony moduli (Pa), ``>= 0``, one per tau.
    """
    a1, a2 = _design(domain, u, taus)
    rows, rhs = [a1 / y[:, None]], [np.ones_like(y)]
    if a2 is not None and y2 is not None:
        rows.append(a2 / y2[:, None])
        rhs.append(np.ones_like(y2))
    a = np.vstack(rows)
    b = np.concatenate(rhs)
    scale = np.maximum(np.abs(a).max(axis=0), 1e-300)
    coef, _ = nnls(a / scale, b, maxiter=50 * a.shape[1])
    coef = coef / scale
    return float(coef[0]), coef[1:]


def _prony_log10(domain: str, u: FloatArray, e_inf: float, moduli: FloatArray,
                 taus: FloatArray) -> tuple[FloatArray, FloatArray | None]:
    a1, a2 = _design(domain, u, taus)
    coef = np.concatenate([[e_inf], moduli])
    m1 = np.log10(np.maximum(a1 @ coef, 1e-300))
    m2 = None if a2 is None else np.log10(np.maximum(a2 @ coef, 1e-300))
    return m1, m2


@dataclass(frozen=True)
class PronyChoice:
    """The term-count selection.

    Attributes
    ----------
    taus : ndarray
        Relaxation times of the chosen series (s).
    e_inf : float
        Equilibrium modulus (Pa).
    moduli : ndarray
        Moduli (Pa), one per tau (zeros dropped).
    table : list of dict
        Per tried number of terms: ``n_terms``, ``n_nonzero`` and ``rms_log10_master``.
    target_log10 : float
        The error the selection aimed at (the data's scatter).
    """

    taus: FloatArray
    e_inf: float
    moduli: FloatArray
    table: list[dict[str, float]] = field(default_factory=list)
    target_log10: float = math.nan


def log_spaced_taus(u: FloatArray, n: int, domain: str) -> FloatArray:
    """``n`` relaxation times log-spaced over the master curve's reduced range."""
    if domain == "time":
        lo, hi = u.min(), u.max()
    else:  # tau ~ 1/w
        lo, hi = -u.max(), -u.min()
    if n == 1:
        return np.array([10.0 ** (0.5 * (lo + hi))])
    return 10.0 ** np.linspace(lo, hi, n)


def master_rms_log10(domain: str, u: FloatArray, y: FloatArray, y2: FloatArray | None,
                e_inf: float, moduli: FloatArray, taus: FloatArray) -> float:
    m1, m2 = _prony_log10(domain, u, e_inf, moduli, taus)
    r = [m1 - np.log10(y)]
    if m2 is not None and y2 is not None:
        r.append(m2 - np.log10(y2))
    rr = np.concatenate(r)
    return float(np.sqrt(np.mean(rr**2)))


def data_scatter_log10(u: FloatArray, y: FloatArray, y2: FloatArray | None = None,
                       window_decades: float = 1.0) -> float:
    """The master curve's own scatter (log10) about a local quadratic.

    Each point is predicted by a quadratic in log-log through the other points
    of the master curve within ``window_decades / 2`` of it (leave one out);
    the RMS of those prediction errors, corrected for the quadratic's own
    variance, is the error no smooth curve through the shifted data can beat
    by more than chance: measurement noise and what the superposition leaves.
    """
    sq, count = 0.0, 0
    for curve in (y, y2):
        if curve is None:
            continue
        order = np.argsort(u)
        uu, ly = u[order], np.log10(curve[order])
        half = 0.5 * window_decades
        lo = np.searchsorted(uu, uu - half, side="left")
        hi = np.searchsorted(uu, uu + half, side="right")
        for i in range(uu.size):
            idx = np.r_[lo[i]:i, i + 1:hi[i]]
            if idx.size < 6:
                continue
            du = uu[idx] - uu[i]
            coef = np.polyfit(du, ly[idx], 2)
            r = ly[i] - coef[-1]
            sq += r * r / (1.0 + 3.0 / idx.size)
            count += 1
    return math.sqrt(sq / count) if count else 0.0


def _prony_resid(domain: str, u: FloatArray, logy: FloatArray, logy2: FloatArray | None,
                 p: FloatArray, n: int, scale: float) -> FloatArray:
    """Log10 residuals of a Prony series ``p = [E_inf, E_1..n, log10 tau_1..n]``.

    The moduli in ``p`` are divided by ``scale``.
    """
    coef = p[: n + 1] * scale
    taus = 10.0 ** p[n + 1:]
    a1, a2 = _design(domain, u, taus)
    out = [np.log10(np.maximum(a1 @ coef, 1e-300)) - logy]
    if a2 is not None and logy2 is not None:
        out.append(np.log10(np.maximum(a2 @ coef, 1e-300)) - logy2)
    return np.concatenate(out)


def _prony_jac(domain: str, u: FloatArray, logy: FloatArray, logy2: FloatArray | None,
               p: FloatArray, n: int, scale: float) -> FloatArray:
    """Analytic Jacobian of :func:`_prony_resid`."""
    coef = p[: n + 1] * scale
    taus = 10.0 ** p[n + 1:]
    x = 10.0**u
    ln10 = math.log(10.0)
    blocks = []
    if domain == "time":
        z = x[:, None] / taus
        f = np.exp(-z)
        parts = [(np.column_stack([np.ones_like(x), f]), f * z)]
    else:
        z = x[:, None] * taus
        d = 1.0 + z * z
        parts = [(np.column_stack([np.ones_like(x), z * z / d]), 2.0 * z * z / d**2)]
        if logy2 is not None:
            parts.append((np.column_stack([np.zeros_like(x), z / d]), z * (1.0 - z * z) / d**2))
    for basis, dlntau in parts:
        m = np.maximum(basis @ coef, 1e-300)
        j_mod = basis * scale / (m[:, None] * ln10)
        # d/d log10 tau = ln10 d/d ln tau; over ln10 for the log10 residual.
        j_tau = dlntau * coef[1:] / m[:, None]
        blocks.append(np.hstack([j_mod, j_tau]))
    return np.vstack(blocks)


def _tau_bounds(domain: str, u: FloatArray) -> tuple[float, float]:
    """Bounds of log10 tau: two decades beyond the master curve's reduced range."""
    lo, hi = (u.min(), u.max()) if domain == "time" else (-u.max(), -u.min())
    return float(lo - 2.0), float(hi + 2.0)


def _refine_master(domain: str, u: FloatArray, y: FloatArray, y2: FloatArray | None,
                   e_inf: float, moduli: FloatArray, taus: FloatArray, max_nfev: int = 60
                   ) -> tuple[float, FloatArray, FloatArray, float]:
    """Moduli (>= 0) and relaxation times together on the master curve's log residual."""
    n = taus.size
    logy = np.log10(y)
    logy2 = None if y2 is None else np.log10(y2)
    scale = float(np.median(y))
    x0 = np.concatenate([[e_inf / scale], moduli / scale, np.log10(taus)])
    t_lo, t_hi = _tau_bounds(domain, u)
    lo = np.concatenate([np.zeros(n + 1), np.full(n, t_lo)])
    hi = np.concatenate([np.full(n + 1, np.inf), np.full(n, t_hi)])
    x0[: n + 1] = np.maximum(x0[: n + 1], 1e-9)
    x0[n + 1:] = np.clip(x0[n + 1:], t_lo + 1e-9, t_hi - 1e-9)
    def resid(p: FloatArray) -> FloatArray:
        return _prony_resid(domain, u, logy, logy2, p, n, scale)

    def jac(p: FloatArray) -> FloatArray:
        return _prony_jac(domain, u, logy, logy2, p, n, scale)

    r = least_squares(resid, x0, jac=jac,
                      bounds=(lo, hi), x_scale="jac", max_nfev=max_nfev, ftol=1e-6)
    rms = float(np.sqrt(np.mean(r.fun**2)))
    return (float(r.x[0] * scale), r.x[1: n + 1] * scale, 10.0 ** r.x[n + 1:], rms)


def select_terms(domain: str, u: FloatArray, y: FloatArray, y2: FloatArray | None,
                 target_log10: float, max_terms: int) -> PronyChoice:
    """Fewest terms whose master-curve error reaches ``target_log10``.

    For each count, NNLS on log-spaced times starts a least-squares fit of
    moduli (``>= 0``) and times together on the log residual.  Where no
    count up to ``max_terms`` reaches the target, or :data:`STALL_COUNTS` more
    terms gained less than :data:`STALL_GAIN` of the error, the count of least
    error so far is kept.
    """
    table: list[dict[str, float]] = []
    best: tuple[float, float, FloatArray, FloatArray] | None = None
    chosen = None
    for n in range(1, max_terms + 1):
        taus = log_spaced_taus(u, n, domain)
        e_inf, mod = fit_prony_nnls(domain, u, y, y2, taus)
        rms_nnls = master_rms_log10(domain, u, y, y2, e_inf, mod, taus)
        e_inf, mod, taus, rms = _refine_master(domain, u, y, y2, e_inf, mod, taus)
        table.append({"n_terms": n, "n_nonzero": int(np.count_nonzero(mod)),
                      "rms_log10_master_nnls": rms_nnls, "rms_log10_master": rms})
        if best is None or rms < best[0]:
            best = (rms, e_inf, mod, taus)
        if rms <= target_log10:
            chosen = (rms, e_inf, mod, taus)
            break
        recent = [row["rms_log10_master"] for row in table[-STALL_COUNTS - 1:]]
        if len(recent) > STALL_COUNTS and min(recent[1:]) > (1.0 - STALL_GAIN) * recent[0]:
            break  # more terms no longer pay: the data's limit is not the series'

    pick = chosen if chosen is not None else best
    assert pick is not None
    _, e_inf, mod, taus = pick
    keep = mod > 0
    order = np.argsort(taus[keep])
    return PronyChoice(taus[keep][order], e_inf, mod[keep][order], table, target_log10)


def model_residuals_log10(material: Material, meas: Measurements) -> FloatArray:
    """``log10`` model minus measured at every point (E, or E' then E'' per set)."""
    out = []
    for s in meas.sets:
        if meas.domain == "time":
            out.append(np.log10(material.relaxation_modulus_pa(s.x, s.temp_c)) - np.log10(s.y))
        else:
            out.append(np.log10(material.storage_modulus_pa(s.x, s.temp_c)) - np.log10(s.y))
            if s.y2 is not None:
                out.append(np.log10(np.maximum(material.loss_modulus_pa(s.x, s.temp_c), 1e-300))
                           - np.log10(s.y2))
    return np.concatenate(out)


def refine(meas: Measurements, model: str, law_params: FloatArray, ref_temp_c: float,
           e_inf: float, moduli: FloatArray, taus: FloatArray
           ) -> tuple[FloatArray, FloatArray, float, FloatArray, FloatArray]:
    """Refine the law's parameters and the Prony series together on every measured point.

    Minimises the log10 residual of the whole temperature-dependent model
    (:func:`model_residuals_log10`) over the law's parameters, ``E_inf, E_i >= 0``
    and the relaxation times.

    Returns
    -------
    law_params, law_sigma : ndarray
        The law's parameters and their standard errors (the Prony series'
        parameters profiled out).
    e_inf : float
        Equilibrium modulus (Pa).
    moduli, taus : ndarray
        Moduli (Pa) and relaxation times (s) at ``ref_temp_c``.
    """
    n_law = law_params.size
    n = taus.size
    y = np.concatenate([s.y for s in meas.sets])
    y2 = None if meas.domain == "time" else np.concatenate(
        [s.y2 for s in meas.sets if s.y2 is not None])
    logy = np.log10(y)
    logy2 = None if y2 is None else np.log10(y2)
    scale = float(np.median(y))
    temps = meas.temps_c
    lo_law, hi_law = _bounds(model, temps, ref_temp_c)
    logx = [np.log10(s.x) for s in meas.sets]
    counts = [s.x.size for s in meas.sets]

    def u_of(law: FloatArray) -> FloatArray:
        log_at = log10_shift(model, law, temps, ref_temp_c)
        return np.concatenate([lx + meas.sign * a for lx, a in zip(logx, log_at, strict=True)])

    def resid(p: FloatArray) -> FloatArray:
        try:
            u = u_of(p[:n_law])
        except ValueError:
            return np.full(meas.n_points, 10.0)
        return _prony_resid(meas.domain, u, logy, logy2, p[n_law:], n, scale)

    def jac(p: FloatArray) -> FloatArray:
        law = p[:n_law]
        try:
            u = u_of(law)
        except ValueError:
            return np.zeros((meas.n_points, p.size))
        j_prony = _prony_jac(meas.domain, u, logy, logy2, p[n_law:], n, scale)
        # The law moves every point of a set along u: d r / d law = (d r / d u) (d u / d law).
        base = _prony_resid(meas.domain, u, logy, logy2, p[n_law:], n, scale)
        du = 1e-5
        dr_du = (_prony_resid(meas.domain, u + du, logy, logy2, p[n_law:], n, scale) - base) / du
        log_at = log10_shift(model, law, temps, ref_temp_c)
        j_law = np.zeros((base.size, n_law))
        for k in range(n_law):
            step = np.zeros(n_law)
            step[k] = 1e-6 * max(abs(law[k]), 1.0)
            try:
                d_at = (log10_shift(model, law + step, temps, ref_temp_c) - log_at) / step[k]
            except ValueError:
                continue
            du_dp = meas.sign * np.repeat(d_at, counts)
            reps = base.size // du_dp.size
            j_law[:, k] = dr_du * np.tile(du_dp, reps)
        return np.hstack([j_law, j_prony])

    x0 = np.concatenate([law_params, [max(e_inf, 0.0) / scale], moduli / scale, np.log10(taus)])
    t_lo, t_hi = _tau_bounds(meas.domain, u_of(law_params))
    t_lo, t_hi = min(t_lo, float(np.log10(taus).min())), max(t_hi, float(np.log10(taus).max()))
    lo = np.concatenate([lo_law, np.zeros(1 + n), np.full(n, t_lo - 1.0)])
    hi = np.concatenate([hi_law, np.full(1 + n, np.inf), np.full(n, t_hi + 1.0)])
    x0 = np.clip(x0, lo + 1e-12, np.where(np.isfinite(hi), hi - 1e-12, np.inf))
    r = least_squares(resid, x0, jac=jac, bounds=(lo, hi), x_scale="jac", max_nfev=300)
    dof = max(r.fun.size - r.x.size, 1)
    s2 = float(np.sum(r.fun**2)) / dof
    sigma = _param_sigma(np.asarray(r.jac), s2)[:n_law]
    q = r.x[n_law:]
    return (r.x[:n_law], sigma, float(q[0] * scale), q[1: n + 1] * scale, 10.0 ** q[n + 1:])


def to_material(modulus: str, model: str, law_params: FloatArray, ref_temp_c: float,
                e_inf: float, moduli: FloatArray, taus: FloatArray,
                temp_range_c: tuple[float, float], provenance_json: str) -> Material:
    """A :class:`Material` from fitted arrays; terms of zero modulus are dropped."""
    keep = moduli > 0
    return Material(modulus=modulus, e_inf_pa=float(max(e_inf, 0.0)),
                    moduli_pa=tuple(float(v) for v in moduli[keep]),
                    tau_s=tuple(float(v) for v in taus[keep]),
                    shift=ShiftLaw(model, tuple(float(v) for v in law_params), float(ref_temp_c)),
                    temp_range_c=temp_range_c, provenance_json=provenance_json)
