"""Bring-up of a rig: the plan of recorded holds, and one take of it, on the twin or the rig.

A new gripper has no models of its own.  Its bring-up records holds at a
fixed aperture over the forces, temperatures and contact positions its rig
file allows (:func:`plan_for_rig`), each labelled by the rig's force
reference, so that the dataset, the ICFN, the RCFN and the observer are
learned from that gripper alone; then a few regulated holds for the
closed-loop calibration and one check hold.

A take (:func:`record_take`) is a ``fixed`` grasp: the controller closes on
the force ball and, at contact, holds the aperture.  Its closing stops when
the force reference reads the take's force (the experiment's stop condition,
like its plan; the controller and the estimator never read the reference:
:meth:`~relaxgrip.control.GraspController.hold` is what the operator's "hold
now" is on the dashboard).  Were it stopped by the ICFN's estimate instead,
the shipped ICFN, fitted on another finger, would set the forces of the
data meant to replace it.

Recordings carry no truth, on the twin either: a bring-up on the twin is
the rehearsal of one on the rig, and its data, models and calibration rest
on the force reference alone (:class:`TruthlessRecorder`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from relaxgrip.backend import Command, Gripper, Observation
from relaxgrip.clock import Clock, VirtualClock
from relaxgrip.control import (
    EstimatorKind,
    GraspController,
    GraspPhase,
    GraspPlan,
    LoopResult,
    bundle_estimator,
    run_loop,
    twin_limits,
)
from relaxgrip.errors import InputError
from relaxgrip.hardware.rig_file import RigFile
from relaxgrip.learning.store import ModelBundle
from relaxgrip.perception.proximity import ProximityTarget
from relaxgrip.recording import McapRecorder
from relaxgrip.twin import GripperTwin, TwinConfig

__all__ = [
    "MAX_CALIBRATION_HOLDS",
    "BringupPlan",
    "Take",
    "TruthlessRecorder",
    "plan_for_rig",
    "record_take",
]

#: Most regulated holds the calibration takes.
MAX_CALIBRATION_HOLDS = 12
#: Contact positions of the plan, as shares of the rig's usual contact (``[finger] contact_mm``).
CONTACT_SHARES = (0.85, 1.0, 1.12)
#: Finger temperatures of the plan (°C), each clipped to the rig's setpoint limits.
PLAN_TEMPS_C = (30.0, 40.0, 50.0, 58.0)
#: Lowest force of the plan (N) and its highest, as a share of the rig's largest target.
PLAN_MIN_FORCE_N = 1.0
PLAN_MAX_FORCE_SHARE = 0.8
#: Highest planned force (N): the datasets reach 8 N (paper §V-A).
PLAN_MAX_FORCE_N = 8.0
#: Time allowed to reach a take's hold, on top of it (s): heating from room temperature
#: on a rig (the twin starts at the take's temperature).
SETUP_ALLOWANCE_S = 300.0
#: The loop's rate, the camera's (Hz).
RATE_HZ = 30.0


@dataclass(frozen=True)
class Take:
    """One recorded hold of the plan.

    Attributes
    ----------
    index : int
        Its place in the plan.
    kind : str
        ``data`` (a fixed-aperture hold for the dataset), ``calibration`` (a
        regulated ``relax`` hold) or ``check``.
    force_n : float
        Force to close to (N): where the force reference stops the closing
        (``data``), the target (otherwise).
    temp_c : float
        Finger temperature (°C).
    contact_mm : float
        Where the force ball sits along the fingers (mm from the root).
    seed : int
        Twin seed (the twin only).
    """

    index: int
    kind: str
    force_n: float
    temp_c: float
    contact_mm: float
    seed: int

    @property
    def name(self) -> str:
        """Its recording's file name."""
        return f"{self.kind}-{self.index:03d}.mcap"

    def instruction(self) -> str:
        """What the operator does before it (a serial rig)."""
        return (f"place the force ball {self.contact_mm:.0f} mm from the finger root, nothing "
                f"touching it; the fingers heat to {self.temp_c:g} °C, close to "
                f"{self.force_n:g} N and hold")

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form (the bring-up's state file)."""
        return {"index": self.index, "kind": self.kind, "force_n": self.force_n,
                "temp_c": self.temp_c, "contact_mm": self.contact_mm, "seed": self.seed}


@dataclass(frozen=True)
class BringupPlan:
    """Every hold of a bring-up.

    Attributes
    ----------
    data : tuple of Take
        Fixed-aperture holds for the dataset.
    calibration : tuple of Take
        Regulated ``relax`` holds for the closed-loop calibration, two or
        more at each target and temperature.
    check : Take
        The hold that checks the calibrated models.
    hold_s : float
        Length of every hold (s).
    """

    data: tuple[Take, ...]
    calibration: tuple[Take, ...]
    check: Take
    hold_s: float

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form."""
        return {"hold_s": self.hold_s, "data": [t.to_dict() for t in self.data],
                "calibration": [t.to_dict() for t in self.calibration],
                "check": self.check.to_dict()}


def _levels(values: tuple[float, ...], lo: float, hi: float) -> list[float]:
    """``values`` clipped to ``[lo, hi]``, repeats dropped, in order."""
    out: list[float] = []
    for v in values:
        c = min(max(v, lo), hi)
        if not any(abs(c - o) < 1e-9 for o in out):
            out.append(c)
    return out


def plan_for_rig(rig: RigFile, takes: int = 24, hold_s: float = 100.0, seed: int = 0,
                 calibration_holds: int = MAX_CALIBRATION_HOLDS) -> BringupPlan:
    """The bring-up plan of ``rig``: forces, temperatures and contact positions it allows.

    The data takes cycle through the temperatures (:data:`PLAN_TEMPS_C`
    within the rig's setpoint limits) and the contact positions
    (:data:`CONTACT_SHARES` of its usual contact, within the finger), every
    combination in turn; their forces are stratified over
    ``PLAN_MIN_FORCE_N .. min(8 N, 0.8 x max_target_n)`` in a seeded order,
    so that any prefix of the plan spreads over the range.  The calibration
    holds two (or more) of each of the targets 3, 5 and 7 N (those the rig
    allows) at 40 and 50 °C, at the usual contact; the check holds 5 N at
    40 °C.

    Parameters
    ----------
    rig : RigFile
        The rig.
    takes : int
        Data takes (4-400): the plan's size.
    hold_s : float
        Length of every hold (s), 20-280.
    seed : int
        Seed of the force order and of the twin's runs (design seeds: 0-4999).
    calibration_holds : int
        Regulated holds of the calibration, 4 to :data:`MAX_CALIBRATION_HOLDS`.

    Raises
    ------
    InputError
        A size or length out of range.
    """
    if not 4 <= takes <= 400:
        raise InputError(f"a bring-up plan takes 4-400 data holds, got {takes}")
    if not (math.isfinite(hold_s) and 20.0 <= hold_s <= 280.0):
        raise InputError(f"bring-up holds last 20-280 s, got {hold_s}")
    if not 4 <= calibration_holds <= MAX_CALIBRATION_HOLDS:
        raise InputError(f"the calibration takes 4-{MAX_CALIBRATION_HOLDS} holds, "
                         f"got {calibration_holds}")
    if seed < 0:
        raise InputError(f"--seed must be >= 0, got {seed}")
    limits = rig.limits
    temps = _levels(PLAN_TEMPS_C, limits.min_setpoint_c, min(limits.max_setpoint_c, 60.0))
    usual_mm = rig.finger.contact_m * 1e3
    tip_mm = rig.finger.length_m * 1e3
    positions = _levels(tuple(usual_mm * s for s in CONTACT_SHARES), 0.3 * tip_mm,
                        tip_mm - 0.6 * rig.force_ball.width_m * 1e3)
    f_hi = min(PLAN_MAX_FORCE_N, PLAN_MAX_FORCE_SHARE * limits.max_target_n)
    f_lo = min(PLAN_MIN_FORCE_N, 0.5 * f_hi)
    rng = np.random.default_rng([seed, 63])
    strata = rng.permutation(takes)
    jitter = rng.uniform(0.0, 1.0, takes)
    data = []
    for k in range(takes):
        force = f_lo + (f_hi - f_lo) * (strata[k] + jitter[k]) / takes
        data.append(Take(k, "data", round(float(force), 2), temps[k % len(temps)],
                         round(positions[(k // len(temps)) % len(positions)], 1), seed + k))
    targets = [t for t in (3.0, 5.0, 7.0) if t <= limits.max_target_n] or [limits.max_target_n]
    cal_temps = _levels((40.0, 50.0), limits.min_setpoint_c, limits.max_setpoint_c)
    grid = [(f, c) for f in targets for c in cal_temps]
    while len(grid) * 2 > calibration_holds and len(grid) > 1:
        grid = grid[:-1] if len(targets) == 1 else [g for g in grid if g[0] != targets[-1]]
        targets = sorted({f for f, _ in grid})
    repeats = max(2, calibration_holds // len(grid))
    calibration = tuple(
        Take(i, "calibration", f, c, round(usual_mm, 1), seed + 1000 + i)
        for i, (f, c) in enumerate((f, c) for f, c in grid for _ in range(repeats)))
    check_target = 5.0 if limits.max_target_n >= 5.0 else targets[0]
    check_temp = min(max(40.0, limits.min_setpoint_c), limits.max_setpoint_c)
    check = Take(0, "check", check_target, check_temp, round(usual_mm, 1), seed + 2000)
    return BringupPlan(tuple(data), calibration, check, hold_s)


class TruthlessRecorder(McapRecorder):
    """An MCAP recorder that leaves the twin's truth out: the recording of a real rig."""

    def step(self, obs: Observation, controller: GraspController, command: Command) -> None:
        """Record the period without ``obs.truth``."""
        super().step(replace(obs, truth=None), controller, command)


def _latest_ref_n(obs: Observation) -> float:
    ref = obs.force_ref
    if ref is None or not ref.force_n.size:
        return math.nan
    return float(ref.force_n[-1])


def take_hook(take: Take, hold_s: float) -> Callable[[Observation, GraspController], bool]:
    """The loop hook of a data take: hold when the reference reads its force, open the
    fingers after ``hold_s`` of hold (the run ends when they are free)."""
    reached = [False]

    def step(obs: Observation, controller: GraspController) -> bool:
        if controller.phase is GraspPhase.CLOSE and not reached[0] and \
                _latest_ref_n(obs) >= take.force_n:
            try:
                controller.hold(obs.t_s)
                reached[0] = True
            except InputError:
                pass  # not in contact yet by the marker: the next period
        held = controller.estimate.hold_s
        if controller.phase is GraspPhase.HOLD and math.isfinite(held) and held >= hold_s:
            controller.release(obs.t_s)
        return False

    return step


def twin_of_take(config: TwinConfig, take: Take) -> TwinConfig:
    """The twin of a take: the force ball at its position, the fingers at its temperature."""
    return replace(config, contact_position_m=take.contact_mm * 1e-3,
                   initial_temp_c=take.temp_c)


def record_take(take: Take, hold_s: float, path: Path, models: ModelBundle, *,
                config: TwinConfig | None = None, rig: RigFile | None = None,
                gripper: Gripper | None = None, clock: Clock | None = None,
                observer: Any = None) -> LoopResult:
    """Run one take and record it to ``path`` (its truth left out).

    On the twin (``config``, the twin of the rig), a twin is made for the
    take; on a rig, ``gripper`` (reset, its force reference tared) and its
    ``clock`` are the rig's and ``rig`` its file.

    Parameters
    ----------
    take : Take
        What to hold.
    hold_s : float
        How long (s).
    path : Path
        The recording (written as it runs; the caller renames it into place).
    models : ModelBundle
        The controller's models: the shipped ones for data takes (the
        reference stops the closing), the rig's own for the others.
    observer : ObserverModel, optional
        The ``observer``'s parameters (unused by ``fixed`` and ``relax``).

    Returns
    -------
    LoopResult

    Raises
    ------
    InputError
        The hold never started (no contact, the force never reached).
    """
    kind = EstimatorKind.FIXED if take.kind == "data" else EstimatorKind.RELAX
    estimator = bundle_estimator(kind, models, observer)
    if config is not None:
        cfg = twin_of_take(config, take)
        virtual = VirtualClock()
        backend: Gripper = GripperTwin(cfg, seed=take.seed, clock=virtual)
        run_clock: Clock = virtual
        controller = GraspController(cfg.rig, estimator, heat=cfg.heat, limits=twin_limits(cfg))
        ball = cfg.force_ball
        grasped = ProximityTarget(ball.width_m, ball.color_rgb,
                                  grasp_position_m=cfg.contact_position_m)
        allowance = 60.0
    else:
        if rig is None or gripper is None or clock is None:
            raise InputError("a take on a rig needs its rig file, its gripper and its clock")
        backend, run_clock = gripper, clock
        controller = GraspController(rig.geometry, estimator, heat=rig.heat, limits=rig.limits)
        ball = rig.force_ball
        grasped = ProximityTarget(ball.width_m, ball.color_rgb,
                                  grasp_position_m=take.contact_mm * 1e-3)
        allowance = SETUP_ALLOWANCE_S
    limits = controller.limits
    if take.kind == "data":
        # Closing until the reference says so: the controller's own target out of its way.
        plan = GraspPlan(target_n=limits.max_target_n, temp_c=take.temp_c, hold_s=math.inf,
                         release=True, grasped=grasped)
        hook: Callable[[Observation, GraspController], bool] | None = take_hook(take, hold_s)
    else:
        plan = GraspPlan(target_n=take.force_n, temp_c=take.temp_c, hold_s=hold_s,
                         release=True, grasped=grasped)
        hook = None
    # A regulated hold's recording is a plain hold (the calibration takes no scenario).
    scenario = ({"bringup_take": take.name, "force_n": f"{take.force_n:g}",
                 "contact_mm": f"{take.contact_mm:g}"} if take.kind == "data" else None)
    try:
        if config is not None:
            backend.reset(seed=take.seed)
        with TruthlessRecorder(path, scenario=scenario) as recorder:
            loop = run_loop(backend, controller, run_clock, plan, hold_s + allowance,
                            rate_hz=RATE_HZ, recorder=recorder, on_step=hook)
    finally:
        if config is not None:
            backend.close()
    if loop.hold_onset_s() is None:
        events = "; ".join(loop.log.summary())
        raise InputError(f"{take.name}: the hold never started ({events or 'no contact'})")
    return loop
