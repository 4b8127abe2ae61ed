"""Generalized Maxwell–Wiechert (Prony series) force model (paper Eqs. 1–10).

The model is an equilibrium spring ``k_e(T)`` in parallel with ``N`` Maxwell
branches, each a spring ``k_i(T)`` in series with a dashpot, relaxation time
``tau_i(T) = eta_i(T) / k_i(T)``.  Under a displacement ``X(t)``::

    F(t) = k_e(T) X(t) + sum_i F_i(t)                       (Eq. 1)
    tau_i(T) dF_i/dt + F_i = k_i(T) tau_i(T) dX/dt           (Eq. 2)

All stiffnesses are N/m, displacements m, forces N, times s.  Temperature
enters through the caller: pass the parameters already evaluated at the
current temperature (``k_e``, ``k_i``) and the relaxation times
``tau_i = tau_ref_i * a_T`` (see :mod:`relaxgrip.physics.smp`).

:func:`branch_update` is the exact exponential recursion used everywhere a
history has to be integrated (twin, observer): within one step the
displacement moves linearly and the temperature is constant, which makes the
update exact for piecewise-linear ``X`` and piecewise-constant ``T`` with any
step length (reduced time: a step of ``dt`` at shift factor ``a_T`` advances
each branch by ``dt / (tau_ref_i a_T)`` of its own time constant).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.physics.smp import SMPParams, relaxation_fraction, shift_factor

FloatArray = NDArray[np.float64]

__all__ = [
    "PronySeries",
    "RelaxationParams",
    "branch_update",
    "dominant_mode",
    "finger_prony",
    "phi1",
    "prony_force",
    "reduced_force",
    "step_response",
]


def phi1(h: ArrayLike) -> FloatArray:
    """Return ``(1 - exp(-h)) / h``, with its limit 1 at ``h = 0``.

    Parameters
    ----------
    h : array_like
        Non-negative step lengths in units of the time constant.

    Returns
    -------
    ndarray
        ``(1 - e^{-h}) / h`` evaluated without cancellation for small ``h``.
    """
    h = np.asarray(h, dtype=np.float64)
    small = h < 1e-8
    safe = np.where(small, 1.0, h)
    return np.where(small, 1.0 - 0.5 * h, -np.expm1(-safe) / safe)


def branch_update(
    branch_force_n: ArrayLike,
    dx_m: float,
    dt_s: float,
    k_branch_n_per_m: ArrayLike,
    tau_s: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Advance Maxwell branch forces by one step, exactly (Eq. 2).

    The displacement changes by ``dx_m`` linearly over ``dt_s`` and the
    branch parameters are constant over the step.  ``dt_s = 0`` is an
    instantaneous jump: every branch takes ``k_i dx``.

    Parameters
    ----------
    branch_force_n : array_like, shape (N,)
        Branch forces ``F_i`` at the start of the step (N).
    dx_m : float
        Change of displacement over the step (m).
    dt_s : float
        Step length (s), ``>= 0``.
    k_branch_n_per_m : array_like, shape (N,)
        Branch stiffnesses ``k_i(T)`` (N/m).
    tau_s : array_like, shape (N,)
        Branch relaxation times ``tau_i(T)`` (s), ``> 0``.

    Returns
    -------
    forces : ndarray, shape (N,)
        Branch forces at the end of the step (N).
    gain : ndarray, shape (N,)
        ``dF_i / d(dx)``: the branch's incremental stiffness over this step
        (N/m).  Contact solvers use it to make the step implicit in ``X``.
    """
    tau = np.asarray(tau_s, dtype=np.float64)
    h = dt_s / tau
    gain = np.asarray(k_branch_n_per_m, dtype=np.float64) * phi1(h)
    forces = np.asarray(branch_force_n, dtype=np.float64) * np.exp(-h) + gain * dx_m
    return forces, gain


def step_response(
    t_s: ArrayLike, x0_m: float, k_e_n_per_m: float, k_n_per_m: ArrayLike, tau_s: ArrayLike
) -> FloatArray:
    """Closed-form force after a displacement step ``X(t) = X0 H(t)`` (Eq. 4).

    Parameters
    ----------
    t_s : array_like
        Times since the step (s), ``>= 0``.
    x0_m : float
        Step height (m).
    k_e_n_per_m : float
        Equilibrium stiffness (N/m).
    k_n_per_m, tau_s : array_like, shape (N,)
        Branch stiffnesses (N/m) and relaxation times (s).

    Returns
    -------
    ndarray
        ``F(t) = X0 (k_e + sum_i k_i e^{-t/tau_i})`` (N), same shape as ``t_s``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    k = np.asarray(k_n_per_m, dtype=np.float64)
    tau = np.asarray(tau_s, dtype=np.float64)
    decay = np.exp(-t[..., None] / tau) @ k
    return x0_m * (k_e_n_per_m + decay)


def prony_force(t_s: ArrayLike, f_eq_n: float, k_n: ArrayLike, tau_s: ArrayLike) -> FloatArray:
    """Prony series in force units: ``F(t) = F_eq + sum_i k_i e^{-t/tau_i}``.

    This is Eq. 4 with the step height folded into the amplitudes
    (``F_eq = k_e X0``, ``k_i <- k_i X0``), the form fitted to measured curves.

    Parameters
    ----------
    t_s : array_like
        Times since the hold start (s).
    f_eq_n : float
        Equilibrium (fully relaxed) force (N).
    k_n, tau_s : array_like, shape (N,)
        Branch amplitudes (N) and relaxation times (s).

    Returns
    -------
    ndarray
        Force (N), same shape as ``t_s``.
    """
    return step_response(t_s, 1.0, f_eq_n, k_n, tau_s)


def reduced_force(t_s: ArrayLike, f_inst_n: float, k_n: float, tau_s: float) -> FloatArray:
    """Reduced relaxation model ``F(t) = F_inst - K (1 - e^{-t/tau})`` (Eqs. 9–10).

    Parameters
    ----------
    t_s : array_like
        Times since contact onset (s).
    f_inst_n : float
        Instantaneous force at the hold onset (N).
    k_n : float
        Effective relaxation magnitude ``K`` (N).
    tau_s : float
        Effective relaxation time ``tau`` (s).

    Returns
    -------
    ndarray
        Force (N), same shape as ``t_s``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    return f_inst_n + k_n * np.expm1(-t / tau_s)


def dominant_mode(
    k_n: ArrayLike, tau_s: ArrayLike, horizon_s: float, n_samples: int = 400
) -> tuple[float, float]:
    """Reduce a Prony set to one effective mode over a horizon (Eq. 8).

    Finds ``(K, tau)`` minimising
    ``int_0^H [sum_i k_i (1 - e^{-t/tau_i}) - K (1 - e^{-t/tau})]^2 dt``,
    the least-squares sense of the paper's approximation.  For a fixed
    ``tau`` the optimal ``K`` is linear, so only ``log tau`` is searched
    (a grid, then a bounded scalar refinement).

    Parameters
    ----------
    k_n : array_like, shape (N,)
        Branch amplitudes (N) (``k_i X0`` of Eq. 7).
    tau_s : array_like, shape (N,)
        Branch relaxation times (s).
    horizon_s : float
        Holding horizon ``H`` (s), ``> 0``.
    n_samples : int
        Quadrature points on ``[0, H]``.

    Returns
    -------
    K : float
        Effective relaxation magnitude (N).
    tau : float
        Effective relaxation time (s).
    """
    from scipy.optimize import minimize_scalar

    if horizon_s <= 0:
        raise ValueError(f"horizon_s must be > 0, got {horizon_s}")
    k = np.asarray(k_n, dtype=np.float64)
    tau = np.asarray(tau_s, dtype=np.float64)
    t = np.linspace(0.0, horizon_s, n_samples)
    w = np.full(n_samples, t[1] - t[0])
    w[[0, -1]] *= 0.5
    loss = -np.expm1(-t[:, None] / tau) @ k

    def fit(log_tau: float) -> tuple[float, float]:
        basis = -np.expm1(-t / np.exp(log_tau))
        den = float(np.sum(w * basis * basis))
        big_k = float(np.sum(w * basis * loss)) / den if den > 0 else 0.0
        resid = loss - big_k * basis
        return float(np.sum(w * resid * resid)), big_k

    lo = np.log(min(tau.min(), horizon_s) / 10.0)
    hi = np.log(max(tau.max(), horizon_s) * 10.0)
    grid = np.linspace(lo, hi, 121)
    best = int(np.argmin([fit(g)[0] for g in grid]))
    a, b = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    res = minimize_scalar(lambda g: fit(g)[0], bounds=(a, b), method="bounded",
                          options={"xatol": 1e-10})
    log_tau = float(res.x) if res.fun <= fit(grid[best])[0] else float(grid[best])
    return fit(log_tau)[1], float(np.exp(log_tau))


@dataclass(frozen=True)
class PronySeries:
    """A Prony series evaluated at one temperature, in stiffness units.

    Attributes
    ----------
    k_e_n_per_m : float
        Equilibrium stiffness ``k_e`` (N/m).
    k_n_per_m : tuple of float
        Branch stiffnesses ``k_i`` (N/m).
    tau_s : tuple of float
        Branch relaxation times ``tau_i`` (s).
    """

    k_e_n_per_m: float
    k_n_per_m: tuple[float, ...]
    tau_s: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.k_n_per_m) != len(self.tau_s):
            raise ValueError("k_n_per_m and tau_s must have the same length")
        if any(t <= 0 for t in self.tau_s):
            raise ValueError("relaxation times must be > 0")

    @property
    def k_inst_n_per_m(self) -> float:
        """Instantaneous stiffness ``k_e + sum k_i`` (Eq. 5 divided by X0)."""
        return self.k_e_n_per_m + float(sum(self.k_n_per_m))

    def step_response(self, t_s: ArrayLike, x0_m: float) -> FloatArray:
        """Force after a displacement step ``x0_m`` (Eq. 4), see :func:`step_response`."""
        return step_response(t_s, x0_m, self.k_e_n_per_m, self.k_n_per_m, self.tau_s)

    def dominant_mode(self, x0_m: float, horizon_s: float) -> tuple[float, float]:
        """Effective ``(K, tau)`` of a step ``x0_m`` over ``horizon_s`` (Eq. 8)."""
        return dominant_mode(np.asarray(self.k_n_per_m) * x0_m, self.tau_s, horizon_s)


@dataclass(frozen=True)
class RelaxationParams:
    """How the finger's relaxing stiffness is spread over Maxwell branches.

    Attributes
    ----------
    branch_weights : tuple of float
        Share of the relaxing stiffness in each branch (sums to 1).
    tau_ref_s : tuple of float
        Branch relaxation times at Tg (s); at temperature ``T`` they are
        ``tau_ref_s * a_T(T)``.
    """

    branch_weights: tuple[float, ...] = (0.25, 0.30, 0.45)
    tau_ref_s: tuple[float, ...] = (1.2, 12.0, 120.0)

    def __post_init__(self) -> None:
        if len(self.branch_weights) != len(self.tau_ref_s) or not self.tau_ref_s:
            raise ValueError("branch_weights and tau_ref_s need the same, non-zero length")
        if abs(sum(self.branch_weights) - 1.0) > 1e-9 or min(self.branch_weights) < 0:
            raise ValueError("branch_weights must be >= 0 and sum to 1")
        if min(self.tau_ref_s) <= 0:
            raise ValueError("relaxation times must be > 0")


def finger_prony(
    k_inst_n_per_m: float, temp_c: float, relax: RelaxationParams, smp: SMPParams
) -> PronySeries:
    """Temperature-dependent Prony series of a finger contact (Eqs. 1–5).

    The instantaneous stiffness ``k_inst`` (from the beam model at this
    temperature) is split into an equilibrium spring and the branches by the
    relaxing share ``g(T)`` (:func:`relaxgrip.physics.smp.relaxation_fraction`);
    branch times follow the shift factor ``a_T(T)``.

    Parameters
    ----------
    k_inst_n_per_m : float
        Instantaneous contact stiffness ``k_e + sum k_i`` (N/m).
    temp_c : float
        Finger temperature (°C).
    relax : RelaxationParams
        Branch weights and reference times.
    smp : SMPParams
        Material constants.

    Returns
    -------
    PronySeries
        ``k_e(T)``, ``k_i(T)``, ``tau_i(T)``.
    """
    g = float(relaxation_fraction(temp_c, smp))
    a_t = float(shift_factor(temp_c, smp))
    k_branches = tuple(k_inst_n_per_m * g * w for w in relax.branch_weights)
    taus = tuple(t * a_t for t in relax.tau_ref_s)
    return PronySeries(k_inst_n_per_m * (1.0 - g), k_branches, taus)
