"""The viscoelastic observer's parameters: identified from RCFN holds, saved without pickle.

The observer (:class:`relaxgrip.control.observer.ObserverEstimator`) treats the
finger that carries the marker as a generalized Maxwell element (Eqs. 1–2)
driven by the deflection the marker measures, ``d(t)`` (its ``dx``, m)::

    F(t) = k(T) [ g_e(T) d(t) + sum_i F_i(t) ]
    tau_i(T) dF_i/dt + F_i = g_i(T) tau_i(T) dd/dt,   tau_i(T) = tau_ref_i a_T(T)

``k(T)`` is the instantaneous stiffness per metre of marker deflection
relative to the reference temperature, ``g_e + sum g_i = 1`` the split of it
between the equilibrium spring and the branches, ``a_T`` the shift factor
(reduced time).  All three are tables over temperature knots, interpolated
linearly (the shift factor in ``ln a_T``).  The absolute scale (N per metre)
is not a parameter: the observer takes it from the ICFN at the hold onset.

Identification (:meth:`ObserverModel.fit`) on a dataset's RCFN holds (fixed
aperture after a loading at a known closing speed):

1. The relaxation times at the reference temperature: a ``n_terms`` Prony
   series (:func:`relaxgrip.physics.fitting.fit_prony`) fitted to the mean
   normalised force curve of the sequences nearest the reference temperature.
2. Per temperature group (sequences of one set temperature; a sequence
   without one, as recordings whose plan set no heater temperature give,
   joins the group of its measured temperature, :func:`_group_keys`): for each
   candidate shift ``ln a_T`` the branch responses ``h_i(t)`` to the
   sequence's deflection history (a ramp from contact to the onset
   deflection over the loading time, then the marker's measured deflection
   during the hold) are integrated with the exact recursion
   (:func:`relaxgrip.physics.viscoelastic.branch_update`); the force is
   linear in ``k g_e`` and ``k g_i`` given them, solved by non-negative least
   squares per sequence.  The shift minimising the group's normalised squared
   error wins; the shares are the group's mean.
3. ``k(T)``: ``ln k`` of every sequence regressed on temperature-group and
   set-up (object, contact location) indicators.
4. The 95 % band: the observer run on the held-out (validation and test)
   sequences, its force scaled by the ICFN's onset estimate as in closed loop;
   the 95th percentile of ``|estimate - truth| / F_onset`` per hold-time bin.
   And the spread of the relaxing share between runs (the relative SD of
   each sequence's total branch share within its temperature group; groups
   of fewer than three holds take the spread pooled over all groups): the
   observer fits the run's share where Eq. 10 holds, and relaxation elsewhere
   carries that spread (:meth:`ObserverModel.band_drift_rel`).
   ``relaxgrip calibrate-band`` then scales the band on closed-loop holds.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from statistics import NormalDist
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

import relaxgrip
from relaxgrip.errors import InputError
from relaxgrip.fileio import (
    check_output_dir,
    file_entry,
    made_directory,
    npz_bytes,
    one_line,
    read_manifest,
    read_npz_entry,
    write_files_atomically,
)
from relaxgrip.learning.datastore import Dataset
from relaxgrip.learning.icfn import ICFN
from relaxgrip.perception.features import ICFN_SCHEMA
from relaxgrip.physics.fitting import UnidentifiableError, fit_prony
from relaxgrip.physics.viscoelastic import branch_update
from relaxgrip.validate import check_finite, check_positive

FloatArray = NDArray[np.float64]

__all__ = [
    "LOADING_SPEED_MM_S",
    "OBSERVER_FORMAT",
    "OBSERVER_VERSION",
    "ObserverModel",
    "band_factors",
    "branch_responses",
    "check_temp_factors",
    "default_observer_dir",
    "load_default_observer",
    "load_observer",
    "save_observer",
    "set_band_scale",
]

#: Closing speed of the twin datasets' RCFN loadings (``relaxgrip.learning.datasets``, mm/s).
LOADING_SPEED_MM_S = 2.0
OBSERVER_FORMAT = "relaxgrip-observer"
OBSERVER_VERSION = 1
OBSERVER_FILE = "observer.npz"
MANIFEST_NAME = "manifest.json"
#: Hold-time bins of the band (s).
_BAND_BIN_S = 20.0
#: Resampling interval of the force curves for identification (s).
_FIT_DT_S = 1.0
#: Steps of the loading ramp (the recursion is exact for a linear ramp; a few suffice).
_RAMP_STEPS = 4
#: Longest hold, and loading before it, identified (s): each hold is resampled every
#: ``_FIT_DT_S`` and integrated step by step for every candidate shift, so its cost grows
#: with its length.  The datasets' holds last at most an hour, their loadings seconds: a
#: day is generous, and a time far beyond it is a damaged table, not a long hold.
_MAX_HOLD_S = 86400.0
#: Search window of a group's ``ln a_T`` below / above the next colder group's.
_MAX_SHIFT_DROP = 3.0
_SHIFT_SLACK = 0.1
_ARRAYS = ("temps_c_", "tau_ref_s_", "log_shift_", "branch_share_", "log_stiffness_",
           "band_t_s_", "band_rel_")


def branch_responses(t_s: FloatArray, d_m: FloatArray, tau_s: FloatArray) -> FloatArray:
    """Unit-stiffness Maxwell branch forces along a deflection history (Eq. 2, exact).

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Non-decreasing times (s).
    d_m : ndarray, shape (n,)
        Deflection at ``t_s`` (m), linear in between; the history starts
        at rest (every branch at zero before ``t_s[0]``, deflection jumps to
        ``d_m[0]`` at once).
    tau_s : ndarray, shape (..., N)
        Relaxation times (s); leading axes are candidates evaluated together.

    Returns
    -------
    ndarray, shape (n, ..., N)
        Branch forces per unit branch stiffness (m).
    """
    tau = np.asarray(tau_s, dtype=np.float64)
    out = np.empty((t_s.size, *tau.shape))
    f, _ = branch_update(np.zeros(tau.shape), float(d_m[0]), 0.0, np.ones(tau.shape), tau)
    out[0] = f
    for k in range(1, t_s.size):
        f, _ = branch_update(f, float(d_m[k] - d_m[k - 1]), float(t_s[k] - t_s[k - 1]),
                             np.ones(tau.shape), tau)
        out[k] = f
    return out


@dataclass(frozen=True)
class _Hold:
    """One RCFN sequence prepared for identification."""

    sequence: int
    group: float  # the temperature group's key (:func:`_group_keys`)
    temp_c: float
    setup: str
    split: str
    f0_n: float
    t_s: FloatArray  # loading ramp (negative times) then the hold
    d_m: FloatArray
    f_n: FloatArray  # force at the hold's times (t >= 0)
    onset_x: FloatArray | None  # ICFN features at the onset


class ObserverModel:
    """Temperature-dependent Prony parameters of the observer, identified from RCFN holds.

    Parameters
    ----------
    n_terms : int
        Maxwell branches.
    loading_speed_mm_s : float
        Closing speed of the dataset's loadings before each hold (mm/s): with
        the closure ratio it gives each loading's duration.
    band_level : float
        Coverage the band is computed for (0.95: the 95 % band).
    band_scale : float
        Factor on the band's half-width from the held-out residuals (a
        recalibration; 1: as identified).
    drift_scale : float
        Factor on the band's part from the relaxing share's spread
        (:meth:`band_drift_rel`; a recalibration, 1: as identified).  Files
        written before the two parts had scales of their own take
        ``band_scale``, as both parts had then.
    band_floor_n : float
        Half-width in newtons added to the relative parts (a recalibration;
        0: as identified, and files written before the band had one).  The
        ICFN's onset error is partly absolute: a band that is only a share
        of the force is too narrow at small forces.
    band_temps_c, band_temp_factors : sequence of float
        Factors on the relative parts of the band at finger temperatures
        (°C, ascending), interpolated between them and held beyond (a
        recalibration; none: 1 at every temperature, as identified and in
        files written before the band had them).  The relative parts are
        calibrated where most holds are, at 40 °C; hotter, the relaxing
        share that the hold's error follows scatters more.
    """

    def __init__(self, n_terms: int = 3, loading_speed_mm_s: float = LOADING_SPEED_MM_S,
                 band_level: float = 0.95, band_scale: float = 1.0,
                 drift_scale: float = 1.0, band_floor_n: float = 0.0,
                 band_temps_c: Sequence[float] = (),
                 band_temp_factors: Sequence[float] = ()) -> None:
        self.n_terms = n_terms
        self.loading_speed_mm_s = loading_speed_mm_s
        self.band_level = band_level
        self.band_scale = band_scale
        self.drift_scale = drift_scale
        self.band_floor_n = band_floor_n
        self.band_temps_c = tuple(band_temps_c)
        self.band_temp_factors = tuple(band_temp_factors)
        #: The directory it was loaded from and its file's sha256 (None: built in memory).
        self.source: tuple[Path, str] | None = None

    def provenance(self) -> dict[str, Any]:
        """What a recording says of this observer: where it was loaded from, its file's
        sha256 (both None for one built in memory) and its band's scales and floor."""
        directory, sha256 = (None, None) if self.source is None else self.source
        return {"directory": None if directory is None else str(directory), "sha256": sha256,
                "band_scale": self.band_scale, "drift_scale": self.drift_scale,
                "band_floor_n": self.band_floor_n, "band_temps_c": list(self.band_temps_c),
                "band_temp_factors": list(self.band_temp_factors)}

    def get_params(self) -> dict[str, Any]:
        """Hyperparameters (scikit-learn style)."""
        return {"n_terms": self.n_terms, "loading_speed_mm_s": self.loading_speed_mm_s,
                "band_level": self.band_level, "band_scale": self.band_scale,
                "drift_scale": self.drift_scale, "band_floor_n": self.band_floor_n,
                "band_temps_c": list(self.band_temps_c),
                "band_temp_factors": list(self.band_temp_factors)}

    # -- evaluation ---------------------------------------------------------------------

    def _check_fitted(self) -> None:
        if not hasattr(self, "tau_ref_s_"):
            raise ValueError("the observer model is not fitted")

    def parameters(self, temp_c: float) -> tuple[float, FloatArray, FloatArray]:
        """Equilibrium and branch stiffnesses (relative) and relaxation times at ``temp_c``.

        Parameters
        ----------
        temp_c : float
            Finger temperature (°C); outside the identified range the nearest
            knot's parameters hold.

        Returns
        -------
        k_e : float
            ``k(T) g_e(T)`` (per unit of the reference stiffness).
        k_i : ndarray, shape (N,)
            ``k(T) g_i(T)``.
        tau_s : ndarray, shape (N,)
            ``tau_ref_i a_T(T)`` (s).
        """
        self._check_fitted()
        temps = self.temps_c_
        k = math.exp(float(np.interp(temp_c, temps, self.log_stiffness_)))
        shares = np.array([np.interp(temp_c, temps, self.branch_share_[:, i])
                           for i in range(self.branch_share_.shape[1])])
        shift = math.exp(float(np.interp(temp_c, temps, self.log_shift_)))
        return k * (1.0 - float(shares.sum())), k * shares, self.tau_ref_s_ * shift

    def band_drift_rel(self, temp_c: float) -> float:
        """Band half-width per newton of relaxation the share fit did not see, at ``temp_c``.

        The run's relaxing share scatters around the population's by
        ``share_spread_`` (relative SD between the dataset's holds of one
        temperature); the observer identifies it where Eq. 10 holds, and the
        relaxation that follows elsewhere (another temperature, a new
        displacement) carries that scatter.  ``drift_scale`` applies.
        """
        self._check_fitted()
        z = NormalDist().inv_cdf(0.5 + 0.5 * self.band_level)  # per frame: not scipy's 46 µs
        return self.drift_scale * z * float(np.interp(temp_c, self.temps_c_, self.share_spread_))

    def band_factor(self, temp_c: float) -> float:
        """The factor on the band's relative parts at finger temperature ``temp_c`` (°C):
        ``band_temp_factors`` interpolated, held beyond the ends; 1 without them or
        without a temperature read (the band as calibrated where most holds were)."""
        return float(band_factors(self.band_temps_c, self.band_temp_factors, temp_c))

    def band_rel(self, hold_s: float, temp_c: float) -> float:
        """Half-width of the band's relative part per newton of onset force, ``hold_s`` into
        the hold with the fingers at ``temp_c`` (°C)."""
        self._check_fitted()
        return (self.band_scale * self.band_factor(temp_c)
                * float(np.interp(hold_s, self.band_t_s_, self.band_rel_)))

    def band_half_n(self, hold_s: float, f_onset_n: float, temp_c: float) -> float:
        """Half-width of the band without the share's drift, ``hold_s`` into a hold whose
        onset force is ``f_onset_n`` (N), at ``temp_c`` (°C): the floor and the relative
        part."""
        return self.band_floor_n + self.band_rel(hold_s, temp_c) * f_onset_n

    def closing_half_n(self, force_n: float, temp_c: float) -> float:
        """Half-width of the band before the hold, on an ICFN estimate of ``force_n`` (N) at
        ``temp_c`` (°C): the floor and the ICFN's onset error."""
        return (self.band_floor_n
                + self.onset_rel_ * self.band_scale * self.band_factor(temp_c) * force_n)

    # -- identification -------------------------------------------------------------------

    def fit(self, data: Dataset, icfn: ICFN | None = None) -> ObserverModel:
        """Identify the parameters from a dataset's RCFN holds (module docstring).

        Parameters
        ----------
        data : Dataset
            A dataset with RCFN sequences (``relaxgrip dataset build`` or
            ``relaxgrip dataset from-recordings``).
        icfn : ICFN, optional
            The ICFN whose onset estimate scales the observer (for the band);
            without it the band assumes the onset force is known exactly.

        Returns
        -------
        ObserverModel
            ``self``.

        Raises
        ------
        InputError
            Too few usable sequences, hyperparameters out of range, or holds the
            identification cannot take: a hold or its loading longer than a day,
            forces that fit no positive stiffness or no Prony series, or
            parameters that come out non-finite.
        """
        self._check_params()
        holds = self._prepare(data)
        train = [h for h in holds if h.split == "train"] or holds
        held = [h for h in holds if h.split != "train"] or holds
        # Without train holds every hold identifies the model and calibrates its band.
        self.identified_on_ = "train" if any(h.split == "train" for h in holds) else "all"
        groups = sorted({h.group for h in train})
        group_temps = np.array([np.mean([h.temp_c for h in train if h.group == g])
                                for g in groups])
        ref = int(np.argmin(np.abs(group_temps - float(np.median(group_temps)))))
        self.tau_ref_s_ = self._reference_times(
            [h for h in train if h.group == groups[ref]])
        # The shift factor falls with temperature (WLF / Arrhenius): groups are fitted from
        # the coldest up, each searched at or below the previous one's shift, which keeps
        # the modes from swapping between groups where two local optima compete.
        shifts, shares = [0.0] * len(groups), [np.zeros(self.n_terms)] * len(groups)
        totals: list[FloatArray] = [np.zeros(0)] * len(groups)
        bounds = (-6.0, 6.0)
        for i in np.argsort(group_temps).tolist():
            s, share, total = self._fit_group([h for h in train if h.group == groups[i]],
                                              bounds)
            shifts[i], shares[i], totals[i] = s, share, total
            bounds = (s - _MAX_SHIFT_DROP, s + _SHIFT_SLACK)
        log_shift = np.array(shifts) - shifts[ref]
        self.tau_ref_s_ = self.tau_ref_s_ * math.exp(shifts[ref])
        order = np.argsort(group_temps)
        self.temps_c_ = group_temps[order]
        self.log_shift_ = log_shift[order]
        self.branch_share_ = np.array(shares)[order]
        self.share_spread_ = _share_spread(totals)[order]
        shift_of = dict(zip(groups, log_shift.tolist(), strict=True))
        self.log_stiffness_ = self._stiffness(train, groups, ref, shift_of)[order]
        self._fit_band(held, icfn)
        self.n_sequences_ = len(holds)
        bad = [name for name, value in self.to_arrays().items() if not np.isfinite(value).all()]
        if bad:  # load_observer would refuse the file: say so now, of the dataset
            raise InputError(f"the dataset's RCFN holds give non-finite observer parameters "
                             f"({', '.join(bad)}); check their forces and deflections")
        return self

    def _prepare(self, data: Dataset) -> list[_Hold]:
        seqs = data.sequences
        if len(seqs) == 0:
            raise InputError("the dataset has no RCFN sequences")
        feats = {int(k): v.sort_values("t_s") for k, v in data.rcfn_features.groupby("sequence")}
        curves = {int(k): v.sort_values("t_s") for k, v in data.curves.groupby("sequence")}
        onset_names = [f"onset_{n}" for n in ICFN_SCHEMA.names]
        has_onset = all(n in seqs.columns for n in onset_names)
        ratios = data.rcfn_features["closure_ratio"].to_numpy(np.float64)
        fallback_ratio = float(np.nanmedian(ratios)) if np.isfinite(ratios).any() else 1.0
        holds = []
        set_temps: list[float] = []
        for _, row in seqs.iterrows():
            seq = int(row["sequence"])
            if seq not in feats or seq not in curves:
                continue
            fe, cu = feats[seq], curves[seq]
            d0 = float(fe["onset_dx_m"].iloc[0])
            f0 = float(row["f0_n"])
            t_c = cu["t_s"].to_numpy(np.float64)
            # Under one resampling step a hold shows no relaxation (and the Prony fit of the
            # reference times needs two samples at least).
            if not (d0 > 0 and f0 > 0) or len(fe) < 2 or not t_c[-1] >= _FIT_DT_S:
                continue
            if t_c[-1] > _MAX_HOLD_S:
                raise InputError(f"RCFN sequence {seq}: a hold of {t_c[-1]:g} s; the observer "
                                 f"identifies holds of at most {_MAX_HOLD_S:g} s (a day)")
            f_c = cu["force_n"].to_numpy(np.float64)  # within MAX_FORCE_N: load_dataset checks
            grid = np.arange(0.0, float(t_c[-1]) + 1e-9, _FIT_DT_S)
            f = np.interp(grid, t_c, f_c)
            d_hold = np.interp(grid, fe["t_s"].to_numpy(np.float64),
                               fe["dx_m"].to_numpy(np.float64))
            d_hold[0] = d0
            ratio = float(fe["closure_ratio"].iloc[0])
            if not (math.isfinite(ratio) and ratio > 0):
                ratio = fallback_ratio
            load_s = max(ratio * d0 * 1e3 / self.loading_speed_mm_s, 1e-3)
            if not load_s <= _MAX_HOLD_S:
                raise InputError(
                    f"RCFN sequence {seq}: an onset deflection of {d0:g} m at closure ratio "
                    f"{ratio:g} makes a loading of {load_s:g} s at {self.loading_speed_mm_s:g} "
                    f"mm/s; the observer identifies loadings of at most {_MAX_HOLD_S:g} s")
            ramp_t = np.linspace(-load_s, 0.0, _RAMP_STEPS + 1)[:-1]
            ramp_d = np.linspace(0.0, d0, _RAMP_STEPS + 1)[:-1]
            temp_c = float(np.nanmedian(fe["temp_c"].to_numpy(np.float64)))
            set_temps.append(float(row["temp_set_c"]))
            holds.append(_Hold(
                sequence=seq, group=math.nan,  # set below, from every hold's temperature
                temp_c=temp_c,
                setup=f"{row['object']}@{float(row['contact_set_m']):.3f}",
                split=str(row["split"]), f0_n=f0,
                t_s=np.concatenate([ramp_t, grid]), d_m=np.concatenate([ramp_d, d_hold]),
                f_n=f, onset_x=row[onset_names].to_numpy(np.float64) if has_onset else None,
            ))
        if len(holds) < 3:
            raise InputError(f"only {len(holds)} usable RCFN sequences; the observer needs >= 3")
        keys = _group_keys(set_temps, [h.temp_c for h in holds])
        return [replace(h, group=key) for h, key in zip(holds, keys, strict=True)]

    def _reference_times(self, group: list[_Hold]) -> FloatArray:
        n = min(h.f_n.size for h in group)
        t = group[0].t_s[_RAMP_STEPS:][:n]
        y = np.mean([h.f_n[:n] / h.f0_n for h in group], axis=0)
        try:
            fit = fit_prony(t, y, n_terms=self.n_terms)
        except InputError as exc:  # the holds are too short for this many times
            failed = exc.n_terms if isinstance(exc, UnidentifiableError) else self.n_terms
            if failed == 1:
                raise
            raise InputError(f"{exc} (relaxgrip fit-observer --terms {failed - 1})") from None
        return np.clip(np.asarray(fit.tau_s, dtype=np.float64), 0.05, 1e5)

    def _group_error(self, group: list[_Hold], log_shift: float
                     ) -> tuple[float, FloatArray, list[float]]:
        """Normalised squared error of a group at one shift, its shares and stiffnesses.

        The shares come one row per sequence (for their mean and for the spread
        of the relaxing share between runs), the stiffnesses one per sequence.
        """
        from scipy.optimize import nnls

        tau = self.tau_ref_s_ * math.exp(log_shift)
        err = 0.0
        shares, stiff = [], []
        for h in group:
            resp = branch_responses(h.t_s, h.d_m, tau)[_RAMP_STEPS:]
            basis = np.column_stack([h.d_m[_RAMP_STEPS:], resp])
            theta, resid = nnls(basis, h.f_n)
            rel = float(resid) / h.f0_n
            err += rel * rel  # not ** 2: a float power overflows with an exception
            total = float(theta.sum())
            stiff.append(total)
            shares.append(theta[1:] / total if total > 0 else np.zeros(self.n_terms))
        return err, np.array(shares).reshape(len(group), self.n_terms), stiff

    def _fit_group(self, group: list[_Hold], bounds: tuple[float, float]
                   ) -> tuple[float, FloatArray, FloatArray]:
        from scipy.optimize import minimize_scalar

        grid = np.linspace(bounds[0], bounds[1], max(9, round(4 * (bounds[1] - bounds[0])) + 1))
        errs = [self._group_error(group, s)[0] for s in grid]
        best = int(np.argmin(errs))
        lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
        res = minimize_scalar(lambda s: self._group_error(group, float(s))[0],
                              bounds=(lo, hi), method="bounded", options={"xatol": 1e-3})
        s = float(res.x) if res.fun <= errs[best] else float(grid[best])
        shares = self._group_error(group, s)[1]
        return s, shares.mean(axis=0), shares.sum(axis=1)

    def _stiffness(self, holds: list[_Hold], groups: list[float], ref: int,
                   shift: dict[float, float]) -> FloatArray:
        """``ln k(T)`` per group, relative to the reference group (set-ups as nuisance)."""
        setups = sorted({h.setup for h in holds})
        rows, target = [], []
        for h in holds:
            i = groups.index(h.group)
            _, _, stiff = self._group_error([h], shift[h.group])
            if not stiff[0] > 0:
                continue
            row = np.zeros(len(groups) + len(setups))
            row[i] = 1.0
            row[len(groups) + setups.index(h.setup)] = 1.0
            rows.append(row)
            target.append(math.log(stiff[0]))
        if not rows:
            raise InputError("no RCFN sequence gives the observer a positive stiffness: their "
                             "forces do not follow the marker's deflection")
        a = np.array(rows)
        a = np.delete(a, ref, axis=1)  # the reference group is the level
        coef, *_ = np.linalg.lstsq(a, np.array(target), rcond=None)
        out = np.insert(coef[: len(groups) - 1], ref, 0.0)
        return np.asarray(out, dtype=np.float64)

    def predict_hold(self, t_s: FloatArray, d_m: FloatArray, temp_c: float) -> FloatArray:
        """Unit-scaled force along a deflection history at one temperature (arbitrary scale).

        Parameters
        ----------
        t_s, d_m : ndarray, shape (n,)
            Times (s) and marker deflection (m), the history starting at rest.
        temp_c : float
            Temperature (°C).

        Returns
        -------
        ndarray, shape (n,)
            ``k(T) [g_e d + sum g_i h_i]`` (m, per unit reference stiffness).
        """
        k_e, k_i, tau = self.parameters(temp_c)
        return k_e * d_m + branch_responses(t_s, d_m, tau) @ k_i

    def _fit_band(self, held: list[_Hold], icfn: ICFN | None) -> None:
        edges = np.arange(0.0, max(h.t_s[-1] for h in held) + _BAND_BIN_S, _BAND_BIN_S)
        errs: list[list[float]] = [[] for _ in edges]
        onset_errs = []
        for h in held:
            u = self.predict_hold(h.t_s, h.d_m, h.temp_c)[_RAMP_STEPS:]
            f_onset = h.f0_n
            if icfn is not None and h.onset_x is not None and np.isfinite(h.onset_x).all():
                f_onset = max(1e-3, float(icfn.predict(h.onset_x[None, :])[0]))
            est = f_onset * u / u[0]
            rel = np.abs(est - h.f_n) / h.f0_n
            onset_errs.append(abs(f_onset - h.f0_n) / h.f0_n)
            t = h.t_s[_RAMP_STEPS:]
            idx = np.minimum((t / _BAND_BIN_S).astype(int), edges.size - 1)
            for b, r in zip(idx.tolist(), rel.tolist(), strict=True):
                errs[b].append(r)
        q = 100.0 * self.band_level
        rel_q = np.array([np.percentile(e, q) if e else np.nan for e in errs])
        rel_q = np.maximum.accumulate(np.where(np.isfinite(rel_q), rel_q, 0.0))
        self.band_t_s_ = edges + 0.5 * _BAND_BIN_S
        self.band_rel_ = np.maximum(rel_q, float(np.percentile(onset_errs, q)))
        self.onset_rel_ = float(np.percentile(onset_errs, q))

    # -- persistence ----------------------------------------------------------------------

    def to_arrays(self) -> dict[str, FloatArray]:
        """The learned arrays (for :func:`save_observer`)."""
        self._check_fitted()
        out = {name: np.asarray(getattr(self, name), dtype=np.float64) for name in _ARRAYS}
        out["onset_rel_"] = np.array([self.onset_rel_])
        out["share_spread_"] = np.asarray(self.share_spread_, dtype=np.float64)
        return out

    def _check_params(self) -> None:
        """Refuse parameters no fit or band can use (:class:`InputError`)."""
        if isinstance(self.n_terms, bool) or self.n_terms not in range(1, 6):
            raise InputError(f"n_terms must be 1-5, got {self.n_terms!r}")
        if not (_finite_at_least(self.band_scale, 0.0, strict=True)
                and _finite_at_least(self.drift_scale, 0.0, strict=False)
                and _finite_at_least(self.band_floor_n, 0.0, strict=False)):
            raise InputError(f"band_scale must be > 0, drift_scale and band_floor_n >= 0 "
                             f"(finite), got {self.band_scale!r}, {self.drift_scale!r} and "
                             f"{self.band_floor_n!r}")
        if not (self.loading_speed_mm_s > 0 and 0.5 <= self.band_level < 1.0):
            raise InputError("need loading_speed_mm_s > 0, 0.5 <= band_level < 1")
        check_temp_factors(self.band_temps_c, self.band_temp_factors)

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, Any], params: Mapping[str, Any]) -> ObserverModel:
        """Rebuild a fitted model from :meth:`to_arrays` and :meth:`get_params`.

        Raises
        ------
        ValueError
            Missing, non-finite or misshapen arrays, or unknown parameters.
        """
        params = dict(params)
        if "band_scale" in params:  # files from before the drift part had its own scale
            params.setdefault("drift_scale", params["band_scale"])
        try:
            model = cls(**params)
        except TypeError as exc:
            raise ValueError(f"bad observer parameters: {exc}") from exc
        try:
            model._check_params()  # an InputError, a ValueError, names a bad band scale
        except TypeError:  # a parameter of another type than a number
            raise ValueError(f"bad observer parameters: {dict(params)}") from None
        onset = np.asarray(arrays.get("onset_rel_", [np.nan]), dtype=np.float64).ravel()
        if onset.size != 1 or not np.isfinite(onset).all():
            raise ValueError("array 'onset_rel_' missing or bad")
        model.onset_rel_ = float(onset[0])
        # Files written before the share spread was identified: no drift band.
        spread = arrays.get("share_spread_")
        for name in _ARRAYS:
            if name not in arrays:
                raise ValueError(f"array {name!r} missing")
            value = np.asarray(arrays[name], dtype=np.float64)
            if not np.isfinite(value).all():
                raise ValueError(f"array {name!r} has non-finite values")
            setattr(model, name, value)
        n_k = model.temps_c_.size
        n = model.tau_ref_s_.size
        model.share_spread_ = (np.zeros(n_k) if spread is None
                               else np.asarray(spread, dtype=np.float64))
        if model.share_spread_.shape != (n_k,) or not (
                np.isfinite(model.share_spread_).all() and (model.share_spread_ >= 0).all()):
            raise ValueError("array 'share_spread_' must hold one spread >= 0 per temperature")
        if not (model.temps_c_.ndim == 1 and n_k >= 1 and model.log_shift_.shape == (n_k,)
                and model.log_stiffness_.shape == (n_k,) and model.branch_share_.shape == (n_k, n)
                and model.tau_ref_s_.shape == (n,) and n == model.n_terms
                and model.band_t_s_.shape == model.band_rel_.shape
                and model.band_t_s_.ndim == 1 and model.band_t_s_.size >= 1):
            raise ValueError("array shapes do not fit together")
        if (model.tau_ref_s_ <= 0).any() or np.any(np.diff(model.temps_c_) < 0):
            raise ValueError("relaxation times must be > 0 and temperatures ascending")
        return model


class ObserverFileError(InputError):
    """An observer directory that cannot be loaded (one line: the file and the problem)."""


def check_observer_out(directory: Path) -> Path:
    """Check that an observer can be written at ``directory`` (before fitting it).

    Raises
    ------
    InputError
        A file there, a directory of something else, one of an earlier
        observer with files that are not its own, or not writable.
    """
    return check_output_dir(Path(directory), OBSERVER_FORMAT, (OBSERVER_FILE, MANIFEST_NAME),
                            InputError)


def save_observer(directory: Path, model: ObserverModel, training: Mapping[str, Any]) -> Path:
    """Write ``observer.npz`` and ``manifest.json`` (format, version, sha256, training record).

    Returns
    -------
    Path
        The manifest's path.
    """
    directory = check_observer_out(directory)
    data = npz_bytes(dict(model.to_arrays()))
    manifest = {
        "format": OBSERVER_FORMAT, "format_version": OBSERVER_VERSION,
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "relaxgrip_version": relaxgrip.__version__,
        "observer": {"estimator": "ObserverModel", "params": model.get_params(),
                     **file_entry(OBSERVER_FILE, data)},
        "training": dict(training),
    }
    text = json.dumps(manifest, indent=2, allow_nan=False)
    with made_directory(directory):
        write_files_atomically(directory, [(OBSERVER_FILE, data),
                                           (MANIFEST_NAME, (text + "\n").encode())])
    return directory / MANIFEST_NAME


def load_observer(directory: Path) -> ObserverModel:
    """Load an observer directory written by :func:`save_observer`, checking everything.

    Raises
    ------
    ObserverFileError
        Missing directory or file, a foreign or too new manifest, a file whose
        size or sha256 differs from the manifest, unreadable or bad arrays.
    """
    directory = Path(directory)
    path = directory / MANIFEST_NAME
    manifest = read_manifest(path, OBSERVER_FORMAT, OBSERVER_VERSION, ObserverFileError,
                             "an observer model directory")
    section = manifest.get("observer")
    if not (isinstance(section, dict) and isinstance(section.get("params"), dict)
            and {"file", "bytes", "sha256"} <= section.keys()):
        raise ObserverFileError(f"{path}: manifest lacks the 'observer' section or its fields")
    npz_path, arrays = read_npz_entry(directory, section, ObserverFileError)
    try:
        model = ObserverModel.from_arrays(arrays, section["params"])
    except Exception as exc:  # shape and value checks of the arrays and parameters
        # The parameters are the manifest's, the arrays the npz file's: name both.
        raise ObserverFileError(f"{path} and {npz_path.name}: {one_line(exc)}") from None
    model.source = (directory.resolve(), str(section["sha256"]))
    return model


def set_band_scale(directory: Path, band_scale: float, record: Mapping[str, Any],
                   drift_scale: float | None = None, floor_n: float | None = None,
                   temp_factors: tuple[Sequence[float], Sequence[float]] | None = None,
                   ) -> ObserverModel:
    """Rewrite an observer directory with a recalibrated band, atomically.

    The parameters and the training record are kept; ``record`` (how the
    scales were measured) becomes the record's ``band_recalibration``.

    Parameters
    ----------
    directory : Path
        An observer directory (:func:`save_observer`).
    band_scale : float
        The new :attr:`ObserverModel.band_scale` (> 0).
    record : mapping
        How it was measured.
    drift_scale : float, optional
        The new :attr:`ObserverModel.drift_scale` (>= 0); the directory's is
        kept without one.
    floor_n : float, optional
        The new :attr:`ObserverModel.band_floor_n` (N, >= 0); the directory's
        is kept without one.
    temp_factors : (temperatures, factors), optional
        The new :attr:`ObserverModel.band_temps_c` (°C, ascending) and
        :attr:`ObserverModel.band_temp_factors` (> 0, one per temperature;
        both empty: none); the directory's are kept without them.

    Raises
    ------
    ObserverFileError
        The directory cannot be loaded.
    InputError
        A band scale that is not a positive number, a drift scale or floor
        that is not a number >= 0, or temperature factors as
        :func:`check_temp_factors` refuses.
    """
    check_positive(band_scale, "band scale")
    if drift_scale is not None and check_finite(drift_scale, "drift scale") < 0:
        raise InputError(f"drift scale must be >= 0, got {drift_scale}")
    if floor_n is not None and check_finite(floor_n, "band floor") < 0:
        raise InputError(f"band floor must be >= 0 N, got {floor_n}")
    if temp_factors is not None:
        check_temp_factors(*temp_factors)
    directory = Path(directory)
    model = load_observer(directory)
    manifest = read_manifest(directory / MANIFEST_NAME, OBSERVER_FORMAT, OBSERVER_VERSION,
                             ObserverFileError, "an observer model directory")
    training = manifest.get("training")
    training = dict(training) if isinstance(training, dict) else {}
    training["band_recalibration"] = dict(record)
    model.band_scale = float(band_scale)
    if drift_scale is not None:
        model.drift_scale = float(drift_scale)
    if floor_n is not None:
        model.band_floor_n = float(floor_n)
    if temp_factors is not None:
        model.band_temps_c = tuple(float(t) for t in temp_factors[0])
        model.band_temp_factors = tuple(float(f) for f in temp_factors[1])
    save_observer(directory, model, training)
    return model


def band_factors(temps_c: Sequence[float], factors: Sequence[float],
                 temp_c: ArrayLike) -> FloatArray:
    """The band's temperature factors at each of ``temp_c`` (°C): ``factors`` at
    ``temps_c`` interpolated, held beyond the ends; 1 without factors or where no
    temperature was read.  The one rule for the observer and its calibration."""
    temp = np.asarray(temp_c, dtype=np.float64)
    if not factors:
        return np.ones_like(temp)
    out: FloatArray = np.where(np.isfinite(temp), np.interp(temp, temps_c, factors), 1.0)
    return out


def check_temp_factors(temps_c: Sequence[Any], factors: Sequence[Any]) -> None:
    """Refuse band temperature factors no band can use (:class:`InputError`): one factor
    (finite, > 0) per temperature (finite, ascending)."""
    ok = (len(temps_c) == len(factors)
          and all(_finite_at_least(f, 0.0, strict=True) for f in factors)
          and all(_finite_at_least(t, -math.inf, strict=True) for t in temps_c)
          and all(a < b for a, b in itertools.pairwise(temps_c)))
    if not ok:
        raise InputError(f"band temperature factors must be one number > 0 per temperature, "
                         f"the temperatures ascending, got {list(temps_c)!r} °C and "
                         f"{list(factors)!r}")


def _finite_at_least(value: Any, low: float, strict: bool) -> bool:
    """Whether ``value`` is a finite number above ``low`` (or at it, unless ``strict``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return False
    return value > low if strict else value >= low


#: Holds without a set temperature whose measured ones lie within this of each other (K)
#: are one heater setting: a setting's holds read within about a kelvin, and settings
#: differ by several.
_GROUP_GAP_K = 1.0


def _group_keys(set_temps_c: list[float], temps_c: list[float]) -> list[float]:
    """Each hold's temperature group: its set temperature to 0.1 °C, or without one the
    setting its measured temperature belongs to.

    Recordings whose plan set no heater temperature give NaN set points, and NaN keys
    would never compare equal.  ``temps_c`` are the medians of the holds' ``temp_c``
    feature (°C).  Sorted, holds without a set point run into one setting while each is
    within :data:`_GROUP_GAP_K` of the one before (rounding to whole degrees split one
    setting whose holds read 40.48 and 40.59 °C); a setting whose median lies within that
    of a set temperature joins its group, and any other is keyed by its median to 0.1 °C.
    """
    keys = [round(t, 1) if math.isfinite(t) else math.nan for t in set_temps_c]
    set_keys = sorted({k for k in keys if math.isfinite(k)})
    unset = sorted((i for i, k in enumerate(keys) if not math.isfinite(k)),
                   key=lambda i: temps_c[i])
    runs: list[list[int]] = []
    for i in unset:
        if runs and temps_c[i] - temps_c[runs[-1][-1]] <= _GROUP_GAP_K:
            runs[-1].append(i)
        else:
            runs.append([i])
    for members in runs:
        median = float(np.median([temps_c[i] for i in members]))
        near = min(set_keys, key=lambda k: abs(k - median), default=math.nan)
        key = near if abs(near - median) <= _GROUP_GAP_K else round(median, 1)
        for i in members:
            keys[i] = key
    return keys


def _share_spread(totals: list[FloatArray]) -> FloatArray:
    """Relative SD of each group's per-sequence total branch share.

    A group of fewer than three holds says little about its spread: it takes
    the spread pooled over every group of two or more (0 when there is none).
    """
    rel = [t / np.mean(t) - 1.0 for t in totals if t.size >= 2 and np.mean(t) > 0]
    dof = sum(r.size - 1 for r in rel)
    pooled = math.sqrt(sum(float(r @ r) for r in rel) / dof) if dof > 0 else 0.0
    return np.array([float(np.std(t, ddof=1) / np.mean(t))
                     if t.size >= 3 and np.mean(t) > 0 else pooled for t in totals])


def default_observer_dir() -> Path:
    """Where the shipped observer parameters live (inside the package)."""
    from importlib import resources

    return Path(str(resources.files("relaxgrip") / "models" / "observer"))


def load_default_observer() -> ObserverModel:
    """The shipped observer parameters."""
    return load_observer(default_observer_dir())


def fit_observer(data_dir: Path, out_dir: Path, models_dir: Path | None = None,
                 n_terms: int = 3) -> ObserverModel:
    """Identify the observer on a dataset directory and save it to ``out_dir``.

    ``relaxgrip fit-observer --data DIR --out DIR`` runs this; the shipped
    parameters came from ``relaxgrip dataset build --icfn-samples 0
    --rcfn-sequences 810 --seed 3``, their band scaled by ``relaxgrip
    calibrate-band DIR --seeds 3000-3035`` (see the manifest's training record).

    Parameters
    ----------
    data_dir : Path
        A relaxgrip dataset with RCFN sequences.
    out_dir : Path
        Observer directory to write.
    models_dir : Path, optional
        The model directory whose ICFN reads the contact onset for the band's
        onset error: the gripper's own (default: the shipped models).
    n_terms : int
        Prony branches, 1-5: holds too short to separate three relaxation
        times identify fewer.

    Returns
    -------
    ObserverModel
    """
    from relaxgrip.learning.datastore import load_dataset
    from relaxgrip.learning.store import load_models
    from relaxgrip.learning.training import default_models_dir
    from relaxgrip.perception.features import ICFN_SCHEMA

    check_observer_out(out_dir)
    # Only the ICFN is read: an RCFN of other features (a rebuild's) does not stop the fit.
    net = load_models(default_models_dir() if models_dir is None else Path(models_dir),
                      icfn_feature_schema=ICFN_SCHEMA).icfn
    data = load_dataset(Path(data_dir))
    model = ObserverModel(n_terms=n_terms).fit(data, net)
    spec = data.manifest.get("spec", {})
    save_observer(Path(out_dir), model, {
        "dataset": {"path": str(data_dir), "spec": spec,
                    "twin_version": data.manifest.get("twin_version")},
        "onset_icfn": "shipped" if models_dir is None else str(models_dir),
        "n_sequences": model.n_sequences_,
        "identified_on": model.identified_on_,
    })
    return model
