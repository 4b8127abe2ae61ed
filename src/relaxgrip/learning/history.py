"""What a single frame cannot show: how much of its unrelaxed force a finger still carries.

The ICFN reads the force from one frame, but a viscoelastic finger's force
at a given deflection depends on how it got there: closed slowly, its fast
branches have relaxed on the way and it pushes less than closed fast.  The
ICFN's training closings span 0.5-4 mm/s, so on one frame it can only give
their average: on the twin (force ball, 40 °C, 80 mm) it read 0.13-0.32 N
low at 5-7 N on closings at 2 mm/s and up to 0.1 N high at 0.5 mm/s, by
how much depending on its training seed.  The controller closes at up to
3 mm/s, so the hold onset, which every later estimate of ``relax`` builds
on, read 0.07-0.21 N low on average for four of five training seeds.

The remedy splits the estimate in two.  :class:`LoadingHistory` integrates the
finger's Maxwell branches (the observer's parameters,
:class:`relaxgrip.learning.observer.ObserverModel`) along the deflection the
marker measures, from contact, and gives the **retained share**: the force
per unit of deflection now over the instantaneous stiffness,
``(k_e d + sum F_i) / ((k_e + sum k_i) d)``, 1 for a step, less the longer
the loading took.  An ICFN trained on the force divided by that share
(:func:`retained_shares` on the dataset's episodes) reads the force the
finger would carry had it not relaxed, which one frame does show; times the
share at run time it is the force (:class:`UnrelaxedIcfn`).  The share uses
what perception measures on both sides (the marker's ``dx`` and the
infrared beam temperatures), so it applies to recorded data as to the twin.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from relaxgrip.learning.icfn import ICFN
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.perception.features import ICFN_SCHEMA
from relaxgrip.physics.viscoelastic import branch_update

__all__ = ["CONTACT_DEFLECTION_M", "UNRELAXED_FEATURES", "LoadingHistory", "UnrelaxedIcfn",
           "features_deflection_m", "features_temp_c", "retained_shares"]

FloatArray = NDArray[np.float64]
#: Marker deflection (m) from which the branches load: the controller's contact threshold.
CONTACT_DEFLECTION_M = 3e-5
#: Step of the integration along a dataset episode, between its samples (s).
_EPISODE_DT_S = 1.0 / 30.0
_DX = ICFN_SCHEMA.index("marker_dx_m")
_TEMPS = (ICFN_SCHEMA.index("f0_temp_mean_c"), ICFN_SCHEMA.index("f1_temp_mean_c"))


def features_deflection_m(features: ArrayLike) -> FloatArray:
    """The marker deflection the share is integrated along: its ``dx`` (m).

    Parameters
    ----------
    features : array_like, shape (d,) or (n, d)
        ICFN feature vectors (:data:`relaxgrip.perception.features.ICFN_SCHEMA`).
    """
    x = np.asarray(features, dtype=np.float64)
    dx: FloatArray = x[..., _DX]
    return dx


def features_temp_c(features: ArrayLike) -> FloatArray:
    """The finger temperature the share is computed at: both fingers' infrared means (°C).

    Parameters
    ----------
    features : array_like, shape (d,) or (n, d)
        ICFN feature vectors (:data:`relaxgrip.perception.features.ICFN_SCHEMA`).
    """
    x = np.asarray(features, dtype=np.float64)
    return 0.5 * (x[..., _TEMPS[0]] + x[..., _TEMPS[1]])


class LoadingHistory:
    """The finger's Maxwell branches along the measured deflection, from contact.

    Parameters
    ----------
    model : ObserverModel
        Fitted branch parameters over temperature.
    contact_deflection_m : float
        The branches start loading when the deflection first exceeds this (m).

    Attributes
    ----------
    branches_m : ndarray or None
        Branch states per unit reference stiffness (m); None before contact.
    deflection_m, temp_c : float
        The latest deflection (m) and temperature (°C).
    """

    def __init__(self, model: ObserverModel,
                 contact_deflection_m: float = CONTACT_DEFLECTION_M) -> None:
        self.model = model
        self.contact_deflection_m = contact_deflection_m
        self.reset()

    def reset(self) -> None:
        """Before contact: no branch has loaded."""
        self.branches_m: FloatArray | None = None
        self.deflection_m = math.nan
        self.temp_c = math.nan
        self._t: float | None = None
        self._params_at = math.nan
        self._params: tuple[float, FloatArray, FloatArray] | None = None

    def _parameters(self, temp_c: float) -> tuple[float, FloatArray, FloatArray]:
        """The model's parameters at ``temp_c``, kept while it stays (it changes at 1 Hz)."""
        if self._params is None or temp_c != self._params_at:
            self._params, self._params_at = self.model.parameters(temp_c), temp_c
        return self._params

    def advance(self, t_s: float, deflection_m: float, temp_c: float) -> None:
        """Step the branches to ``t_s`` (deflection linear, temperature constant over the step).

        Before contact nothing happens; at contact the deflection so far is
        taken to have arrived within the last frame.
        """
        if self.branches_m is None:
            if not deflection_m > self.contact_deflection_m:
                return
            _, k_i, tau = self._parameters(temp_c)
            self.branches_m, _ = branch_update(np.zeros(k_i.size), deflection_m, 0.0, k_i, tau)
        elif self._t is not None and t_s > self._t:
            _, k_i, tau = self._parameters(temp_c)
            self.branches_m, _ = branch_update(self.branches_m, deflection_m - self.deflection_m,
                                               t_s - self._t, k_i, tau)
        self.deflection_m, self.temp_c, self._t = deflection_m, temp_c, t_s

    def unit_force_m(self) -> float:
        """Force per unit reference stiffness now, ``k_e d + sum F_i`` (m); nan before contact."""
        if self.branches_m is None:
            return math.nan
        k_e, _, _ = self._parameters(self.temp_c)
        return k_e * self.deflection_m + float(self.branches_m.sum())

    def relaxed_m(self) -> float:
        """What the branches have relaxed of the instantaneous response (m, per unit)."""
        if self.branches_m is None:
            return math.nan
        _, k_i, _ = self._parameters(self.temp_c)
        return float(k_i.sum()) * self.deflection_m - float(self.branches_m.sum())

    def retained(self) -> float:
        """The share of the unrelaxed force the finger carries now (1 before contact).

        At most 1 at a constant temperature; above it after warming at a fixed
        deflection (see :func:`retained_shares`).
        """
        if self.branches_m is None or not self.deflection_m > self.contact_deflection_m:
            return 1.0
        k_e, k_i, _ = self._parameters(self.temp_c)
        return self.unit_force_m() / ((k_e + float(k_i.sum())) * self.deflection_m)


def _episode_shares(t_s: FloatArray, d_m: FloatArray, temp_c: FloatArray,
                    model: ObserverModel) -> FloatArray:
    """Retained shares at one episode's samples, the deflection linear between them."""
    order = np.argsort(t_s, kind="stable")
    t, d, temp = t_s[order], d_m[order], temp_c[order]
    n = max(2, math.ceil((t[-1] - t[0]) / _EPISODE_DT_S) + 1)
    grid = np.linspace(t[0], t[-1], n) if t[-1] > t[0] else t[:1]
    grid_d, grid_temp = np.interp(grid, t, d), np.interp(grid, t, temp)
    history = LoadingHistory(model)
    shares = np.empty(grid.size)
    for i in range(grid.size):
        history.advance(float(grid[i]), float(grid_d[i]), float(grid_temp[i]))
        shares[i] = history.retained()
    out = np.empty(t.size)
    out[order] = np.interp(t, grid, shares)
    return out


def retained_shares(rows: pd.DataFrame, model: ObserverModel,
                    columns: Sequence[str] = ICFN_SCHEMA.names) -> FloatArray:
    """Each ICFN sample's retained share, from its episode's loading up to it.

    An episode's samples are taken along one closing, so the deflection
    between them is interpolated linearly (a constant closing speed, which the
    dataset's episodes keep between their halvings).

    Parameters
    ----------
    rows : DataFrame
        ICFN rows with ``episode``, ``t_s`` and the feature columns.
    model : ObserverModel
        The branch parameters.
    columns : sequence of str
        The feature columns, in schema order.

    Returns
    -------
    ndarray, shape (len(rows),)
        The share: in ``(0, 1]`` at a constant temperature (1 for samples
        before contact).  Warmed at a fixed deflection, a finger keeps its
        branch forces while its instantaneous stiffness falls (Eq. 2 of the
        foundation, as the twin's physics), so the share can then pass 1.
    """
    x = rows[list(columns)].to_numpy(np.float64)
    t = rows["t_s"].to_numpy(np.float64)
    episodes = rows["episode"].to_numpy()
    shares = np.ones(len(rows))
    for episode in np.unique(episodes):
        at = np.flatnonzero(episodes == episode)
        shares[at] = _episode_shares(t[at], features_deflection_m(x[at]), features_temp_c(x[at]),
                                     model)
    return shares


#: What the unrelaxed ICFN reads by default: the marker's pose and each finger's warmest
#: infrared beam.  The other thermal features see the object: it covers the fingers'
#: distal beams in the infrared image, more as they close around it, and a network on
#: all 29 features learns that coverage as a cue of how far the grasp has closed.  At a
#: hold onset the cue reads what the run's grasp and object happen to show.  On the twin
#: (5 N, 40 °C, ``F_inst`` less the true force over the first 0.6 s of the hold, fresh
#: seeds 4000-4035) the 29-feature ensemble read +0.072 N (SD 0.055 N), its error
#: correlating -0.64 with the infrared beam under the ball; this one +0.022 N (SD
#: 0.043 N).  With the ball at 15, 25 and 35 °C instead of the room's (seeds
#: 4000-4011) the 29-feature reading moved by -0.008, +0.075 and +0.071 N on average
#: (SD 0.090, 0.073, 0.031 N), this one's by +0.013, +0.019 and +0.009 N (SD 0.039,
#: 0.054, 0.040 N).  The warmest beam is one the object leaves clear.
UNRELAXED_FEATURES: tuple[str, ...] = (
    *ICFN_SCHEMA.names[:9], "f0_temp_max_c", "f1_temp_max_c")


@dataclass(frozen=True)
class UnrelaxedIcfn:
    """ICFNs trained on unrelaxed forces, with the branch parameters their labels used.

    The estimate is the members' mean.  One network's reading of the
    closed-loop hold onset moves by about 0.1 N with its training seed (a
    state the test split does not sample: a closing at the controller's
    speed, slowing to a stop); five members trained alike on the same rows
    and differing only in their seed average that spread.

    Attributes
    ----------
    members : tuple of ICFN
        Each fitted on each sample's force over its retained share.
    model : ObserverModel
        The branch parameters of those shares; run time must use the same.
    features : tuple of str
        The ICFN features the members read, in the order of
        :data:`relaxgrip.perception.features.ICFN_SCHEMA` (all of them by
        default).  :meth:`predict_one` and :meth:`predict` take whole ICFN
        feature vectors and pick these.
    """

    members: tuple[ICFN, ...]
    model: ObserverModel
    features: tuple[str, ...] = ICFN_SCHEMA.names
    _columns: slice | NDArray[np.intp] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.members:
            raise ValueError("an unrelaxed ICFN needs at least one member")
        if len({m.n_features_in_ for m in self.members}) != 1:
            raise ValueError("the unrelaxed ICFN's members read different feature counts")
        names = ICFN_SCHEMA.names
        unknown = [f for f in self.features if f not in names]
        if unknown:
            raise ValueError(f"the unrelaxed ICFN reads features the ICFN schema does not "
                             f"have: {', '.join(unknown)}")
        columns = [names.index(f) for f in self.features]
        if columns != sorted(set(columns)):
            raise ValueError("the unrelaxed ICFN's features must be distinct and in the "
                             "ICFN schema's order")
        if self.members[0].n_features_in_ != len(columns):
            raise ValueError(f"the unrelaxed ICFN's members read "
                             f"{self.members[0].n_features_in_} features but it names "
                             f"{len(columns)}")
        # A slice where the features are the whole schema: no copy per frame.
        every = len(columns) == len(names)
        object.__setattr__(self, "_columns", slice(None) if every else np.array(columns))

    @property
    def n_features_in_(self) -> int:
        """Features each member reads."""
        return int(self.members[0].n_features_in_)

    def predict_one(self, x: FloatArray) -> float:
        """The members' mean unrelaxed force on one ICFN feature vector (N)."""
        picked = np.asarray(x)[self._columns]
        return sum(m.predict_one(picked) for m in self.members) / len(self.members)

    def predict(self, X: ArrayLike) -> FloatArray:
        """The members' mean unrelaxed force on each row of ICFN features (N)."""
        picked = np.asarray(X)[:, self._columns]
        mean: FloatArray = np.mean([m.predict(picked) for m in self.members], axis=0)
        return mean
