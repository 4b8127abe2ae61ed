"""A thermorheologically simple viscoelastic material: shift law and Prony series.

Time–temperature superposition says that at temperature ``T`` the material
relaxes as it does at the reference temperature ``T_r`` with every time
stretched by the shift factor ``a_T(T)`` (``a_T(T_r) = 1``).  The modulus is a
Prony series in reduced time ``t / a_T``::

    E(t, T)   = E_inf + sum_i E_i exp(-t / (tau_i a_T))
    E'(w, T)  = E_inf + sum_i E_i (w tau_i a_T)^2 / (1 + (w tau_i a_T)^2)
    E''(w, T) =         sum_i E_i (w tau_i a_T)   / (1 + (w tau_i a_T)^2)

with ``w`` the angular frequency (rad/s) and ``tau_i`` the relaxation times at
``T_r``.  The shift laws (:class:`ShiftLaw`, all as ``log10 a_T``):

* ``wlf``:  ``-C1 (T - T_r) / (C2 + T - T_r)`` (Williams–Landel–Ferry);
* ``arrhenius``: ``E_a / (R ln 10) (1/T - 1/T_r)``, temperatures in K;
* ``two_regime``: Arrhenius below a fitted ``T_g`` and WLF referenced at
  ``T_g`` above it, continuous at ``T_g`` (the form the twin's SMP uses,
  :func:`relaxgrip.physics.smp.shift_factor`), then referenced to ``T_r``;
* ``poly``: ``sum_k c_k (T - T_r)^k``, k = 1..4 (the empirical form some DMA
  software fits; kept for comparison).

:class:`Material` bundles both with what was measured (tensile ``E`` or shear
``G``, the measured temperature range) and where it came from (provenance),
and round-trips through JSON (:meth:`Material.to_dict` /
:meth:`Material.from_dict`, schema ``relaxgrip-material`` version
:data:`MATERIAL_SCHEMA_VERSION`).  Everything is SI: Pa, s, rad/s, °C.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from relaxgrip.errors import InputError

FloatArray = NDArray[np.float64]

__all__ = [
    "MATERIAL_SCHEMA",
    "MATERIAL_SCHEMA_VERSION",
    "SHIFT_MODELS",
    "SHIFT_PARAMS",
    "Material",
    "ShiftLaw",
    "log10_shift",
]

MATERIAL_SCHEMA = "relaxgrip-material"
MATERIAL_SCHEMA_VERSION = 1
GAS_CONSTANT_J_PER_MOL_K = 8.314462618
ZERO_CELSIUS_K = 273.15
_LN10 = math.log(10.0)

#: The shift laws and the names of their parameters, in the order fits use.
SHIFT_PARAMS: dict[str, tuple[str, ...]] = {
    "wlf": ("c1", "c2_k"),
    "arrhenius": ("ea_j_per_mol",),
    "two_regime": ("c1", "c2_k", "tg_c", "ea_j_per_mol"),
    "poly": ("c1", "c2", "c3", "c4"),
}
SHIFT_MODELS: tuple[str, ...] = tuple(SHIFT_PARAMS)


def _wlf(dt: FloatArray, c1: float, c2_k: float) -> FloatArray:
    den = c2_k + dt
    if np.any(den <= 0):
        raise ValueError(f"WLF law undefined at or below its pole (C2 = {c2_k:.4g} K below "
                         "the reference)")
    return -c1 * dt / den


def _arrhenius(temp_c: FloatArray, ref_c: float, ea: float) -> FloatArray:
    return ea / (GAS_CONSTANT_J_PER_MOL_K * _LN10) * (
        1.0 / (temp_c + ZERO_CELSIUS_K) - 1.0 / (ref_c + ZERO_CELSIUS_K))


def log10_shift(model: str, params: ArrayLike, temp_c: ArrayLike, ref_temp_c: float) -> FloatArray:
    """``log10 a_T`` of a shift law at ``temp_c``, referenced to ``ref_temp_c``.

    Parameters
    ----------
    model : str
        One of :data:`SHIFT_MODELS`.
    params : array_like
        The law's parameters in the order of :data:`SHIFT_PARAMS` (°C, K, J/mol).
    temp_c : array_like
        Temperatures (°C), above absolute zero.
    ref_temp_c : float
        Reference temperature (°C), where ``log10 a_T = 0``.

    Returns
    -------
    ndarray
        ``log10 a_T`` (dimensionless), the shape of ``temp_c``; positive below
        the reference (slower), negative above.

    Raises
    ------
    ValueError
        An unknown model, the wrong number of parameters, a temperature at or
        below absolute zero, or one at or below a WLF pole.
    """
    if model not in SHIFT_PARAMS:
        raise ValueError(f"unknown shift model {model!r}, "
                         f"expected one of {', '.join(SHIFT_MODELS)}")
    p = np.asarray(params, dtype=np.float64).ravel()
    if p.size != len(SHIFT_PARAMS[model]):
        raise ValueError(f"{model} takes {len(SHIFT_PARAMS[model])} parameters, got {p.size}")
    t = np.asarray(temp_c, dtype=np.float64)
    if np.any(t <= -ZERO_CELSIUS_K):
        raise ValueError("temperature must be above absolute zero")
    dt = t - ref_temp_c
    if model == "wlf":
        return _wlf(dt, float(p[0]), float(p[1]))
    if model == "arrhenius":
        return _arrhenius(t, ref_temp_c, float(p[0]))
    if model == "poly":
        return np.asarray(dt * (p[0] + dt * (p[1] + dt * (p[2] + dt * p[3]))), dtype=np.float64)
    c1, c2, tg, ea = (float(v) for v in p)

    def branch(temp: FloatArray) -> FloatArray:
        above = temp >= tg
        wlf = _wlf(np.where(above, temp - tg, 0.0), c1, c2)
        arr = _arrhenius(np.where(above, tg, temp), tg, ea)
        return np.where(above, wlf, arr)

    return np.asarray(branch(t) - branch(np.asarray(ref_temp_c)), dtype=np.float64)


@dataclass(frozen=True)
class ShiftLaw:
    """A time–temperature shift law ``log10 a_T(T)``.

    Attributes
    ----------
    model : str
        One of :data:`SHIFT_MODELS`.
    params : tuple of float
        Its parameters in the order of :data:`SHIFT_PARAMS`.
    ref_temp_c : float
        Reference temperature (°C): ``a_T(ref_temp_c) = 1``.
    """

    model: str
    params: tuple[float, ...]
    ref_temp_c: float

    def __post_init__(self) -> None:
        if self.model not in SHIFT_PARAMS:
            raise ValueError(f"unknown shift model {self.model!r}, "
                             f"expected one of {', '.join(SHIFT_MODELS)}")
        if len(self.params) != len(SHIFT_PARAMS[self.model]):
            raise ValueError(f"{self.model} takes {len(SHIFT_PARAMS[self.model])} parameters, "
                             f"got {len(self.params)}")
        if not all(math.isfinite(v) for v in (*self.params, self.ref_temp_c)):
            raise ValueError("shift parameters must be finite")

    @property
    def named_params(self) -> dict[str, float]:
        """The parameters by name."""
        return dict(zip(SHIFT_PARAMS[self.model], self.params, strict=True))

    def log10_at(self, temp_c: ArrayLike) -> FloatArray:
        """``log10 a_T`` at ``temp_c`` (°C); see :func:`log10_shift`."""
        return log10_shift(self.model, self.params, temp_c, self.ref_temp_c)


@dataclass(frozen=True)
class Material:
    """A viscoelastic material: Prony series at a reference temperature and its shift law.

    Attributes
    ----------
    modulus : str
        ``"E"`` (tensile) or ``"G"`` (shear): what was measured.
    e_inf_pa : float
        Equilibrium modulus ``E_inf`` (Pa), ``>= 0``.
    moduli_pa : tuple of float
        Prony moduli ``E_i`` (Pa), each ``> 0``.
    tau_s : tuple of float
        Relaxation times ``tau_i`` at the reference temperature (s), each ``> 0``.
    shift : ShiftLaw
        ``a_T(T)``; its reference temperature is the material's.
    temp_range_c : tuple of float
        Lowest and highest measured temperature (°C): where the material is known.
    provenance_json : str
        Where the material came from (the fit's inputs, settings and scores),
        as a JSON object text (kept as text so that the material is hashable).
    """

    modulus: str
    e_inf_pa: float
    moduli_pa: tuple[float, ...]
    tau_s: tuple[float, ...]
    shift: ShiftLaw
    temp_range_c: tuple[float, float]
    provenance_json: str = field(default="{}")

    def __post_init__(self) -> None:
        if self.modulus not in ("E", "G"):
            raise ValueError(f"modulus must be 'E' or 'G', got {self.modulus!r}")
        if len(self.moduli_pa) != len(self.tau_s) or not self.tau_s:
            raise ValueError("moduli_pa and tau_s need the same, non-zero length")
        if not (math.isfinite(self.e_inf_pa) and self.e_inf_pa >= 0):
            raise ValueError(f"e_inf_pa must be finite and >= 0, got {self.e_inf_pa}")
        if not all(math.isfinite(v) and v > 0 for v in (*self.moduli_pa, *self.tau_s)):
            raise ValueError("Prony moduli and relaxation times must be finite and > 0")
        lo, hi = self.temp_range_c
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise ValueError(f"temp_range_c must be finite and ordered, got {self.temp_range_c}")
        if not isinstance(json.loads(self.provenance_json), dict):
            raise ValueError("provenance_json must hold a JSON object")

    @property
    def ref_temp_c(self) -> float:
        """Reference temperature of the Prony series (°C)."""
        return self.shift.ref_temp_c

    @property
    def e_instant_pa(self) -> float:
        """Instantaneous (glassy) modulus ``E_inf + sum E_i`` (Pa)."""
        return self.e_inf_pa + float(sum(self.moduli_pa))

    @property
    def provenance(self) -> dict[str, Any]:
        """The provenance as a dict."""
        out: dict[str, Any] = json.loads(self.provenance_json)
        return out

    def taus_at(self, temp_c: float) -> FloatArray:
        """Relaxation times at ``temp_c``: ``tau_i a_T(T)`` (s)."""
        return np.asarray(np.asarray(self.tau_s) * 10.0 ** float(self.shift.log10_at(temp_c)),
                          dtype=np.float64)

    def _reduced(self, x: ArrayLike, temp_c: ArrayLike) -> tuple[FloatArray, FloatArray]:
        x_arr = np.asarray(x, dtype=np.float64)
        log_at = self.shift.log10_at(temp_c)
        x_b, log_b = np.broadcast_arrays(x_arr, log_at)
        return x_b, np.asarray(log_b, dtype=np.float64)

    def relaxation_modulus_pa(self, t_s: ArrayLike, temp_c: ArrayLike) -> FloatArray:
        """``E(t, T)`` (Pa) at times ``t_s`` (s) and temperatures ``temp_c`` (°C), broadcast."""
        t, log_at = self._reduced(t_s, temp_c)
        reduced = t * 10.0 ** (-log_at)
        decay = np.exp(-reduced[..., None] / np.asarray(self.tau_s)) @ np.asarray(self.moduli_pa)
        return np.asarray(self.e_inf_pa + decay, dtype=np.float64)

    def storage_modulus_pa(self, omega_rad_s: ArrayLike, temp_c: ArrayLike) -> FloatArray:
        """``E'(w, T)`` (Pa) at angular frequencies ``omega_rad_s`` and ``temp_c``, broadcast."""
        w, log_at = self._reduced(omega_rad_s, temp_c)
        wt = (w * 10.0 ** log_at)[..., None] * np.asarray(self.tau_s)
        part = wt * wt / (1.0 + wt * wt)
        return np.asarray(self.e_inf_pa + part @ np.asarray(self.moduli_pa), dtype=np.float64)

    def loss_modulus_pa(self, omega_rad_s: ArrayLike, temp_c: ArrayLike) -> FloatArray:
        """``E''(w, T)`` (Pa) at angular frequencies ``omega_rad_s`` and ``temp_c``, broadcast."""
        w, log_at = self._reduced(omega_rad_s, temp_c)
        wt = (w * 10.0 ** log_at)[..., None] * np.asarray(self.tau_s)
        return np.asarray((wt / (1.0 + wt * wt)) @ np.asarray(self.moduli_pa), dtype=np.float64)

    def to_dict(self) -> dict[str, Any]:
        """The material file's JSON object (schema :data:`MATERIAL_SCHEMA`)."""
        return {
            "schema": MATERIAL_SCHEMA,
            "schema_version": MATERIAL_SCHEMA_VERSION,
            "modulus": self.modulus,
            "ref_temp_c": self.ref_temp_c,
            "temp_range_c": list(self.temp_range_c),
            "shift": {"model": self.shift.model, "params": self.shift.named_params},
            "prony": {
                "e_inf_pa": self.e_inf_pa,
                "terms": [{"modulus_pa": e, "tau_s": t}
                          for e, t in zip(self.moduli_pa, self.tau_s, strict=True)],
            },
            "provenance": self.provenance,
        }

    @classmethod
    def from_dict(cls, data: Any, source: str = "material file") -> Material:
        """Read a material file's JSON object, checked.

        Parameters
        ----------
        data : Any
            The parsed JSON.
        source : str
            What to call it in an error (the file's name).

        Raises
        ------
        relaxgrip.errors.InputError
            One line naming ``source`` and the problem: not a material file, a
            newer schema version, a missing or malformed field, an unknown
            shift model, a non-positive modulus or time.
        """
        def fail(msg: str) -> InputError:
            return InputError(f"{source}: {msg}")

        if not isinstance(data, dict) or data.get("schema") != MATERIAL_SCHEMA:
            raise fail(f"not a material file (expected \"schema\": \"{MATERIAL_SCHEMA}\")")
        version = data.get("schema_version")
        if isinstance(version, bool) or not isinstance(version, int) or version < 1:
            raise fail(f"bad schema_version {version!r}")
        if version > MATERIAL_SCHEMA_VERSION:
            raise fail(f"schema_version {version} is newer than this relaxgrip reads "
                       f"({MATERIAL_SCHEMA_VERSION}); update relaxgrip")
        try:
            shift = data["shift"]
            model = shift["model"]
            if model not in SHIFT_PARAMS:
                raise fail(f"unknown shift model {model!r}, expected one of "
                           f"{', '.join(SHIFT_MODELS)}")
            named = shift["params"]
            params = tuple(_number(named[k], f"shift.params.{k}", fail)
                           for k in SHIFT_PARAMS[model])
            ref = _number(data["ref_temp_c"], "ref_temp_c", fail)
            prony = data["prony"]
            terms = prony["terms"]
            if not isinstance(terms, list) or not terms:
                raise fail("prony.terms must be a non-empty list")
            moduli = tuple(_number(t["modulus_pa"], f"prony.terms[{i}].modulus_pa", fail)
                           for i, t in enumerate(terms))
            taus = tuple(_number(t["tau_s"], f"prony.terms[{i}].tau_s", fail)
                         for i, t in enumerate(terms))
            e_inf = _number(prony["e_inf_pa"], "prony.e_inf_pa", fail)
            lo, hi = (_number(v, "temp_range_c", fail) for v in data["temp_range_c"])
            provenance = data.get("provenance", {})
            if not isinstance(provenance, dict):
                raise fail("provenance must be an object")
            return cls(modulus=data["modulus"], e_inf_pa=e_inf, moduli_pa=moduli, tau_s=taus,
                       shift=ShiftLaw(model, params, ref), temp_range_c=(lo, hi),
                       provenance_json=json.dumps(provenance, sort_keys=True))
        except KeyError as exc:
            raise fail(f"missing field {exc.args[0]!r}") from None
        except (TypeError, ValueError) as exc:
            if isinstance(exc, InputError):
                raise
            raise fail(str(exc)) from None


def _number(value: Any, name: str, fail: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise fail(f"{name} must be a finite number, got {value!r}")
    return float(value)
