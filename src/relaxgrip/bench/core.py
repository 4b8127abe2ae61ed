"""The benchmark harness: timing, medians, the report.

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

__all__ = ["BenchResult", "run_benchmarks", "timed_runs"]


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
    headline : dict
        Key figures, also reported at the top level of the report.
    """

    name: str
    description: str
    seconds: list[float]
    simulated_s: float = 0.0
    notes: dict[str, Any] = field(default_factory=dict)
    headline: dict[str, Any] = field(default_factory=dict)

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
            **self.headline,
        }


def run_benchmarks(
    benchmarks: dict[str, Callable[[int], BenchResult]], names: list[str], repeat: int
) -> dict[str, Any]:
    """Run the named benchmarks on one thread; the report records machine and twin.

    Key figures of every benchmark are repeated at the report's top level.
    """
    import cv2
    from threadpoolctl import threadpool_limits

    # One core: OpenCV's pool and OpenBLAS's workers (which spin after even tiny
    # products, occupying the second core) would otherwise blur every figure.
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with threadpool_limits(limits=1):
            results = [benchmarks[name](repeat) for name in names]
    finally:
        cv2.setNumThreads(threads)
    report: dict[str, Any] = {
        "twin_version": TWIN_VERSION,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "opencv": cv2.__version__,
        "opencv_threads": 1,
        "repeat": repeat,
    }
    for r in results:
        report.update(r.headline)
    report["benchmarks"] = [r.to_dict() for r in results]
    return report


def timed_runs(fn: Callable[[int], Any], repeat: int) -> tuple[list[float], Any]:
    """Wall time of ``repeat`` runs of ``fn(k)`` after one warm-up run, and the last result."""
    last = fn(repeat)  # warm-up (imports, caches) on a seed the timed runs do not use
    times = []
    for k in range(repeat):
        t0 = time.perf_counter()
        last = fn(k)
        times.append(time.perf_counter() - t0)
    return times, last
