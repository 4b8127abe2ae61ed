"""Validators for values that come from outside (``check_*`` for one value,
``parse_*`` for a list given as text): return the cleaned value or raise
:class:`relaxgrip.errors.InputError` with a one-line message."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

from relaxgrip.errors import InputError

ABSOLUTE_ZERO_C = -273.15

__all__ = ["MAX_JOBS", "check_duty", "check_finite", "check_jobs", "check_positive", "check_seeds",
           "check_temp_c", "parse_floats", "parse_integer", "parse_names", "parse_number",
           "parse_seeds"]

#: A number as people and instruments write one: ASCII digits, an optional sign, point and
#: exponent, or inf / nan (which the range checks then name).  Python's float() and int()
#: also take "1_000" and other scripts' digits: "0_5" for a force would be 5 N.
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?(?:inf(?:inity)?|nan)",
                     re.ASCII | re.IGNORECASE)
_INTEGER = re.compile(r"[+-]?\d+", re.ASCII)


def parse_number(text: str) -> float:
    """``float(text)`` for a number written the usual way (``_NUMBER``).

    Raises
    ------
    ValueError
        As ``float`` does, also for ``1_000`` and non-ASCII digits.
    """
    return float(_matched(text, _NUMBER, "a number"))


def parse_integer(text: str) -> int:
    """``int(text)`` for ASCII digits with an optional sign.

    Raises
    ------
    ValueError
        As ``int`` does, also for ``1_0`` and non-ASCII digits.
    """
    return int(_matched(text, _INTEGER, "an integer"))


def _matched(text: str, pattern: re.Pattern[str], what: str) -> str:
    """``text`` stripped, if ``pattern`` matches all of it; else ValueError naming ``what``."""
    stripped = text.strip()
    if not pattern.fullmatch(stripped):
        raise ValueError(f"{text!r} is not {what}")
    return stripped


def check_finite(value: float, name: str) -> float:
    """Return ``value`` as a float if it is finite."""
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{name} must be a finite number, got {value}")
    return v


def check_positive(value: float, name: str) -> float:
    """Return ``value`` if it is finite and > 0."""
    v = check_finite(value, name)
    if v <= 0:
        raise InputError(f"{name} must be > 0, got {value}")
    return v


def check_temp_c(value: float, name: str = "temperature") -> float:
    """Return a temperature in °C if it is physical (above absolute zero)."""
    v = check_finite(value, name)
    if v <= ABSOLUTE_ZERO_C:
        raise InputError(
            f"{name} {v} °C is {v - ABSOLUTE_ZERO_C:.2f} K: below absolute zero"
        )
    return v


def check_duty(value: float, name: str = "heater duty") -> float:
    """Return a PWM duty if it lies in [0, 1]."""
    v = check_finite(value, name)
    if not 0.0 <= v <= 1.0:
        raise InputError(f"{name} {value} is outside 0-1")
    return v


#: The most worker processes a command starts: each is a Python process of a few hundred
#: MB doing CPU-bound work, and joblib's pool cannot count past a C int (a larger
#: ``--jobs`` had ended ``dataset build`` in a traceback).
MAX_JOBS = 256


def check_jobs(value: int, name: str = "--jobs") -> int:
    """Return a count of parallel workers if it is from 1 to :data:`MAX_JOBS`."""
    if value < 1:
        raise InputError(f"{name} must be >= 1, got {value}")
    if value > MAX_JOBS:
        raise InputError(f"{name} must be at most {MAX_JOBS} worker processes, got {value}")
    return value


#: The most seeds one command takes: each is a run of minutes.
MAX_SEEDS = 10_000


def parse_seeds(text: str) -> list[int]:
    """Seeds from ``10-15``, ``3,5,8`` or a mix (``0-2,7``); non-negative, no repeats.

    Raises
    ------
    InputError
        Anything else.
    """
    seeds: list[int] = []
    for part in text.split(","):
        lo, sep, hi = part.strip().partition("-")
        # ASCII digits only: int() also takes "５", "1_0" and "+3", which no one means as a seed.
        if not all(n.isascii() and n.isdigit() for n in ((lo, hi) if sep else (lo,))):
            raise InputError(f"seeds must look like 10-15 or 3,5,8, got {text!r}")
        first = int(lo)
        last = int(hi) if sep else first
        if first < 0 or last < first:
            raise InputError(f"seed range {part.strip()!r} must be non-negative and ascending")
        if len(seeds) + last - first + 1 > MAX_SEEDS:
            raise InputError(f"at most {MAX_SEEDS} seeds (each is a run), got more in {text!r}")
        seeds.extend(range(first, last + 1))
    if len(set(seeds)) != len(seeds):
        raise InputError(f"seeds repeat in {text!r}")
    return seeds


def check_seeds(seeds: Sequence[int]) -> None:
    """Refuse a negative seed, or one given twice: each seed is one run, and a run counted
    twice passes for two that agree (no spread, or its own bias taken for the others').

    Raises
    ------
    InputError
        A negative or repeated seed (not an empty list: each caller says what needs one).
    """
    if seeds and min(seeds) < 0:
        raise InputError(f"seeds must be >= 0, got {min(seeds)}")
    if len(set(seeds)) != len(seeds):
        raise InputError(f"seeds repeat in {list(seeds)}: give each seed once")


def parse_floats(text: str, name: str) -> list[float]:
    """Finite numbers from ``1,3,5,8``; at least one, no repeats.

    Raises
    ------
    InputError
        Naming ``name`` (the flag) and the text.
    """
    values: list[float] = []
    for part in text.split(","):
        try:
            value = parse_number(part)
        except ValueError:
            raise InputError(f"{name} must be numbers like 1,3,5,8, got {text!r}") from None
        if not math.isfinite(value):
            raise InputError(f"{name} must be finite numbers, got {part.strip()!r}")
        values.append(value)
    if len(set(values)) != len(values):
        raise InputError(f"{name} repeats a value in {text!r}")
    return values


def parse_names(text: str, name: str) -> list[str]:
    """Names from ``standard,ramp``; at least one, none empty, no repeats.

    Whether each is a known one is for the caller to check.

    Raises
    ------
    InputError
        Naming ``name`` (the flag) and the text.
    """
    names = [part.strip() for part in text.split(",")]
    if "" in names:
        raise InputError(f"{name} has an empty item in {text!r}: give names like a,b")
    if len(set(names)) != len(names):
        raise InputError(f"{name} repeats a name in {text!r}")
    return names
