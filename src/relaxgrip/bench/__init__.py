"""Benchmarks behind ``relaxgrip bench``: speed goals are measured here, never in tests."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from relaxgrip.bench import core
from relaxgrip.bench.bringup import bench_bringup
from relaxgrip.bench.control import bench_control_hold
from relaxgrip.bench.core import BenchResult
from relaxgrip.bench.firmware import bench_firmware
from relaxgrip.bench.learning import bench_estimation, bench_learning_pipeline
from relaxgrip.bench.material import bench_material
from relaxgrip.bench.perception import bench_perception
from relaxgrip.bench.twin import bench_twin_hold, bench_twin_step

__all__ = ["BENCHMARKS", "DEFAULT_BENCHMARKS", "BenchResult", "run_benchmarks"]

#: Benchmark name -> function of the repeat count.
BENCHMARKS: dict[str, Callable[[int], BenchResult]] = {
    "twin-hold": bench_twin_hold,
    "twin-step": bench_twin_step,
    "perception": bench_perception,
    "estimation": bench_estimation,
    "learning-pipeline": bench_learning_pipeline,
    "control-hold": bench_control_hold,
    "firmware": bench_firmware,
    "bringup": bench_bringup,
    "material": bench_material,
}
#: What ``relaxgrip bench`` runs without names: everything that takes seconds, not minutes.
DEFAULT_BENCHMARKS: tuple[str, ...] = ("twin-hold", "twin-step", "perception", "estimation")


def run_benchmarks(names: list[str], repeat: int, profile: bool = False) -> dict[str, Any]:
    """Run the named benchmarks; see :func:`relaxgrip.bench.core.run_benchmarks`."""
    return core.run_benchmarks(BENCHMARKS, names, repeat, profile=profile)
