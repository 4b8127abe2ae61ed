"""Shape-memory polymer: storage modulus, relaxation shift factor, relaxation strength.

The SMP beams of the finger (Tg ≈ 48 °C) go from glassy to rubbery over a
few tens of kelvin.  Three temperature laws live here, all pure functions of
temperature in °C:

* :func:`storage_modulus_pa`: a smooth step from ``E_g`` to ``E_r``, steepest
  at Tg (a ``tanh`` in temperature, as DMA curves of SMPs look).
* :func:`shift_factor`: time–temperature superposition ``a_T`` with
  ``tau(T) = tau(T_g) a_T(T)``; WLF above Tg, Arrhenius below, with the
  activation energy chosen so that ``ln a_T`` and its slope are continuous at
  Tg.
* :func:`relaxation_fraction`: the share of the instantaneous stiffness held
  by the Maxwell branches (``sum k_i / (k_e + sum k_i)``), which grows through
  and above the transition, where molecular mobility sets in.

The WLF constants are those of the finger composite, calibrated to the
gripper's holding behaviour, not the universal 17.44 / 51.6 K of bulk polymers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.physics.material import Material

FloatArray = NDArray[np.float64]

GAS_CONSTANT_J_PER_MOL_K = 8.314462618
ZERO_CELSIUS_K = 273.15

__all__ = [
    "SMPMaterial",
    "SMPParams",
    "branch_shares",
    "glassy_fraction",
    "relaxation_fraction",
    "shift_factor",
    "storage_modulus_pa",
]


#: The twin's characteristic loading time (s): a grasp closes onto its object in about 1 s.
LOADING_TIME_S = 1.0


@dataclass(frozen=True)
class SMPMaterial:
    """A measured material (``fit-material``) standing in for the SMP's constants.

    Attributes
    ----------
    material : Material
        The fitted material.
    anchor_c : float
        The material's temperature that :attr:`SMPParams.tg_c` stands for: a
        batch whose Tg is ``d`` K higher behaves as the material at ``T - d``.
    loading_time_s : float
        Loading time at which the modulus counts as instantaneous (s).
    """

    material: Material
    anchor_c: float
    loading_time_s: float = LOADING_TIME_S

    def modulus_pa(self, temp_c: ArrayLike) -> FloatArray:
        """``E(t_load, T)`` (Pa)."""
        return self.material.relaxation_modulus_pa(self.loading_time_s, temp_c)


@dataclass(frozen=True)
class SMPParams:
    """Material constants of the finger's shape-memory polymer.

    Attributes
    ----------
    tg_c : float
        Glass-transition temperature (°C).
    e_glassy_pa, e_rubbery_pa : float
        Storage modulus well below / well above Tg (Pa).
    transition_width_k : float
        Width of the glass transition (K): the modulus step is
        ``0.5 (1 - tanh((T - Tg) / width))``.
    wlf_c1, wlf_c2_k : float
        WLF constants above Tg: ``log10 a_T = -C1 (T - Tg) / (C2 + T - Tg)``.
    relax_fraction_glassy, relax_fraction_rubbery : float
        Relaxing share of the instantaneous stiffness far below / far above
        the relaxation onset.
    relax_onset_c, relax_onset_width_k : float
        Centre and width of the rise of the relaxing share (°C, K).
    """

    tg_c: float = 48.0
    e_glassy_pa: float = 1.2e9
    e_rubbery_pa: float = 12e6
    transition_width_k: float = 7.0
    wlf_c1: float = 1.5
    wlf_c2_k: float = 40.0
    relax_fraction_glassy: float = 0.32
    relax_fraction_rubbery: float = 0.66
    relax_onset_c: float = 60.0
    relax_onset_width_k: float = 4.0
    material: SMPMaterial | None = None

    @classmethod
    def from_material(cls, material: Material, loading_time_s: float = LOADING_TIME_S
                      ) -> SMPParams:
        """The SMP of a measured material.

        ``tg_c`` is the temperature, within the measured range, where
        ``E(t_load, T)`` falls fastest (the transition the twin's scatter of
        a batch's Tg moves); the glassy and rubbery moduli are
        ``E(t_load, T)`` at the ends of the measured range.
        """
        lo, hi = material.temp_range_c
        temps = np.linspace(lo, hi, 601)
        log_e = np.log(material.relaxation_modulus_pa(loading_time_s, temps))
        anchor = float(temps[int(np.argmin(np.gradient(log_e, temps)))])
        e_g = float(np.exp(log_e.max()))
        e_r = min(float(np.exp(log_e.min())), 0.999 * e_g)
        return cls(tg_c=anchor, e_glassy_pa=e_g, e_rubbery_pa=e_r,
                   material=SMPMaterial(material, anchor, loading_time_s))

    def __post_init__(self) -> None:
        if not (self.e_glassy_pa > self.e_rubbery_pa > 0):
            raise ValueError("need e_glassy_pa > e_rubbery_pa > 0")
        if self.transition_width_k <= 0 or self.relax_onset_width_k <= 0:
            raise ValueError("transition widths must be > 0")
        if self.wlf_c1 <= 0 or self.wlf_c2_k <= 0:
            raise ValueError("WLF constants must be > 0")
        if not (0 <= self.relax_fraction_glassy <= self.relax_fraction_rubbery < 1):
            raise ValueError("need 0 <= relax_fraction_glassy <= relax_fraction_rubbery < 1")

    @property
    def activation_energy_j_per_mol(self) -> float:
        """Arrhenius activation energy below Tg (J/mol).

        Chosen so that ``d ln a_T / dT`` is continuous at Tg:
        ``E_a = R Tg^2 C1 ln(10) / C2``.
        """
        tg_k = self.tg_c + ZERO_CELSIUS_K
        return GAS_CONSTANT_J_PER_MOL_K * tg_k**2 * self.wlf_c1 * math.log(10.0) / self.wlf_c2_k


def glassy_fraction(temp_c: ArrayLike, params: SMPParams) -> FloatArray:
    """Return the glassy share ``s(T) = 0.5 (1 - tanh((T - Tg) / w))`` in [0, 1].

    Parameters
    ----------
    temp_c : array_like
        Temperature (°C).
    params : SMPParams
        Material constants.

    Returns
    -------
    ndarray
        1 far below Tg, 0 far above, 0.5 at Tg; same shape as ``temp_c``.
    """
    t = np.asarray(temp_c, dtype=np.float64)
    return 0.5 * (1.0 - np.tanh((t - params.tg_c) / params.transition_width_k))


def storage_modulus_pa(temp_c: ArrayLike, params: SMPParams) -> FloatArray:
    """Storage modulus ``E'(T)`` of the SMP (Pa).

    ``E'(T) = E_r + (E_g - E_r) s(T)``, so ``|dE'/dT|`` peaks exactly at Tg.

    Parameters
    ----------
    temp_c : array_like
        Temperature (°C).
    params : SMPParams
        Material constants.

    Returns
    -------
    ndarray
        Modulus (Pa), same shape as ``temp_c``.
    """
    if params.material is not None:
        return params.material.modulus_pa(_material_temp(temp_c, params))
    s = glassy_fraction(temp_c, params)
    return params.e_rubbery_pa + (params.e_glassy_pa - params.e_rubbery_pa) * s


def shift_factor(temp_c: ArrayLike, params: SMPParams) -> FloatArray:
    """Time–temperature shift factor ``a_T`` referenced to Tg.

    Relaxation times scale as ``tau(T) = tau(Tg) a_T(T)``.  Above Tg the WLF
    law holds, below it an Arrhenius law whose activation energy makes
    ``ln a_T`` continuous with a continuous slope at Tg.

    Parameters
    ----------
    temp_c : array_like
        Temperature (°C); must be above ``Tg - C2`` (the WLF pole) and above
        absolute zero.
    params : SMPParams
        Material constants.

    Returns
    -------
    ndarray
        ``a_T`` (dimensionless, > 0), same shape as ``temp_c``; 1 at Tg,
        > 1 below (slower), < 1 above (faster).
    """
    t = np.asarray(temp_c, dtype=np.float64)
    if np.any(t <= -ZERO_CELSIUS_K):
        raise ValueError("temperature must be above absolute zero")
    if params.material is not None:  # relative to the material's reference temperature
        return np.asarray(10.0 ** params.material.material.shift.log10_at(
            _material_temp(t, params)), dtype=np.float64)
    dt = t - params.tg_c
    above = dt >= 0
    wlf = -params.wlf_c1 * np.log(10.0) * dt / (params.wlf_c2_k + np.where(above, dt, 0.0))
    tg_k = params.tg_c + ZERO_CELSIUS_K
    arrhenius = (
        params.activation_energy_j_per_mol
        / GAS_CONSTANT_J_PER_MOL_K
        * (1.0 / (t + ZERO_CELSIUS_K) - 1.0 / tg_k)
    )
    return np.exp(np.where(above, wlf, arrhenius))


def relaxation_fraction(temp_c: ArrayLike, params: SMPParams) -> FloatArray:
    """Share of the instantaneous stiffness carried by the Maxwell branches.

    ``g(T) = g_glassy + (g_rubbery - g_glassy) sigmoid((T - T_on) / w_on)``:
    relaxation is modest in the glassy state and grows above the transition.

    Parameters
    ----------
    temp_c : array_like
        Temperature (°C).
    params : SMPParams
        Material constants.

    Returns
    -------
    ndarray
        ``sum k_i / k_inst`` in [0, 1), same shape as ``temp_c``.
    """
    if params.material is not None:
        return np.asarray(np.sum(branch_shares(temp_c, params), axis=-1), dtype=np.float64)
    t = np.asarray(temp_c, dtype=np.float64)
    z = (t - params.relax_onset_c) / params.relax_onset_width_k
    rise = 0.5 * (1.0 + np.tanh(0.5 * z))
    lo, hi = params.relax_fraction_glassy, params.relax_fraction_rubbery
    return lo + (hi - lo) * rise


def _material_temp(temp_c: ArrayLike, params: SMPParams) -> FloatArray:
    """The material's temperature for this batch: shifted by its Tg's offset from the anchor."""
    assert params.material is not None
    return np.asarray(temp_c, dtype=np.float64) - (params.tg_c - params.material.anchor_c)


def branch_shares(temp_c: ArrayLike, params: SMPParams) -> FloatArray:
    """Each Prony term's share of the SMP's modulus at the loading time (measured material).

    ``w_i(T) = E_i exp(-t_load / (tau_i a_T)) / E(t_load, T)``: the part of
    the loaded modulus that relaxes through term ``i`` after loading; terms
    much faster than the loading have relaxed already and carry nothing.

    Returns
    -------
    ndarray, shape ``temp_c.shape + (n_terms,)``
        Shares in [0, 1), summing to the SMP's relaxing share.

    Raises
    ------
    ValueError
        ``params`` carries no material.
    """
    if params.material is None:
        raise ValueError("branch_shares needs an SMP made from a material")
    sm = params.material
    t = _material_temp(temp_c, params)
    log_at = sm.material.shift.log10_at(t)
    reduced = sm.loading_time_s * 10.0 ** (-np.asarray(log_at))
    part = np.exp(-reduced[..., None] / np.asarray(sm.material.tau_s)) * np.asarray(
        sm.material.moduli_pa)
    total = sm.material.e_inf_pa + part.sum(axis=-1)
    return np.asarray(part / total[..., None], dtype=np.float64)
