"""The benchmark harness: timing, medians, the reference workload, profiles, the report.

Each benchmark runs its workload ``repeat`` times after one warm-up run and
reports the median (the machines are shared and noisy; medians are robust),
with min and max for spread.  Everything runs in one process on one core.

Absolute times move between machines and with the load of a shared one, so
every report also times a fixed NumPy workload (:func:`reference_workload`:
BLAS products, a sort, small-array calls from Python, in the proportions of
the twin's and the loop's own work) in the same run, before and after the
benchmarks, and gives each benchmark's median as a multiple of it
(``reference_ratio``): a figure two machines, or two loads, can compare.
"""

from __future__ import annotations

import cProfile
import functools
import platform
import pstats
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from relaxgrip.twin import TWIN_VERSION

__all__ = ["PROFILE_TOP", "BenchResult", "profile_top", "reference_workload", "run_benchmarks",
           "time_reference", "timed_runs"]

#: Functions listed per benchmark by ``--profile`` (the most self time first).
PROFILE_TOP = 15
#: Timed runs of the reference workload before and after the benchmarks (each).
REFERENCE_RUNS = 5


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


def reference_workload() -> float:
    """A fixed NumPy workload of about 0.1 s on one core; returns a checksum.

    Three parts, each a third or so of the time: 60 products of 160 x 160
    matrices (BLAS), a sort of 800,000 floats (memory), and 12,000 NumPy calls
    on 3-vectors from a Python loop (the interpreter's dispatch, which
    dominates the twin's step and the control loop).  The same inputs every
    time.
    """
    rng = np.random.default_rng(0)
    a = rng.standard_normal((160, 160)) / 16.0
    b = a
    for _ in range(60):
        b = a @ b
    x = rng.standard_normal(800_000)
    total = float(np.sort(x)[::4000].sum()) + float(b[0, 0])
    v = rng.standard_normal(3)
    w = np.array([0.3, -0.2, 0.1])
    for _ in range(6_000):
        total += float(v.dot(w))
        v = np.maximum(v * 0.999, w)
    return total


def time_reference(runs: int = REFERENCE_RUNS) -> list[float]:
    """Wall times (s) of ``runs`` runs of :func:`reference_workload` after one warm-up."""
    reference_workload()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        reference_workload()
        times.append(time.perf_counter() - t0)
    return times


def _function_label(key: tuple[str, int, str]) -> str:
    """``path:line(name)`` with the path from the package (or the library) down."""
    path, line, name = key
    for marker in ("/site-packages/", "/src/", "/lib/python"):
        if marker in path:
            path = path.split(marker, 1)[1]
            break
    return f"{path}:{line}({name})" if line else name


def profile_top(fn: Callable[[], Any], top: int = PROFILE_TOP) -> list[dict[str, Any]]:
    """Run ``fn`` under cProfile; the ``top`` functions by self time.

    Each entry: ``function`` (``path:line(name)``), ``calls``, ``self_s`` (time
    in the function itself), ``cumulative_s`` (with what it calls) and
    ``self_share`` (of the profiled run's total).
    """
    profiler = cProfile.Profile()
    profiler.enable()
    try:
        fn()
    finally:
        profiler.disable()
    stats = pstats.Stats(profiler)
    table: dict[Any, Any] = stats.stats  # type: ignore[attr-defined]
    total = sum(row[2] for row in table.values()) or 1.0
    rows = sorted(table.items(), key=lambda item: -item[1][2])[:top]
    return [{"function": _function_label(key), "calls": int(row[1]),
             "self_s": float(row[2]), "cumulative_s": float(row[3]),
             "self_share": float(row[2] / total)} for key, row in rows]


def run_benchmarks(
    benchmarks: dict[str, Callable[[int], BenchResult]], names: list[str], repeat: int,
    profile: bool = False,
) -> dict[str, Any]:
    """Run the named benchmarks on one thread; the report records machine and twin.

    Key figures of every benchmark are repeated at the report's top level.
    The reference workload is timed before and after the benchmarks; every
    benchmark's ``reference_ratio`` is its median over the reference's
    median.  With ``profile``, each benchmark runs once more (one timed run)
    under cProfile after its timing, and its entry gains ``profile``
    (:func:`profile_top`).
    """
    import cv2
    from threadpoolctl import threadpool_limits

    # One core: OpenCV's pool and OpenBLAS's workers (which spin after even tiny
    # products, occupying the second core) would otherwise blur every figure.
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    profiles: dict[str, list[dict[str, Any]]] = {}
    try:
        with threadpool_limits(limits=1):
            reference = time_reference()
            results = []
            for name in names:
                results.append(benchmarks[name](repeat))
                if profile:
                    profiles[name] = profile_top(functools.partial(benchmarks[name], 1))
            reference += time_reference()
    finally:
        cv2.setNumThreads(threads)
    reference_s = statistics.median(reference)
    report: dict[str, Any] = {
        "twin_version": TWIN_VERSION,
        "python": platform.python_version(),
        "machine": platform.machine(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "opencv_threads": 1,
        "repeat": repeat,
        "reference_s": reference_s,
        "reference_min_s": min(reference),
        "reference_max_s": max(reference),
    }
    for r in results:
        report.update(r.headline)
    report["benchmarks"] = []
    for r in results:
        entry = r.to_dict()
        entry["reference_ratio"] = r.median_s / reference_s
        if r.name in profiles:
            entry["profile"] = profiles[r.name]
        report["benchmarks"].append(entry)
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
