"""Benchmark of the whole closed loop with rendered images: the paper's 280 s hold."""

from __future__ import annotations

import statistics

from relaxgrip.bench.core import BenchResult, timed_runs

__all__ = ["bench_control_hold"]


def bench_control_hold(repeat: int) -> BenchResult:
    """A 280 s relaxation-aware hold at 5 N, 40 °C: render, perceive, estimate, control at 30 Hz."""
    from relaxgrip.experiments.controlled_hold import HoldResult, run_hold
    from relaxgrip.learning.training import load_default_models

    models = load_default_models()

    def hold(seed: int) -> HoldResult:
        return run_hold("relax", 5.0, 280.0, 40.0, seed=seed, models=models)

    times, result = timed_runs(hold, repeat)
    simulated = float(result.loop["t_s"][-1] - result.loop["t_s"][0])
    steps = int(result.loop["t_s"].size)
    return BenchResult(
        "control-hold",
        "zero, close to 5 N and hold 280 s at 40 °C with rendered RGB (30 Hz) and IR (1 Hz) "
        "frames through perception, ICFN + RCFN, force and temperature PID",
        times,
        simulated_s=simulated,
        notes={"steps_per_run": steps, "ms_per_step": statistics.median(times) / steps * 1e3},
        headline={"control_hold_realtime_factor": simulated / statistics.median(times)},
    )
