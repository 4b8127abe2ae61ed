"""``relaxgrip ablation``: what each of the observer's parts is worth, on fresh seeds.

The ``observer`` (:mod:`relaxgrip.control.observer`) is Eq. 10 with the parts
:data:`~relaxgrip.control.observer.PARTS`.  This runs the full observer and,
on the same seeds, the observer with each part removed, and ``relax`` (Eq. 10
alone) beside them: closed-loop 280 s holds on the twin, scored by the MAE of
the true force from the target over the steady state.  For each part the
difference ``MAE(without it) - MAE(observer)`` is paired over seeds; its mean
and 95 % interval (Student's t) say whether the part earns its place: it does
when the interval lies above zero.  A part that does not is removed from the
observer.

The calibration part is the model directory's, measured with the full
observer; the variants without another part keep it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from relaxgrip.control import EstimatorKind
from relaxgrip.control.observer import PARTS
from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import (
    PAPER_DURATION_S,
    check_hold,
    map_holds,
    run_hold,
)
from relaxgrip.learning.store import ModelBundle
from relaxgrip.twin import TWIN_VERSION, TwinConfig

__all__ = ["Ablation", "paired_interval", "run_ablation"]

#: The variants: the full observer, each part left out, and Eq. 10 alone.
FULL = "observer"
RELAX = "relax"


def paired_interval(a: Sequence[float], b: Sequence[float], level: float = 0.95
                    ) -> tuple[float, float, float]:
    """Mean of ``a - b`` over pairs and its ``level`` interval (Student's t).

    The interval is (nan, nan) for fewer than two pairs.
    """
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    mean = float(d.mean())
    if d.size < 2:
        return mean, math.nan, math.nan
    half = float(stats.t.ppf(0.5 + level / 2, d.size - 1) * d.std(ddof=1) / math.sqrt(d.size))
    return mean, mean - half, mean + half


@dataclass(frozen=True)
class Ablation:
    """Each variant's MAE on every seed.

    Attributes
    ----------
    seeds : list of int
    target_n, temp_c, duration_s : float
        The hold.
    mae_n : dict of str to list of float
        Variant (``observer``, ``without <part>``, ``relax``) to its MAE per seed (N).
    rig : str
        Which gripper's twin ran.
    """

    seeds: list[int]
    target_n: float
    temp_c: float
    duration_s: float
    mae_n: dict[str, list[float]]
    rig: str = "ours"

    def rows(self) -> list[dict[str, Any]]:
        """Per part: the MAE without it, the paired difference from the full observer with
        its 95 % interval, and whether the part earns its place (the interval above 0)."""
        full = self.mae_n[FULL]
        out = []
        for name, runs in self.mae_n.items():
            if name == FULL:
                continue
            mean, lo, hi = paired_interval(runs, full)
            out.append({"variant": name, "mae_n": float(np.mean(runs)), "diff_n": mean,
                        "diff_lo_n": lo, "diff_hi_n": hi, "earns": bool(lo > 0)})
        return out

    def to_dict(self) -> dict[str, Any]:
        """The ``relaxgrip ablation --json`` object."""
        return {"twin_version": TWIN_VERSION, "rig": self.rig, "seeds": self.seeds,
                "target_n": self.target_n, "temp_c": self.temp_c,
                "duration_s": self.duration_s,
                "observer_mae_n": float(np.mean(self.mae_n[FULL])),
                "rows": self.rows(), "mae_n": self.mae_n}


def _variant(name: str) -> tuple[str, tuple[str, ...]]:
    if name == RELAX:
        return EstimatorKind.RELAX.value, ()
    if name == FULL:
        return EstimatorKind.OBSERVER.value, ()
    return EstimatorKind.OBSERVER.value, (name.removeprefix("without "),)


def _one(args: tuple[str, int, float, float, float, ModelBundle | None, TwinConfig | None]
         ) -> float:
    name, seed, target_n, temp_c, duration_s, models, config = args
    kind, without = _variant(name)
    hold = run_hold(kind, target_n, duration_s, temp_c, seed, models, config=config,
                    without=without)
    return float(hold.metrics()["mae_n"])


def run_ablation(seeds: Sequence[int], target_n: float = 5.0, temp_c: float = 40.0,
                 duration_s: float = PAPER_DURATION_S, models: ModelBundle | None = None,
                 parts: Sequence[str] = PARTS, n_jobs: int = 1,
                 config: TwinConfig | None = None, rig: str = "ours") -> Ablation:
    """Run the full observer, each variant without one of ``parts``, and ``relax``.

    Raises
    ------
    InputError
        Fewer than two seeds (no interval), an unknown part, a hold out of range.
    """
    if len(seeds) < 2 or len(set(seeds)) != len(seeds) or min(seeds) < 0:
        raise InputError("an ablation needs two or more distinct non-negative seeds")
    unknown = [p for p in parts if p not in PARTS]
    if unknown:
        raise InputError(f"unknown observer part {unknown[0]!r}; parts: {', '.join(PARTS)}")
    check_hold(EstimatorKind.OBSERVER, target_n, temp_c, duration_s)
    names = [FULL, *(f"without {p}" for p in parts), RELAX]
    jobs = [(name, int(seed), target_n, temp_c, duration_s, models, config)
            for name in names for seed in seeds]
    results = map_holds(_one, jobs, n_jobs)
    mae: dict[str, list[float]] = {name: [] for name in names}
    for (name, *_), value in zip(jobs, results, strict=True):
        mae[name].append(value)
    return Ablation([int(s) for s in seeds], target_n, temp_c, duration_s, mae, rig)
