"""Benchmark of the compiled firmware in simavr behind the emulator: its speed, and its watchdog."""

from __future__ import annotations

import statistics

import numpy as np

from relaxgrip.bench.core import BenchResult, timed_runs

__all__ = ["bench_firmware"]

#: Simulated seconds of one run: closing onto the ball, then holding it.
RUN_S = 40.0
#: Link losses injected into the firmware, for its watchdog's figures.
WATCHDOG_TRIALS = 100


def bench_firmware(repeat: int) -> BenchResult:
    """The firmware in simavr driving the twin (no images), a host at 30 Hz over the pty.

    A run closes on the force ball at 10 mm/s until it holds 5 N, then holds
    still, for 40 s of simulated time, the host sending GetStatus and Command
    each tick through the emulator's pseudo-terminal in lockstep.  Beside the
    speed, the report gives the firmware's image size, its stack's deepest
    reach and its watchdog's reaction over 100 injected link losses.
    """
    from relaxgrip.backend import Command
    from relaxgrip.clock import VirtualClock
    from relaxgrip.hardware.emulator import open_emulated_gripper
    from relaxgrip.hardware.firmware_sim import SimAvr, SimLink, watchdog_reactions
    from relaxgrip.hardware.protocol.codec import Hello
    from relaxgrip.twin import TwinConfig

    cfg = TwinConfig(initial_temp_c=40.0).without_sensors()
    image = None

    def run(seed: int) -> float:
        nonlocal image
        clock = VirtualClock()
        gripper, emu = open_emulated_gripper(cfg, seed, clock, firmware=True)
        try:
            assert emu.firmware is not None
            image = emu.firmware.sim.image
            gripper.reset()
            k = 0
            holding = False
            while clock.now() < RUN_S:
                obs = gripper.observe()
                assert obs.truth is not None
                holding = holding or obs.truth.contact_force_n >= 5.0
                gripper.act(Command(0.0 if holding else 10.0, (0.3, 0.3)))
                k += 1
                clock.sleep_until(k / 30.0)
            return clock.now()
        finally:
            gripper.close()

    times, simulated = timed_runs(run, repeat)
    assert image is not None
    with SimAvr(image) as sim:
        sim.run_for(0.002)
        link = SimLink(sim)
        link.send(Hello(1))
        reactions = np.array(watchdog_reactions(link, WATCHDOG_TRIALS,
                                                np.random.default_rng(5000))) * 1e3
        stack = sim.stack_bytes()
    factor = simulated / statistics.median(times)
    return BenchResult(
        "firmware",
        "the firmware in simavr driving the twin (no images) for 40 s: close on the ball to "
        "5 N and hold, the host at 30 Hz over the pty in lockstep",
        times,
        simulated_s=simulated,
        notes={
            "flash_bytes": image.flash_bytes,
            "static_ram_bytes": image.static_ram_bytes,
            "stack_bytes": stack,
            "watchdog_trials": WATCHDOG_TRIALS,
            "watchdog_within_limit": int(np.sum(reactions <= 200.0 + 1000.0 / 30.0)),
            "watchdog_median_ms": float(np.median(reactions)),
            "watchdog_max_ms": float(reactions.max()),
        },
        headline={"firmware_realtime_factor": factor},
    )
