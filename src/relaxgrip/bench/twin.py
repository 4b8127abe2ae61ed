"""Benchmarks of the digital twin without images: how much faster than real time it runs."""

from __future__ import annotations

import statistics

from relaxgrip.bench.core import BenchResult, timed_runs

__all__ = ["bench_twin_hold", "bench_twin_step"]


def bench_twin_hold(repeat: int) -> BenchResult:
    """The paper's 280 s fixed-aperture hold at 5 N, 40 °C, on the twin without images."""
    from relaxgrip.experiments.holding import HoldTrace, run_fixed_aperture_hold

    def hold(seed: int) -> HoldTrace:
        return run_fixed_aperture_hold(40.0, 5.0, 280.0, seed=seed)

    times, trace = timed_runs(hold, repeat)
    simulated = trace.onset_s + float(trace.t_s[-1])  # the closing is in the run too
    return BenchResult(
        "twin-hold",
        "close to 5 N at 40 °C, hold 280 s at 30 Hz (observe + act each tick, no sensors)",
        times,
        simulated_s=simulated,
        notes={"ticks_per_run": int(trace.t_s.size), "closing_s": trace.onset_s},
        headline={"twin_hold_realtime_factor": simulated / statistics.median(times)},
    )


def bench_twin_step(repeat: int) -> BenchResult:
    """Bare physics: 280 s of twin steps at 30 Hz holding a grasp, no loop around it."""
    from relaxgrip.backend import Command
    from relaxgrip.clock import VirtualClock
    from relaxgrip.twin import GripperTwin, TwinConfig

    n = 280 * 30
    dt = 1.0 / 30.0

    def run(seed: int) -> tuple[float, int]:
        clock = VirtualClock()
        cfg = TwinConfig(initial_temp_c=40.0).without_sensors()
        twin = GripperTwin(cfg, seed=seed, clock=clock)
        twin.act(Command(20.0, (0.3, 0.3)))  # close onto the ball until it holds 5 N
        ticks = 0
        while twin.observe().truth.contact_force_n < 5.0:  # type: ignore[union-attr]
            clock.advance(dt)
            ticks += 1
        twin.act(Command(0.0, (0.3, 0.3)))
        for _ in range(n):
            clock.advance(dt)
            twin.observe()
        return clock.now(), ticks + 1 + n

    times, (simulated, ticks) = timed_runs(run, repeat)
    return BenchResult(
        "twin-step",
        "GripperTwin.observe at 30 Hz closing to 5 N on the ball, then 280 s holding it "
        "(per-tick physics only)",
        times,
        simulated_s=simulated,
        notes={"us_per_tick": statistics.median(times) / ticks * 1e6},
    )
