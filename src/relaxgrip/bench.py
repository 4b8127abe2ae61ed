"""Benchmarks behind ``relaxgrip bench``: speed goals are measured here, never in tests.

Each benchmark runs its workload ``repeat`` times after one warm-up run and
reports the median (the machines are shared and noisy; medians are robust),
with min and max for spread.  Everything runs in one process on one core.
"""

from __future__ import annotations

import platform
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from relaxgrip.twin import TWIN_VERSION

__all__ = ["BENCHMARKS", "BenchResult", "run_benchmarks"]


@dataclass(frozen=True)
class BenchResult:
    """Timing of one benchmark.

    Attributes
    ----------
    name : str
        Benchmark name.
    unit : str
        What one run measures ("s per run").
    seconds : list of float
        Wall time of every timed run (s).
    simulated_s : float
        Simulated seconds per run (0 when not a simulation).
    notes : dict
        Extra figures of the workload.
    """

    name: str
    description: str
    seconds: list[float]
    simulated_s: float = 0.0
    notes: dict[str, Any] = field(default_factory=dict)

    @property
    def median_s(self) -> float:
        """Median wall time of a run (s)."""
        return statistics.median(self.seconds)

    @property
    def realtime_factor(self) -> float | None:
        """Simulated over wall time at the median run, if a simulation."""
        return self.simulated_s / self.median_s if self.simulated_s else None

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form for ``--json``."""
        return {
            "name": self.name,
            "description": self.description,
            "runs": len(self.seconds),
            "median_s": self.median_s,
            "min_s": min(self.seconds),
            "max_s": max(self.seconds),
            "simulated_s": self.simulated_s,
            "realtime_factor": self.realtime_factor,
            **self.notes,
        }


def _timed(fn: Callable[[int], Any], repeat: int) -> tuple[list[float], Any]:
    last = fn(repeat)  # warm-up (imports, caches) on a seed the timed runs do not use
    times = []
    for k in range(repeat):
        t0 = time.perf_counter()
        last = fn(k)
        times.append(time.perf_counter() - t0)
    return times, last


def bench_twin_hold(repeat: int) -> BenchResult:
    """The paper's 280 s fixed-aperture hold at 5 N, 40 °C, on the twin without images."""
    from relaxgrip.experiments.holding import run_fixed_aperture_hold

    times, trace = _timed(lambda seed: run_fixed_aperture_hold(40.0, 5.0, 280.0, seed=seed), repeat)
    return BenchResult(
        "twin-hold",
        "close to 5 N at 40 °C, hold 280 s at 30 Hz (observe + act each tick, no images)",
        times,
        simulated_s=280.0,
        notes={"ticks_per_run": int(trace.t_s.size)},
    )


def bench_twin_step(repeat: int) -> BenchResult:
    """Bare physics: 280 s of twin steps at 30 Hz holding a grasp, no loop around it."""
    from relaxgrip.backend import Command
    from relaxgrip.clock import VirtualClock
    from relaxgrip.twin import GripperTwin, TwinConfig

    n = 280 * 30

    def run(seed: int) -> None:
        clock = VirtualClock()
        cfg = TwinConfig(initial_temp_c=40.0).without_cameras()
        twin = GripperTwin(cfg, seed=seed, clock=clock)
        twin.act(Command(20.0, (0.3, 0.3)))
        clock.advance(4.5)  # close onto the ball
        twin.act(Command(0.0, (0.3, 0.3)))
        for _ in range(n):
            clock.advance(1.0 / 30.0)
            twin.observe()

    times, _ = _timed(run, repeat)
    return BenchResult(
        "twin-step",
        "GripperTwin.observe at 30 Hz for 280 s holding the ball (per-tick physics only)",
        times,
        simulated_s=284.5,
        notes={"us_per_tick": statistics.median(times) / (n + 1) * 1e6},
    )


BENCHMARKS: dict[str, Callable[[int], BenchResult]] = {
    "twin-hold": bench_twin_hold,
    "twin-step": bench_twin_step,
}


def run_benchmarks(names: list[str], repeat: int) -> dict[str, Any]:
    """Run the named benchmarks; the report records the machine and the twin version."""
    results = [BENCHMARKS[name](repeat) for name in names]
    return {
        "twin_version": TWIN_VERSION,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "repeat": repeat,
        "benchmarks": [r.to_dict() for r in results],
    }
