"""Benchmark of ``relaxgrip bringup`` on the twin of the second example rig."""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

from relaxgrip.bench.core import BenchResult

__all__ = ["BRINGUP_HOLD_S", "BRINGUP_TAKES", "bench_bringup"]

#: The benchmark's plan: data takes and the length of every hold (s).  The bring-up's
#: size is a parameter; its goal, 10 minutes on 2 cores, is quoted at this size.
BRINGUP_TAKES = 24
BRINGUP_HOLD_S = 100.0
#: The rig it brings up.
BRINGUP_RIG = Path(__file__).resolve().parents[3] / "docs" / "rigs" / "lab-125mm.toml"


def bench_bringup(repeat: int) -> BenchResult:
    """The whole bring-up (takes, dataset, training, observer, calibration, check, report)."""
    from relaxgrip.bringup import Bringup

    seconds: list[float] = []
    steps: dict[str, float] = {}
    last = [time.perf_counter()]

    def progress(step: str, done: int, total: int) -> None:
        now = time.perf_counter()
        kind = step.split("-")[0].removeprefix("take ")
        steps[kind] = steps.get(kind, 0.0) + now - last[0]
        last[0] = now

    for _ in range(max(1, repeat)):
        with tempfile.TemporaryDirectory() as tmp:
            last[0] = time.perf_counter()
            start = time.perf_counter()
            Bringup(BRINGUP_RIG, Path(tmp) / "bringup", takes=BRINGUP_TAKES,
                    hold_s=BRINGUP_HOLD_S, progress=progress).run()
            seconds.append(time.perf_counter() - start)
    return BenchResult(
        "bringup", f"relaxgrip bringup on the twin of lab-125mm: {BRINGUP_TAKES} data holds "
                   f"and 12 calibration holds of {BRINGUP_HOLD_S:g} s", seconds,
        notes={"seconds_by_step": steps},
        headline={"bringup_s_median": statistics.median(seconds)})
