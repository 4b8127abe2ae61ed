"""Scenario profiles of a controlled hold: temperature, target and disturbance over hold time.

Grammar (times in seconds since the hold onset, fields separated by ``:``):

* ``--temp-profile``: ``ramp:FROM_C:TO_C:START_S:OVER_S`` (the setpoint
  moves linearly from ``FROM_C`` to ``TO_C`` over ``OVER_S`` from
  ``START_S``; ``FROM_C`` before) or ``step:TO_C:AT_S``.
* ``--target-profile``: ``step:TO_N:AT_S`` (the hold's target before, ``TO_N``
  from ``AT_S``) or ``ramp:FROM_N:TO_N:START_S:OVER_S``.

A ramp starts from the hold's own value (``FROM_C`` is ``--temp-c``,
``FROM_N`` is ``--target-n``): the hold refuses one that does not
(:func:`relaxgrip.experiments.controlled_hold.check_ramp_starts`), for its
``FROM`` would hold from the onset on, a jump at the onset.
* ``--disturbance``: ``push:FORCE_N:AT_S`` or ``push:FORCE_N:AT_S:FOR_S``
  (a hand pushes the held object with ``FORCE_N`` from ``AT_S``, for
  ``FOR_S`` if given).

Anything else is an :class:`relaxgrip.errors.InputError` naming the problem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.validate import parse_number

__all__ = ["Profile", "band_coverage", "parse_disturbance", "parse_target_profile",
           "parse_temp_profile"]


@dataclass(frozen=True)
class Profile:
    """A piecewise-linear value over hold time: ``before`` until ``start_s``, then a ramp.

    Attributes
    ----------
    before, after : float
        Value before ``start_s`` and after the ramp (nan ``before``: the
        caller's default).
    start_s, over_s : float
        Ramp start (s since the hold onset) and length (s; 0: a step).
    until_s : float
        The value returns to ``before`` from here (s; inf: never).
    """

    before: float
    after: float
    start_s: float
    over_s: float = 0.0
    until_s: float = math.inf

    def value_at(self, hold_s: float, default: float) -> float:
        """The value ``hold_s`` into the hold (``default`` where ``before`` is nan)."""
        before = default if math.isnan(self.before) else self.before
        if hold_s < self.start_s or hold_s >= self.until_s:
            return before
        if self.over_s <= 0 or hold_s >= self.start_s + self.over_s:
            return self.after
        return before + (self.after - before) * (hold_s - self.start_s) / self.over_s

    def values(self, hold_s: NDArray[np.float64], default: float) -> NDArray[np.float64]:
        """:meth:`value_at` over an array of hold times."""
        return np.array([self.value_at(float(t), default) for t in hold_s])


def _numbers(text: str, what: str, kinds: dict[str, tuple[int, ...]]) -> tuple[str, list[float]]:
    parts = text.strip().split(":")
    kind = parts[0].lower()
    grammar = " or ".join(f"{k}:" + ":".join(["N"] * min(n)) for k, n in kinds.items())
    if kind not in kinds or len(parts) - 1 not in kinds[kind]:
        raise InputError(f"{what} {text!r}: expected {grammar}")
    try:
        values = [parse_number(p) for p in parts[1:]]
    except ValueError:
        raise InputError(f"{what} {text!r}: not a number in it (expected {grammar})") from None
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"{what} {text!r}: values must be finite")
    return kind, values


def _times(what: str, text: str, *times: float) -> None:
    if any(t < 0 for t in times):
        raise InputError(f"{what} {text!r}: times must be >= 0 s")


def parse_temp_profile(text: str) -> Profile:
    """Parse ``ramp:FROM:TO:START:OVER`` or ``step:TO:AT`` (°C, s); range-checked."""
    from relaxgrip.experiments.controlled_hold import check_hold_temp_c

    what = "--temp-profile"
    kind, v = _numbers(text, what, {"ramp": (4,), "step": (2,)})
    if kind == "ramp":
        lo, hi, start, over = v
        _times(what, text, start, over)
        return Profile(check_hold_temp_c(lo), check_hold_temp_c(hi), start, over)
    _times(what, text, v[1])
    return Profile(math.nan, check_hold_temp_c(v[0]), v[1])


def parse_target_profile(text: str) -> Profile:
    """Parse ``step:TO:AT`` or ``ramp:FROM:TO:START:OVER`` (N, s); range-checked."""
    from relaxgrip.control import check_target_n

    what = "--target-profile"
    kind, v = _numbers(text, what, {"step": (2,), "ramp": (4,)})
    if kind == "step":
        _times(what, text, v[1])
        return Profile(math.nan, check_target_n(v[0]), v[1])
    _times(what, text, v[2], v[3])
    return Profile(check_target_n(v[0]), check_target_n(v[1]), v[2], v[3])


def parse_disturbance(text: str) -> Profile:
    """Parse ``push:FORCE:AT`` or ``push:FORCE:AT:FOR`` (N, s); |FORCE| <= 5 N."""
    what = "--disturbance"
    _, v = _numbers(text, what, {"push": (2, 3)})
    if abs(v[0]) > 5.0:
        raise InputError(f"{what} {text!r}: push must be within ±5 N")
    _times(what, text, *v[1:])
    until = v[1] + v[2] if len(v) == 3 else math.inf
    return Profile(0.0, v[0], v[1], 0.0, until)


def band_coverage(truth_n: NDArray[np.float64], lo_n: NDArray[np.float64],
                  hi_n: NDArray[np.float64]) -> float:
    """Share of the samples with a band (finite ``lo``, ``hi``) whose truth lies inside it.

    Returns
    -------
    float
        In [0, 1]; nan if no sample has a band.
    """
    has = np.isfinite(lo_n) & np.isfinite(hi_n) & np.isfinite(truth_n)
    if not has.any():
        return math.nan
    inside = (truth_n[has] >= lo_n[has]) & (truth_n[has] <= hi_n[has])
    return float(np.mean(inside))
