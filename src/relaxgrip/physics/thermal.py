"""Finger heat model: a few thermal nodes along the finger.

Each finger is a chain of ``n`` nodes from base to tip.  A heater film (power
``duty V^2 / R``, split over the nodes it covers) heats them, neighbouring
nodes exchange heat by conduction, every node loses heat to the air by
convection, and the base node also conducts into the gripper mount (held at
ambient)::

    C dT_j/dt = q_j duty V^2/R + G (T_{j-1} - 2 T_j + T_{j+1})
                - hA (T_j - T_amb) - [j = 0] G_base (T_0 - T_amb)

The system is linear, so :func:`heat_step` advances it exactly over any step
with constant duty and ambient temperature (zero-order hold via the matrix
exponential, cached per step length).  Temperatures are °C, powers W,
conductances W/K, capacities J/K.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

__all__ = [
    "HeatParams",
    "discrete_heat_system",
    "duty_for_mean_temp",
    "heat_matrices",
    "heat_step",
    "node_positions_m",
    "steady_state_c",
]


@dataclass(frozen=True)
class HeatParams:
    """Thermal constants of one finger.

    Attributes
    ----------
    n_nodes : int
        Nodes from base to tip.
    length_m : float
        Finger length (m), to place the nodes.
    capacity_j_per_k : float
        Heat capacity of one node (J/K).
    conductance_w_per_k : float
        Conductance between neighbouring nodes (W/K).
    convection_w_per_k : float
        Convective loss ``h A`` of one node (W/K).
    base_conductance_w_per_k : float
        Conductance from the base node into the mount (W/K).
    heater_voltage_v, heater_resistance_ohm : float
        Heater film supply and resistance: full power ``V^2 / R`` (W).
    heater_share : tuple of float
        Share of the heater power each node receives (sums to 1).
    """

    n_nodes: int = 5
    length_m: float = 0.110
    capacity_j_per_k: float = 2.6
    conductance_w_per_k: float = 0.12
    convection_w_per_k: float = 0.018
    base_conductance_w_per_k: float = 0.012
    heater_voltage_v: float = 12.0
    heater_resistance_ohm: float = 20.0
    heater_share: tuple[float, ...] = (0.2, 0.25, 0.25, 0.2, 0.1)

    def __post_init__(self) -> None:
        if self.n_nodes < 1 or len(self.heater_share) != self.n_nodes:
            raise ValueError("heater_share needs one entry per node")
        if abs(sum(self.heater_share) - 1.0) > 1e-9 or min(self.heater_share) < 0:
            raise ValueError("heater_share must be >= 0 and sum to 1")
        positive = (
            self.capacity_j_per_k,
            self.convection_w_per_k,
            self.heater_voltage_v,
            self.heater_resistance_ohm,
            self.length_m,
        )
        if min(positive) <= 0:
            raise ValueError("capacity, convection, heater and length must be > 0")
        if self.conductance_w_per_k < 0 or self.base_conductance_w_per_k < 0:
            raise ValueError("conductances must be >= 0")

    @property
    def heater_power_w(self) -> float:
        """Full heater power ``V^2 / R`` (W)."""
        return self.heater_voltage_v**2 / self.heater_resistance_ohm


def node_positions_m(params: HeatParams) -> FloatArray:
    """Centres of the thermal nodes along the finger (m), base to tip."""
    return (np.arange(params.n_nodes) + 0.5) * params.length_m / params.n_nodes


def heat_matrices(params: HeatParams) -> tuple[FloatArray, FloatArray]:
    """Continuous-time model ``dT/dt = A T + B [duty, T_amb]``.

    Parameters
    ----------
    params : HeatParams
        Thermal constants.

    Returns
    -------
    A : ndarray, shape (n, n)
        State matrix (1/s).
    B : ndarray, shape (n, 2)
        Input matrix for ``[duty, ambient_c]`` (K/s per unit duty, 1/s).
    """
    n = params.n_nodes
    g = params.conductance_w_per_k
    laplacian = np.zeros((n, n))
    for j in range(n - 1):
        laplacian[j, j] += g
        laplacian[j + 1, j + 1] += g
        laplacian[j, j + 1] -= g
        laplacian[j + 1, j] -= g
    loss = np.full(n, params.convection_w_per_k)
    loss[0] += params.base_conductance_w_per_k
    a = -(laplacian + np.diag(loss)) / params.capacity_j_per_k
    b = np.column_stack(
        [np.asarray(params.heater_share) * params.heater_power_w, loss]
    ) / params.capacity_j_per_k
    return a, b


@lru_cache(maxsize=64)
def discrete_heat_system(params: HeatParams, dt_s: float) -> tuple[FloatArray, FloatArray]:
    """Exact zero-order-hold discretisation of :func:`heat_matrices` over ``dt_s``.

    Returns ``(Ad, Bd)`` with ``T[k+1] = Ad T[k] + Bd [duty, T_amb]``.  The
    arrays are cached and read-only.
    """
    from scipy.linalg import expm

    if not 0.0 <= dt_s < math.inf:
        raise ValueError(f"dt_s must be finite and >= 0, got {dt_s}")
    a, b = heat_matrices(params)
    n = params.n_nodes
    aug = np.zeros((n + 2, n + 2))
    aug[:n, :n] = a
    aug[:n, n:] = b
    phi = expm(aug * dt_s)
    ad, bd = phi[:n, :n].copy(), phi[:n, n:].copy()
    ad.flags.writeable = False
    bd.flags.writeable = False
    return ad, bd


def heat_step(
    temps_c: ArrayLike, duty: float, dt_s: float, params: HeatParams, ambient_c: float
) -> FloatArray:
    """Advance the node temperatures by ``dt_s`` at constant duty and ambient.

    Parameters
    ----------
    temps_c : array_like, shape (n_nodes,)
        Node temperatures (°C).
    duty : float
        Heater duty in [0, 1].
    dt_s : float
        Step (s), ``>= 0``.
    params : HeatParams
        Thermal constants.
    ambient_c : float
        Air and mount temperature (°C).

    Returns
    -------
    ndarray, shape (n_nodes,)
        Node temperatures after the step (°C).
    """
    if not 0.0 <= duty <= 1.0:
        raise ValueError(f"heater duty must be in [0, 1], got {duty}")
    ad, bd = discrete_heat_system(params, float(dt_s))
    out: FloatArray = ad @ np.asarray(temps_c, dtype=np.float64) + bd @ np.array([duty, ambient_c])
    return out


def steady_state_c(duty: float, params: HeatParams, ambient_c: float) -> FloatArray:
    """Steady node temperatures at constant duty (°C): solves ``A T + B u = 0``."""
    if not 0.0 <= duty <= 1.0:
        raise ValueError(f"heater duty must be in [0, 1], got {duty}")
    a, b = heat_matrices(params)
    return np.linalg.solve(a, -b @ np.array([duty, ambient_c]))


def duty_for_mean_temp(mean_c: float, params: HeatParams, ambient_c: float) -> float:
    """Constant duty whose steady state has the given mean finger temperature.

    The steady state is affine in the duty, so this is exact; the result is
    clipped to [0, 1] (below ambient, or beyond full power, no duty gets there).
    """
    cold = float(np.mean(steady_state_c(0.0, params, ambient_c)))
    hot = float(np.mean(steady_state_c(1.0, params, ambient_c)))
    return float(np.clip((mean_c - cold) / (hot - cold), 0.0, 1.0))
