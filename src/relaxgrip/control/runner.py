"""The loop runner: any :class:`~relaxgrip.backend.Gripper` through the grasp controller, in time.

At every camera period the runner observes the backend, lets the
:class:`~relaxgrip.control.controller.GraspController` decide, applies the
command and records everything: the controller's view (estimates, commands,
phase, temperatures read) and, where the backend has it, the ground truth
(which the controller never sees).  The clock is injected: a
:class:`~relaxgrip.clock.VirtualClock` runs as fast as the CPU allows, a
:class:`~relaxgrip.clock.WallClock` in real time.  However the loop ends (done,
out of time, an exception, Ctrl-C), the motor is stopped and the heaters are
switched off before the runner returns or raises.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import BackendInfo, Command, Gripper, Observation
from relaxgrip.clock import Clock
from relaxgrip.control.controller import GraspController, GraspPlan
from relaxgrip.control.phases import PHASES, GraspPhase, PhaseLog
from relaxgrip.perception.marker import TrackStatus

FloatArray = NDArray[np.float64]

__all__ = ["LoopInterrupted", "LoopRecorder", "LoopResult", "run_loop"]

_STATUS = tuple(TrackStatus)
_COLUMNS = (
    "t_s", "phase", "motor_mm", "arm_mm", "velocity_cmd_mm_s", "arm_cmd_mm_s", "duty_0", "duty_1",
    "estimate_n", "icfn_n", "f_onset_n", "k_n", "tau_s", "hold_s", "ir_temp_0_c", "ir_temp_1_c",
    "setpoint_c", "band_lo_n", "band_hi_n", "band_drift_n", "calibration_n", "chain_n",
    "marker_status",
    "truth_force_n", "truth_temp_0_c", "truth_temp_1_c", "truth_aperture_mm", "truth_lifted",
    "force_ref_n", "force_ref_t_s",
)


@dataclass(frozen=True)
class LoopResult:
    """Every time series of one run, at the control rate.

    Attributes
    ----------
    backend : BackendInfo
        Which backend ran.
    estimator : str
        Name of the force estimator.
    plan : GraspPlan
        What the grasp was asked to do.
    series : dict of str to ndarray
        Columns (see :data:`COLUMNS`): time (s), phase code (index into
        :data:`relaxgrip.control.phases.PHASES`), encoder (mm), arm height
        (mm), commands (mm/s, duty), the estimate and its parts (N, s),
        infrared finger temperatures (°C), setpoint (°C, nan when off), the
        estimate's band and calibration (N), marker status code, the
        truth (nan when the backend has none), and the force reference's
        latest reading of the period with its own time (N, s; nan in a
        period that brought none).
    log : PhaseLog
        Phase transitions and events.
    """

    backend: BackendInfo
    estimator: str
    plan: GraspPlan
    series: dict[str, FloatArray]
    log: PhaseLog

    COLUMNS = _COLUMNS

    def __getitem__(self, name: str) -> FloatArray:
        return self.series[name]

    def phase_at(self, index: int) -> GraspPhase:
        """The phase of sample ``index``."""
        return PHASES[int(self.series["phase"][index])]

    def hold_onset_s(self) -> float | None:
        """Time of the estimator's hold onset, if the run reached it."""
        hold = self.series["hold_s"]
        idx = np.flatnonzero(np.isfinite(hold))
        if idx.size == 0:
            return None
        return float(self.series["t_s"][idx[0]] - hold[idx[0]])

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python summary (no arrays)."""
        return {"backend": self.backend.name, "backend_version": self.backend.version,
                "estimator": self.estimator, "samples": int(self.series["t_s"].size),
                "log": self.log.to_dict()}


class LoopInterrupted(KeyboardInterrupt):
    """Ctrl-C, ``kill`` or a hang-up stopped :func:`run_loop`: the motor is stopped, the
    heaters off, and :attr:`result` holds the run up to the last period it completed.

    A ``KeyboardInterrupt``: a caller that does not look for the partial run stops as
    on Ctrl-C.
    """

    def __init__(self, result: LoopResult) -> None:
        super().__init__("interrupted")
        self.result = result


class LoopRecorder(Protocol):
    """Something that records a run as it goes (e.g. :class:`relaxgrip.recording.McapRecorder`).

    It only records: it must not change the controller, the backend or the command.
    """

    def start(self, info: BackendInfo, controller: GraspController, t_s: float) -> None:
        """The run starts at ``t_s`` (the controller has just been started)."""
        ...

    def step(self, obs: Observation, controller: GraspController, command: Command) -> None:
        """One control period has been decided (``command`` applied)."""
        ...


def _force_ref_row(obs: Observation) -> tuple[float, float]:
    ref = obs.force_ref
    if ref is None or not ref.force_n.size:
        return (math.nan, math.nan)
    return (float(ref.force_n[-1]), float(ref.t_s[-1]))


def _truth_row(obs: Observation) -> tuple[float, float, float, float, float]:
    truth = obs.truth
    if truth is None:
        return (math.nan,) * 5
    temps = [sum(f) / len(f) for f in truth.finger_temps_c]
    return (truth.contact_force_n, temps[0], temps[1], truth.aperture_m * 1e3,
            float(truth.object_lifted))


def run_loop(
    backend: Gripper,
    controller: GraspController,
    clock: Clock,
    plan: GraspPlan | None,
    max_duration_s: float,
    rate_hz: float = 30.0,
    on_step: Callable[[Observation, GraspController], bool | None] | None = None,
    recorder: LoopRecorder | None = None,
) -> LoopResult:
    """Run one grasp until it is done or ``max_duration_s`` has passed.

    Parameters
    ----------
    backend : Gripper
        The gripper (reset by the caller).
    controller : GraspController
        The host loop.
    clock : Clock
        The backend's clock (virtual or wall).
    plan : GraspPlan or None
        The grasp to run; ``None``: the grasp the controller is running goes on
        (a run taken over mid-grasp, as the fault matrix does).
    max_duration_s : float
        Time limit (s).
    rate_hz : float
        Control rate (the camera's).
    on_step : callable, optional
        Called after every step with the observation and the controller;
        returning ``True`` ends the run (an experiment's own stop condition).
    recorder : LoopRecorder, optional
        Told of the start and of every period, the last one included.

    Returns
    -------
    LoopResult

    Raises
    ------
    LoopInterrupted
        On ``KeyboardInterrupt`` (the stop signals of :mod:`relaxgrip.interrupts`),
        with the run so far; the motor stopped and the heaters off first.
    """
    dt = 1.0 / rate_hz
    t0 = clock.now()
    if plan is not None:
        controller.start(plan, t0)
    if recorder is not None:
        recorder.start(backend.info, controller, t0)
    rows: list[tuple[float, ...]] = []
    # Rounded to 1e-9 first: 8.3 s at 30 Hz is 249.00000000000003 periods, not 250.
    n_steps = math.ceil(round(max_duration_s * rate_hz, 9))
    # A period's work longer than the period (wall-clock time) makes the steps late:
    # the run ends by the clock, one period past its last step's time at most.
    deadline = t0 + (n_steps + 1) * dt
    interrupted = False
    try:
        for k in range(n_steps + 1):
            if k > 0 and clock.now() > deadline:
                break
            obs = backend.observe()
            command = controller.step(obs)
            backend.act(command)
            rows.append(_row(obs, controller, command))
            if recorder is not None:
                recorder.step(obs, controller, command)
            if controller.phase in (GraspPhase.DONE, GraspPhase.STOPPED):
                break
            if on_step is not None and on_step(obs, controller):
                break
            clock.sleep_until(t0 + (k + 1) * dt)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        backend.act(Command())  # motor stopped, heaters off, whatever happened
    columns = zip(*rows, strict=True) if rows else ((),) * len(_COLUMNS)
    series = {name: np.array(col, dtype=np.float64)
              for name, col in zip(_COLUMNS, columns, strict=True)}
    result = LoopResult(backend.info, controller.estimator.name, controller.plan, series,
                        controller.log)
    if interrupted:
        raise LoopInterrupted(result)
    return result


def _row(obs: Observation, c: GraspController, command: Command) -> tuple[float, ...]:
    est = c.estimate
    percept = c.percept
    temps = (math.nan, math.nan)
    status = float(_STATUS.index(TrackStatus.INVALID))
    if percept is not None:
        status = float(_STATUS.index(percept.marker.status))
        if percept.thermal is not None:
            temps = c.temperature.readings_c(percept.thermal)  # type: ignore[assignment]
    setpoint = c.temperature.setpoint_c
    return (
        obs.t_s, float(PHASES.index(c.phase)), obs.motor_position_mm, obs.arm_height_mm,
        command.motor_velocity_mm_s, command.arm_velocity_mm_s, *command.heater_duty,
        est.force_n, est.f_icfn_n, est.f_onset_n, est.k_n, est.tau_s, est.hold_s, *temps,
        math.nan if setpoint is None else setpoint, est.band_lo_n, est.band_hi_n,
        est.band_drift_n, est.calibration_n, est.chain_n, status,
        *_truth_row(obs), *_force_ref_row(obs),
    )
