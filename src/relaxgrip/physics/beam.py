"""The finger as a cantilever with temperature-dependent bending stiffness.

The finger is clamped at ``x = 0`` and free at ``x = L``; a normal load
``F`` acts at the contact position ``a``.  Its bending stiffness is a skeleton
part (a slightly tapered elastomer lattice, weakly temperature dependent) plus
the SMP beams, which follow the storage modulus::

    EI(x, T) = EI_sk(x) (1 - beta (T - T_ref)) + EI_sk(x) r(x) E'(T) / E'(T_ref)

with ``r(x)`` the SMP-to-skeleton ratio at room temperature (largest at the
base, where the SMP beams sit).  Euler–Bernoulli small-deflection theory gives
the profile ``z(x)``; a mild geometric stiffening
``F = z_a / c_a (1 + gamma (z_a / L)^2)`` (the lever arm shortens as the
finger bends) makes large deflections slightly stiffer.

Lengths are m, forces N, EI in N m^2.  Functions take temperatures either as
a scalar (uniform finger) or as an array on :func:`beam_grid` (a temperature
field along the finger).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.physics.smp import SMPParams, storage_modulus_pa

FloatArray = NDArray[np.float64]

__all__ = [
    "FingerParams",
    "beam_grid",
    "bending_stiffness_n_m2",
    "contact_compliance_m_per_n",
    "contact_deflection_m",
    "deflection_area_m2",
    "deflection_profile_m",
    "deflection_share",
    "finger_from_k80",
    "local_stiffness_n_per_m",
    "smp_share",
    "stiffening_factor",
    "unit_profile_m_per_n",
]


@dataclass(frozen=True)
class FingerParams:
    """Geometry and stiffness of one finger.

    Attributes
    ----------
    length_m : float
        Finger length ``L`` (m).
    n_grid : int
        Quadrature points along the finger.
    ei_skeleton_base_n_m2 : float
        Skeleton bending stiffness at the base (N m^2).
    skeleton_taper : float
        Relative loss of skeleton stiffness from base to tip
        (``EI_sk(x) = EI_base (1 - taper x / L)``).
    skeleton_temp_coeff_per_k : float
        Relative softening of the skeleton per kelvin above ``ref_temp_c``.
    smp_ratio_base, smp_ratio_tip : float
        SMP-to-skeleton stiffness ratio ``r(x)`` at the base and the tip at
        ``ref_temp_c`` (linear in between).
    stiffening : float
        Geometric stiffening coefficient ``gamma``.
    ref_temp_c : float
        Reference (room) temperature (°C).
    smp : SMPParams
        The SMP's material constants.
    """

    length_m: float = 0.110
    n_grid: int = 221
    ei_skeleton_base_n_m2: float = 0.156
    skeleton_taper: float = 0.21
    skeleton_temp_coeff_per_k: float = 0.0015
    smp_ratio_base: float = 0.80
    smp_ratio_tip: float = 0.0
    stiffening: float = 4.0
    ref_temp_c: float = 25.0
    smp: SMPParams = field(default_factory=SMPParams)

    def __post_init__(self) -> None:
        if self.length_m <= 0 or self.n_grid < 3:
            raise ValueError("need length_m > 0 and n_grid >= 3")
        if self.ei_skeleton_base_n_m2 <= 0 or not (0 <= self.skeleton_taper < 1):
            raise ValueError("need ei_skeleton_base_n_m2 > 0 and 0 <= skeleton_taper < 1")
        if self.smp_ratio_base < 0 or self.smp_ratio_tip < 0 or self.stiffening < 0:
            raise ValueError("SMP ratios and stiffening must be >= 0")


def beam_grid(finger: FingerParams) -> FloatArray:
    """Quadrature points ``x`` along the finger, from base 0 to tip ``L`` (m); read-only."""
    return _grid(finger.length_m, finger.n_grid)


@lru_cache(maxsize=16)
def _grid(length_m: float, n_grid: int) -> FloatArray:
    # The twin draws the bent finger from it on every frame: made once, shared.
    x = np.linspace(0.0, length_m, n_grid)
    x.flags.writeable = False
    return x


def bending_stiffness_n_m2(temp_c: ArrayLike, finger: FingerParams) -> FloatArray:
    """Bending stiffness ``EI(x, T)`` on :func:`beam_grid` (N m^2).

    Parameters
    ----------
    temp_c : array_like
        Temperature (°C): a scalar or an array of shape ``(n_grid,)``.
    finger : FingerParams
        Finger constants.

    Returns
    -------
    ndarray, shape (n_grid,)
        Bending stiffness along the finger.
    """
    x = beam_grid(finger)
    t = np.broadcast_to(np.asarray(temp_c, dtype=np.float64), x.shape)
    xi = x / finger.length_m
    skeleton = finger.ei_skeleton_base_n_m2 * (1.0 - finger.skeleton_taper * xi)
    ratio = finger.smp_ratio_base + (finger.smp_ratio_tip - finger.smp_ratio_base) * xi
    e_ref = storage_modulus_pa(finger.ref_temp_c, finger.smp)
    soft = 1.0 - finger.skeleton_temp_coeff_per_k * (t - finger.ref_temp_c)
    return skeleton * (soft + ratio * storage_modulus_pa(t, finger.smp) / e_ref)


def smp_share(temp_c: ArrayLike, finger: FingerParams) -> FloatArray:
    """The SMP beams' share ``EI_smp / EI`` of the bending stiffness on :func:`beam_grid`."""
    x = beam_grid(finger)
    t = np.broadcast_to(np.asarray(temp_c, dtype=np.float64), x.shape)
    xi = x / finger.length_m
    skeleton = finger.ei_skeleton_base_n_m2 * (1.0 - finger.skeleton_taper * xi)
    ratio = finger.smp_ratio_base + (finger.smp_ratio_tip - finger.smp_ratio_base) * xi
    smp = skeleton * ratio * storage_modulus_pa(t, finger.smp) / storage_modulus_pa(
        finger.ref_temp_c, finger.smp)
    return np.asarray(smp / bending_stiffness_n_m2(t, finger), dtype=np.float64)


def _cumtrapz(y: FloatArray, x: FloatArray) -> FloatArray:
    out = np.zeros_like(y)
    out[..., 1:] = np.cumsum(0.5 * (y[..., 1:] + y[..., :-1]) * np.diff(x), axis=-1)
    return out


def unit_profile_m_per_n(
    contact_m: float, temp_c: ArrayLike, finger: FingerParams
) -> tuple[FloatArray, FloatArray]:
    """Small-deflection profile and slope per newton of load at ``contact_m``.

    Parameters
    ----------
    contact_m : float
        Contact position ``a`` along the finger (m), ``0 < a <= L``.
    temp_c : array_like
        Temperature (°C), scalar or on the grid.
    finger : FingerParams
        Finger constants.

    Returns
    -------
    z : ndarray, shape (n_grid,)
        Deflection per unit load ``z(x) / F`` on :func:`beam_grid` (m/N).
    slope : ndarray, shape (n_grid,)
        Slope per unit load ``z'(x) / F`` (rad/N).
    """
    if not (0.0 < contact_m <= finger.length_m):
        raise ValueError(f"contact position {contact_m} m is outside the finger (0, L]")
    x = beam_grid(finger)
    curvature = np.clip(contact_m - x, 0.0, None) / bending_stiffness_n_m2(temp_c, finger)
    slope = _cumtrapz(curvature, x)
    return _cumtrapz(slope, x), slope


def contact_compliance_m_per_n(contact_m: float, temp_c: ArrayLike, finger: FingerParams) -> float:
    """Linear compliance at the contact point ``c_a = z(a) / F`` (m/N)."""
    z, _ = unit_profile_m_per_n(contact_m, temp_c, finger)
    return float(np.interp(contact_m, beam_grid(finger), z))


def stiffening_factor(deflection_m: ArrayLike, finger: FingerParams) -> FloatArray:
    """Geometric stiffening ``1 + gamma (z_a / L)^2`` at a contact deflection ``z_a``."""
    z = np.asarray(deflection_m, dtype=np.float64)
    return 1.0 + finger.stiffening * (z / finger.length_m) ** 2


def contact_deflection_m(
    force_n: ArrayLike, compliance_m_per_n: float, finger: FingerParams
) -> FloatArray:
    """Deflection at the contact point under ``force_n``, with geometric stiffening.

    Solves ``F = z / c_a (1 + gamma (z / L)^2)`` for ``z``: the cubic
    ``z^3 + p z - q = 0`` with ``p = L^2 / gamma``, ``q = p c_a F`` has one
    real root, ``z = 2 sqrt(p/3) sinh(asinh(3 q / (2 p) sqrt(3/p)) / 3)``.
    Cardano's sum of cube roots gives the same root but cancels for small
    loads (8e-4 relative error at 1e-12 N); this form keeps full precision.

    Parameters
    ----------
    force_n : array_like
        Load at the contact point (N).
    compliance_m_per_n : float
        Linear compliance ``c_a`` (m/N).
    finger : FingerParams
        Finger constants.

    Returns
    -------
    ndarray
        Contact deflection (m), same shape as ``force_n``; odd in the force.
    """
    f = np.asarray(force_n, dtype=np.float64)
    linear = compliance_m_per_n * f
    if finger.stiffening == 0.0:
        return linear
    p = finger.length_m**2 / finger.stiffening
    q = p * linear
    scale = math.sqrt(p / 3.0)
    out: FloatArray = 2.0 * scale * np.sinh(np.arcsinh(1.5 * q / (p * scale)) / 3.0)
    return out


def deflection_profile_m(
    force_n: float, contact_m: float, temp_c: ArrayLike, finger: FingerParams
) -> FloatArray:
    """Deflection profile ``z(x)`` on :func:`beam_grid` under a load at ``contact_m`` (m).

    Parameters
    ----------
    force_n : float
        Normal load (N).
    contact_m : float
        Contact position ``a`` (m).
    temp_c : array_like
        Temperature (°C), scalar or on the grid.
    finger : FingerParams
        Finger constants.

    Returns
    -------
    ndarray, shape (n_grid,)
        Deflection along the finger (m).
    """
    z_unit, _ = unit_profile_m_per_n(contact_m, temp_c, finger)
    c_a = float(np.interp(contact_m, beam_grid(finger), z_unit))
    z_a = float(contact_deflection_m(force_n, c_a, finger))
    return z_unit * (z_a / c_a)


def deflection_share(along_m: ArrayLike, contact_m: float, temp_c: ArrayLike,
                     finger: FingerParams) -> FloatArray:
    """The deflection at ``along_m`` per unit of deflection at the contact.

    The shape of the bent finger, whatever the load: what a marker at
    ``along_m`` shows of the contact's deflection, or the profile a face's
    bend is fitted with.

    Parameters
    ----------
    along_m : array_like
        Positions along the finger (m from the root).
    contact_m : float
        Contact position ``a`` (m).
    temp_c : array_like
        Temperature (°C), scalar or on the grid.
    finger : FingerParams
        Finger constants.

    Returns
    -------
    ndarray
        Shaped like ``along_m``: 1 at the contact.
    """
    z, _ = unit_profile_m_per_n(contact_m, temp_c, finger)
    x = beam_grid(finger)
    out: FloatArray = np.interp(np.asarray(along_m, dtype=np.float64), x, z) / np.interp(
        contact_m, x, z)
    return out


def local_stiffness_n_per_m(
    force_n: float,
    temp_c: ArrayLike,
    finger: FingerParams,
    contact_m: float = 0.080,
    at_m: float = 0.080,
) -> float:
    """Local stiffness ``k = F / z(at)``, the paper's ``k80`` by default (N/m)."""
    z = deflection_profile_m(force_n, contact_m, temp_c, finger)
    return force_n / float(np.interp(at_m, beam_grid(finger), z))


def deflection_area_m2(
    force_n: float, temp_c: ArrayLike, finger: FingerParams, contact_m: float = 0.080
) -> float:
    """Global deformation ``A_z = int_0^L z(x) dx`` (m^2)."""
    z = deflection_profile_m(force_n, contact_m, temp_c, finger)
    return float(_cumtrapz(z, beam_grid(finger))[-1])


def finger_from_k80(finger: FingerParams, k80_n_per_m: tuple[float, float],
                    temps_c: tuple[float, float], force_n: float,
                    contact_m: float = 0.080) -> FingerParams:
    """The finger whose ``k80`` at two temperatures is the measured one.

    ``k80 = F / z(a)`` with the load ``F`` at ``a`` (the paper's 80 mm) is
    what a lab measures with a force gauge and a ruler.  Two temperatures
    fix the two parts of :func:`bending_stiffness_n_m2`: the ratio
    ``k80(T_hot) / k80(T_cold)`` depends only on the SMP share at the base
    (``smp_ratio_base``; the rest of ``finger`` keeps its shape), and the
    cold ``k80`` then scales the skeleton (``ei_skeleton_base_n_m2``).  The
    geometric stiffening is taken out of each measurement first.

    Parameters
    ----------
    finger : FingerParams
        The finger's length, taper, temperature coefficient, tip ratio,
        stiffening and SMP; its ``ei_skeleton_base_n_m2`` and
        ``smp_ratio_base`` are replaced.
    k80_n_per_m : tuple of float
        Measured ``F / z(a)`` at ``temps_c`` (N/m), > 0.
    temps_c : tuple of float
        The two uniform finger temperatures (°C), colder first.
    force_n : float
        The load of the measurement (N), > 0.
    contact_m : float
        Where the load acted and the deflection was read (m from the root).

    Returns
    -------
    FingerParams

    Raises
    ------
    ValueError
        Temperatures not rising, a stiffness that does not fall with them, or a
        fall this SMP cannot give at any share.
    """
    from scipy.optimize import brentq

    (k_cold, k_hot), (t_cold, t_hot) = k80_n_per_m, temps_c
    if not (min(k_cold, k_hot, force_n) > 0 and math.isfinite(k_cold + k_hot + force_n)):
        raise ValueError("k80 and the load must be finite and > 0")
    if not t_cold < t_hot:
        raise ValueError(f"the temperatures must rise, got {t_cold:g} and {t_hot:g} °C")

    def compliance(k_n_per_m: float) -> float:
        # F = z / c_a (1 + gamma (z / L)^2), from the measured z = F / k
        z = force_n / k_n_per_m
        return z * (1.0 + finger.stiffening * (z / finger.length_m) ** 2) / force_n

    c_cold, c_hot = compliance(k_cold), compliance(k_hot)

    def ratio(smp_ratio_base: float) -> float:
        trial = replace(finger, ei_skeleton_base_n_m2=1.0, smp_ratio_base=smp_ratio_base)
        return (contact_compliance_m_per_n(contact_m, t_hot, trial)
                / contact_compliance_m_per_n(contact_m, t_cold, trial))

    wanted, lo, hi = c_hot / c_cold, ratio(0.0), ratio(_MAX_SMP_RATIO)
    if not lo <= wanted <= hi:
        raise ValueError(
            f"k80 falls {100 * (1 - k_hot / k_cold):.1f} % from {t_cold:g} to {t_hot:g} °C; "
            f"this finger's SMP gives {100 * (1 - 1 / lo):.1f} to {100 * (1 - 1 / hi):.1f} %")
    share = float(brentq(lambda r: ratio(r) - wanted, 0.0, _MAX_SMP_RATIO, xtol=1e-12))
    unit = replace(finger, ei_skeleton_base_n_m2=1.0, smp_ratio_base=share)
    ei = contact_compliance_m_per_n(contact_m, t_cold, unit) / c_cold
    return replace(finger, ei_skeleton_base_n_m2=ei, smp_ratio_base=share)


#: Largest SMP-to-skeleton ratio :func:`finger_from_k80` considers: beyond it, the skeleton
#: carries under 0.1 % of the finger, and k80's fall is the SMP's alone.
_MAX_SMP_RATIO = 1000.0
