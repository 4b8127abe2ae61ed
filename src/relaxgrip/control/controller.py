"""The host of the paper's Fig. "network" c: perception, estimation, force and temperature control.

:class:`GraspController` turns each :class:`~relaxgrip.backend.Observation` into
a :class:`~relaxgrip.backend.Command`.  It reads the frames and the encoder
(never ``Observation.truth`` or ``force_ref``), runs perception and a force
estimator, and steps the grasp phases:

* **Open**: fingers open and still; the tracker zeroes on the unloaded
  finger, the heaters bring the fingers to the plan's temperature.  The marker
  is zeroed again once the temperature has settled (heating moves it).
* **Close**: the motor closes at the approach speed until perception sees
  contact (marker deflection beyond a threshold on consecutive frames), then
  the force PID drives the motor up to the target force.
* **Hold**: entered when the estimate reaches the target; the motor stops for
  a settling time (its lag), then the estimator's hold starts (Eq. 8's onset)
  and the PID regulates the estimate, or, for the fixed baseline, the
  aperture is held.  A new target during the hold is fed forward: the motor
  moves at up to 10 mm/s by most of the travel the loading's stiffness says
  it needs while the PID, capped at 3 mm/s for regulation, follows the force
  that travel has reached and takes up the rest.
* **Lift** / **Sustain**: the arm lifts and waits with the force held.
* **Release**: the motor opens until the marker is back at rest.

Whatever the phase, the safe state (motor stopped, heaters off) comes at
once on a fault (``docs/safety.md``): while the force cannot be read (the
marker lost, an RGB frame older than 200 ms, a stale infrared frame, no valid
estimate) the motor holds and the heaters are held off, until the reading is
back; an estimate beyond the rig's force limit (a real over-force, or a model
that outputs absurd forces), a finger above the rig's temperature cut-off and
a heater fault stop the grasp.  Every command is clamped to the rig's
speed and duty limits (:class:`~relaxgrip.limits.LimitsSpec`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from relaxgrip.backend import Command, Observation
from relaxgrip.clock import TIME_SLACK_S
from relaxgrip.control.estimators import (
    SLOPE_FORCE_SHARE,
    ForceEstimate,
    ForceEstimator,
    travel_slope,
)
from relaxgrip.control.phases import EventKind, GraspPhase, PhaseLog
from relaxgrip.control.pid import PID, PIDGains
from relaxgrip.control.temperature import (
    StiffnessMode,
    TemperatureLoop,
    TemperatureStatus,
    ThermalLimits,
    fresh,
)
from relaxgrip.errors import InputError
from relaxgrip.limits import OUR_LIMITS, LimitsSpec
from relaxgrip.perception.features import marker_pose
from relaxgrip.perception.marker import TrackStatus
from relaxgrip.perception.pipeline import Percept, Perception
from relaxgrip.perception.proximity import ProximityTarget
from relaxgrip.physics.thermal import HeatParams
from relaxgrip.rig import RigGeometry

if TYPE_CHECKING:
    from relaxgrip.twin.config import TwinConfig

__all__ = ["MAX_TARGET_N", "ForceControlConfig", "GraspController", "GraspPlan", "check_target_n",
           "onset_contact_m"]

#: Largest force target our gripper accepts (N): the paper's range is 0–10 N (the rig's limits).
MAX_TARGET_N = OUR_LIMITS.max_target_n
#: How a hold-onset event's detail says where the grasped object was seen ("… mm").
ONSET_OBJECT = "object at"


def onset_contact_m(detail: str) -> float:
    """Where a hold-onset event's detail says the grasped object sat (m); nan if it does not.

    The detail gives it to the micrometre, as the estimator was told it.
    """
    found = re.search(rf"{ONSET_OBJECT} ([0-9]+\.[0-9]+) mm", detail)
    return float(found.group(1)) / 1e3 if found else math.nan


@dataclass(frozen=True)
class GraspPlan:
    """What one grasp is asked to do.

    Attributes
    ----------
    target_n : float
        Force to hold (N), in (0, 10].
    mode : StiffnessMode or None
        Stiffness mode; ``None`` uses ``temp_c``.
    temp_c : float or None
        Finger temperature setpoint (°C) when no mode is given; ``None`` with
        no mode: heaters off.
    wait_for_temp : bool
        Stay open until the fingers are within :attr:`ForceControlConfig.temp_band_k`
        of the setpoint.
    hold_s : float
        Time held from the hold's onset (the motor settled, ``settle_s`` into
        Hold) before lifting or releasing (s); ``inf`` holds until told.
    lift_mm : float
        Arm lift after the hold (mm); 0: no Lift or Sustain.
    sustain_s : float
        Time in Sustain (s); ``inf`` sustains until told.
    release : bool
        Open the fingers at the end; else the grasp ends (Done) with the
        motor stopped where it is: the aperture is held, the force no longer
        regulated.
    grasped : ProximityTarget or None
        The object to be held, as the operator knows it (width, colour).
        With it, perception looks for the object in the frames where the
        motor settles before the hold, and the estimator is told where it
        sits along the fingers (its closed chain reads the run's marker
        share from that); ``None`` (the default): the nominal contact
        position.  Beyond the paper: at 5 N, 40 °C it holds better, across
        the grid of 1-8 N and 30-55 °C neither better nor worse (README,
        section Control).
    """

    target_n: float = 5.0
    mode: StiffnessMode | None = None
    temp_c: float | None = None
    wait_for_temp: bool = True
    hold_s: float = math.inf
    lift_mm: float = 0.0
    sustain_s: float = 0.0
    release: bool = True
    grasped: ProximityTarget | None = None

    def __post_init__(self) -> None:
        check_target_n(self.target_n)
        if not self.hold_s > 0 or math.isnan(self.hold_s):
            raise InputError(f"hold time must be > 0 s, got {self.hold_s}")
        if not (math.isfinite(self.lift_mm) and self.lift_mm >= 0):
            raise InputError(f"lift must be >= 0 mm, got {self.lift_mm}")
        if not self.sustain_s >= 0:  # nan refused; inf sustains until told, as hold_s
            raise InputError(f"sustain time must be >= 0 s, got {self.sustain_s}")


def twin_limits(config: TwinConfig) -> LimitsSpec:
    """Our limits on a twin's gripper: its motor's stroke, at most its motor's speed."""
    return OUR_LIMITS.for_motor(config.motor.stroke_mm, config.motor.max_velocity_mm_s)


def check_target_n(value: float) -> float:
    """Return a force target if our gripper's limits take it (within (0, 10] N)."""
    return OUR_LIMITS.check_target_n(value)


@dataclass(frozen=True)
class ForceControlConfig:
    """Gains, speeds and thresholds of the force loop and the phases.

    Attributes
    ----------
    gains : PIDGains
        Force PID: motor velocity (mm/s) per newton of error; its output limits
        are the velocity limits under force control.
    approach_mm_s : float
        Closing speed before contact (mm/s).
    release_mm_s : float
        Opening speed on release (mm/s).
    lift_mm_s : float
        Arm speed while lifting (mm/s).
    icfn_margin_n : float
        The per-frame ICFN is checked against the rig's force limit plus this
        too (N): a second reading, independent of Eq. 10, which a temperature
        change can throw far off; the margin leaves room for the ICFN's own
        over-reading as the finger relaxes (about 16 % after 280 s).
    contact_deflection_m : float
        Marker deflection that means contact (m).
    contact_frames : int
        Consecutive frames beyond it before contact is declared.
    hold_tolerance_rel : float
        The hold starts once the estimate is within this share of the target.
    settle_s : float
        Motor stop at the hold onset before the estimator's hold starts (s):
        four lag constants of the motor, as in the RCFN dataset.
    temp_band_k : float
        Temperature within this of the setpoint counts as reached (K).
    temp_settle_s : float
        Time the temperature must stay in band before closing (s).
    slip_drop_rel : float
        A fall of the estimate by this share of the target within
        ``slip_window_s`` while lifted is a slip.
    slip_window_s : float
        Window of the slip test (s).
    target_move_mm_s : float
        A new target during the hold moves the motor at up to this speed by
        ``target_move_share`` of the travel the loading's stiffness says it
        needs (feed-forward), while the PID follows the force that travel has
        reached so far (mm/s; 0: the PID alone, within its output limit).
    target_move_share : float
        That share, in (0, 1]: a quick move meets a stiffer chain than the
        loading did, which relaxed as it closed, and the PID takes up the
        rest from the near side.
    loading_share : float
        The loading's stiffness is fitted over the frames whose estimate is
        above this share of the estimate at the hold (motor travel against
        estimate, least squares).
    rgb_stale_after_s : float
        Under force control, an RGB frame older than this on the loop's clock
        counts as a lost marker (s): the motor holds until a new frame comes.
        A camera that stops, or a backend that hands over the same frame
        again, would otherwise leave the loop on a frozen estimate.  Six frame
        periods at 30 Hz; the serial gripper's cameras stall at 200 ms too.
    """

    gains: PIDGains = field(default_factory=lambda: PIDGains(
        kp=2.5, ki=1.0, kd=0.0, out_min=-3.0, out_max=3.0, derivative_tau_s=0.1))
    approach_mm_s: float = 10.0
    release_mm_s: float = 10.0
    lift_mm_s: float = 20.0
    icfn_margin_n: float = 1.0
    contact_deflection_m: float = 3e-5
    contact_frames: int = 2
    hold_tolerance_rel: float = 0.005
    settle_s: float = 0.2
    temp_band_k: float = 1.5
    temp_settle_s: float = 3.0
    slip_drop_rel: float = 0.3
    slip_window_s: float = 0.5
    target_move_mm_s: float = 10.0
    target_move_share: float = 0.9
    loading_share: float = SLOPE_FORCE_SHARE
    rgb_stale_after_s: float = 0.2

    def __post_init__(self) -> None:
        if not self.rgb_stale_after_s > 0:
            raise ValueError(f"RGB staleness limit must be > 0 s, got {self.rgb_stale_after_s}")
        if not (math.isfinite(self.target_move_mm_s) and self.target_move_mm_s >= 0):
            raise ValueError(f"target move speed must be >= 0 mm/s, got {self.target_move_mm_s}")
        if not 0.0 < self.target_move_share <= 1.0:
            raise ValueError(f"target move share must be in (0, 1], got {self.target_move_share}")
        if not 0.0 <= self.loading_share < 1.0:
            raise ValueError(f"loading share must be in [0, 1), got {self.loading_share}")


#: Phases in which an object may stand between the infrared camera and the fingertips.
_GRASPING = frozenset({GraspPhase.CLOSE, GraspPhase.HOLD, GraspPhase.LIFT, GraspPhase.SUSTAIN,
                       GraspPhase.RELEASE})


class GraspController:
    """Observation in, command out: the whole host loop for one grasp at a time.

    Parameters
    ----------
    rig : RigGeometry
        Cameras, marker and fingers (for perception).
    estimator : ForceEstimator
        Force estimator (``fixed``, ``icfn``, ``relax``, …).
    config : ForceControlConfig
        Force loop and phase settings.
    heat : HeatParams, optional
        Heat model for the temperature loop's feed-forward.
    limits : LimitsSpec, optional
        The rig's safety limits (default: our gripper's, the twin's): force
        target and limit, setpoints and cut-off, speed, duty and stroke.

    Raises
    ------
    InputError
        A speed of ``config`` beyond the rig's speed limit.
    """

    def __init__(self, rig: RigGeometry, estimator: ForceEstimator,
                 config: ForceControlConfig | None = None, heat: HeatParams | None = None,
                 limits: LimitsSpec | None = None) -> None:
        self.rig = rig
        self.estimator = estimator
        self.config = config if config is not None else ForceControlConfig()
        self.limits = limits if limits is not None else OUR_LIMITS
        cfg = self.config
        for name, speed in (("approach", cfg.approach_mm_s), ("release", cfg.release_mm_s),
                            ("target move", cfg.target_move_mm_s),
                            ("force PID", max(-cfg.gains.out_min, cfg.gains.out_max))):
            self.limits.check_speed_mm_s(speed, f"the controller's {name} speed")
        self.perception = Perception(rig)
        self.temperature = TemperatureLoop(heat, ThermalLimits.for_rig(self.limits))
        self.pid = PID(self.config.gains)
        self.plan = GraspPlan()
        self.log = PhaseLog()
        self.phase = GraspPhase.DONE
        self.percept: Percept | None = None
        self.estimate = ForceEstimate(math.nan, math.nan)
        self.command = Command()
        self._reset_state()

    def _reset_state(self) -> None:
        self._phase_t = 0.0
        self._t_prev: float | None = None
        self._contact_count = 0
        self._in_contact = False
        self._lost: EventKind | None = None  # MARKER_LOST or ESTIMATE_LOST while it lasts
        self._temp_ok_since: float | None = None
        self._rezeroed = False
        self._hold_started = False
        self._onset_t = 0.0
        self._lift_start_mm = 0.0
        self._recent: list[tuple[float, float]] = []
        self._temp_status = TemperatureStatus.OFF
        self._loading: list[tuple[float, float]] = []  # (motor mm, estimate N) while closing
        self._stiffness_n_per_mm = math.nan
        self._regulated_n = math.nan  # the target the hold has moved to
        self._move_mm = 0.0  # feed-forward travel still to go
        self._grasped_seen: list[float] | None = None  # object positions (m) while settling

    # -- operator requests ---------------------------------------------------------------

    def start(self, plan: GraspPlan, t_s: float = 0.0) -> None:
        """Begin a grasp from the open gripper.

        Raises
        ------
        InputError
            While a grasp is under way (release or stop it first), or a plan
            whose temperature the loop does not accept; nothing is changed.
        """
        if self.phase not in (GraspPhase.DONE, GraspPhase.STOPPED, GraspPhase.OPEN):
            raise InputError(f"a grasp is under way (phase {self.phase.value}): release or "
                             "stop it first")
        self.limits.check_target_n(plan.target_n)
        if plan.mode is not None:
            self.temperature.check_mode(plan.mode)
        elif plan.temp_c is not None:
            self.temperature.limits.check_setpoint(plan.temp_c)
        if self._grasped_seen is not None:  # the last grasp stopped while looking for its object
            self.perception.set_target(None)
        self.plan = plan
        self.log = PhaseLog()
        self.perception.reset()
        self.estimator.reset()
        self.pid.reset()
        self._reset_state()
        if plan.mode is not None:
            self.temperature.set_mode(plan.mode)
        else:
            self.temperature.set_temperature(plan.temp_c)
        self._enter(t_s, GraspPhase.OPEN)

    def set_target(self, target_n: float) -> None:
        """Change the force target from now on."""
        self.plan = replace(self.plan, target_n=self.limits.check_target_n(target_n))

    def hold(self, t_s: float) -> None:
        """Hold the force from now on, however far the closing or lifting has got.

        A closing grasp in contact enters Hold at once (the motor settles,
        then the estimator's hold starts); a lift or sustain returns to Hold
        (the arm stops, the force stays held).  The hold then lasts until
        told otherwise.

        Raises
        ------
        InputError
            In any other phase, or while closing before contact.
        """
        if self.phase is GraspPhase.CLOSE and self._in_contact:
            self._hold_started = False
        elif self.phase not in (GraspPhase.HOLD, GraspPhase.LIFT, GraspPhase.SUSTAIN):
            raise InputError(f"nothing to hold in phase {self.phase.value}"
                             + (" before contact" if self.phase is GraspPhase.CLOSE else ""))
        self.plan = replace(self.plan, hold_s=math.inf)
        if self.phase is not GraspPhase.HOLD:
            self._enter(t_s, GraspPhase.HOLD)

    def lift(self, t_s: float, arm_mm: float, lift_mm: float) -> None:
        """Lift the held object by ``lift_mm`` from the arm's height ``arm_mm``, then sustain.

        Raises
        ------
        InputError
            Unless the grasp is in Hold, or if ``lift_mm`` is not > 0.
        """
        if self.phase is not GraspPhase.HOLD:
            raise InputError(f"lift needs a grasp in hold, not in phase {self.phase.value}")
        if not (math.isfinite(lift_mm) and lift_mm > 0):
            raise InputError(f"lift must be > 0 mm, got {lift_mm}")
        self.plan = replace(self.plan, lift_mm=float(lift_mm), sustain_s=math.inf)
        self._after_hold(t_s, arm_mm)

    def release(self, t_s: float) -> None:
        """Open the fingers now."""
        self._enter(t_s, GraspPhase.RELEASE)

    def stop(self, t_s: float, reason: str = "operator") -> None:
        """Stop the motor and switch the heaters off.

        The last command becomes the stopped one at once (what a caller sends
        the gripper now), not at the next :meth:`step`: a state shown between
        the two had read the heaters on.
        """
        self.temperature.set_temperature(None)
        self.log.event(t_s, EventKind.STOP, reason)
        self._enter(t_s, GraspPhase.STOPPED)
        self.command = Command()

    # -- the loop ------------------------------------------------------------------------

    def step(self, obs: Observation) -> Command:
        """One control period: perceive, estimate, decide."""
        t = obs.t_s
        dt = 1.0 / 30.0 if self._t_prev is None else max(t - self._t_prev, 1e-4)
        self._t_prev = t
        motor = obs.motor_position_mm
        percept = self.perception.update(obs.rgb, obs.ir, motor)
        self.percept = percept
        self.estimate = self.estimator.update(percept, motor)
        duty = self._heaters(percept, t)
        velocity, arm = self._motor(t, dt, motor, obs.arm_height_mm, percept)
        if self.phase is GraspPhase.STOPPED:
            velocity, duty, arm = 0.0, (0.0, 0.0), 0.0  # stopped in this period: all off now
        elif self._lost is not None:
            duty = (0.0, 0.0)  # blind to the force: nothing is driven on a reading not made
            self.temperature.hold_off()
        velocity, duty = self.limits.clamp(velocity, duty)
        self.command = Command(velocity, duty, arm)
        return self.command

    def _heaters(self, percept: Percept, t: float) -> tuple[float, float]:
        if self.phase is GraspPhase.STOPPED:
            return (0.0, 0.0)
        duty = self.temperature.update(percept.thermal, t)
        status = self.temperature.status
        if status is not self._temp_status:
            if status is TemperatureStatus.OVER_TEMPERATURE:
                hottest = max((f.max_c for f in percept.thermal.fingers  # type: ignore[union-attr]
                               if math.isfinite(f.max_c)), default=math.nan)
                detail = (f"a finger read {hottest:.1f} °C, above the "
                          f"{self.temperature.limits.max_temp_c:g} °C cut-off")
                self.log.event(t, EventKind.OVER_TEMPERATURE, detail)
                self._temp_status = status
                self.stop(t, f"over-temperature: {detail}")
                return (0.0, 0.0)
            elif status is TemperatureStatus.STALE:
                self.log.event(t, EventKind.IR_STALE,
                               f"no infrared frame for {percept.ir_age_s:.1f} s: heaters off")
            self._temp_status = status
            if status is TemperatureStatus.HEATER_FAULT:
                self.log.event(t, EventKind.HEATER_FAULT, str(self.temperature.fault))
                self.stop(t, "heater fault")
                return (0.0, 0.0)
        return duty

    def _enter(self, t: float, phase: GraspPhase) -> None:
        if phase is GraspPhase.RELEASE and self._hold_started:
            # Opening unloads the fingers: Eq. 10 and the closure term end with the hold.
            self._hold_started = False
            self.estimator.end_hold(t)
        self.phase = phase
        self._phase_t = t
        self.log.enter(t, phase)
        self.temperature.set_grasping(phase in _GRASPING)

    def _sensing_lost(self, t: float, percept: Percept, est: ForceEstimate
                      ) -> tuple[EventKind, str] | None:
        """Why the force cannot be read at ``t`` (an event to log), or None if it can.

        The marker must be tracked on a current RGB frame (a camera that
        stopped would leave the force loop closing on a frozen estimate) and
        the estimate valid; and the infrared current by the temperature loop's
        rule, for every estimate reads the finger's temperature: a stalled
        thermal camera would leave them on a temperature the fingers left
        (cooling fingers stiffen, and the force held would climb unseen).
        """
        lost = self._marker_lost(t, percept)
        if lost is not None:
            return lost
        limit = self.temperature.limits.stale_after_s
        thermal = percept.thermal
        if thermal is None or not fresh(thermal.t_s, t, limit):
            seen = -math.inf if thermal is None else thermal.t_s
            return EventKind.ESTIMATE_LOST, _stale("infrared", seen, t, limit)
        if not est.valid:
            return EventKind.ESTIMATE_LOST, "no valid estimate"
        return None

    def _marker_lost(self, t: float, percept: Percept) -> tuple[EventKind, str] | None:
        """Why the marker cannot be read at ``t`` (a ``MARKER_LOST`` to log), or None if it can.

        It must be tracked on a current RGB frame.
        """
        rgb_limit = self.config.rgb_stale_after_s
        if not fresh(percept.t_s, t, rgb_limit):
            return EventKind.MARKER_LOST, _stale("RGB", percept.t_s, t, rgb_limit)
        if percept.marker.status is not TrackStatus.TRACKING:
            return EventKind.MARKER_LOST, percept.marker.message or \
                f"marker {percept.marker.status.value}"
        return None

    def _held_while_lost(self, t: float, lost: tuple[EventKind, str] | None) -> bool:
        """Log where a loss starts or ends; whether the motor must hold position now.

        ``lost`` is the loss at ``t`` (its event and detail), or None: the
        first period of a loss logs its event, the first period without one
        the matching back event (and resets the PID).
        """
        if lost is not None:
            kind, detail = lost
            if self._lost is None:
                self._lost = kind
                self.log.event(t, kind, detail)
            return True
        if self._lost is not None:
            back = (EventKind.MARKER_BACK if self._lost is EventKind.MARKER_LOST
                    else EventKind.ESTIMATE_BACK)
            self._lost = None
            self.pid.reset(0.0)
            self.log.event(t, back)
        return False

    def _look_for_grasped(self, percept: Percept) -> None:
        """While the motor settles into the hold, perception looks for the plan's object."""
        if self.plan.grasped is None:
            return
        if self._grasped_seen is None:
            self._grasped_seen = []
            self.perception.set_target(self.plan.grasped)
        elif percept.proximity is not None and percept.proximity.found:
            self._grasped_seen.append(percept.proximity.position_m)

    def _grasped_position_m(self) -> float:
        """Where the object sat while the motor settled (m, median, to the µm); stop looking."""
        if self.plan.grasped is None:
            return math.nan
        self.perception.set_target(None)
        seen = self._grasped_seen or []
        return round(float(np.median(seen)) * 1e3, 3) / 1e3 if seen else math.nan

    def _contact(self, t: float, percept: Percept) -> None:
        pose = marker_pose(percept.marker)
        bent = pose is not None and pose[0] > self.config.contact_deflection_m
        self._contact_count = self._contact_count + 1 if bent else 0
        if not self._in_contact and self._contact_count >= self.config.contact_frames:
            self._in_contact = True
            self.pid.reset(0.0)
            tare = self.estimator.contact(t)
            detail = f"marker deflection {pose[0] * 1e3:.3f} mm" if pose is not None else ""
            if tare != 0.0:
                detail += f"; the ICFN read {tare:+.3f} N at rest: tared"
            self.log.event(t, EventKind.CONTACT, detail)

    def _temperature_ready(self, t: float, percept: Percept) -> bool:
        setpoint = self.temperature.setpoint_c
        if setpoint is None or not self.plan.wait_for_temp:
            return True
        thermal = percept.thermal
        if thermal is None:
            return False
        readings = self.temperature.readings_c(thermal)
        ok = all(math.isfinite(r) and abs(r - setpoint) <= self.config.temp_band_k
                 for r in readings)
        if not ok:
            self._temp_ok_since = None
            return False
        if self._temp_ok_since is None:
            self._temp_ok_since = t
        return t - self._temp_ok_since >= self.config.temp_settle_s

    def _motor(self, t: float, dt: float, motor: float, arm_mm: float,
               percept: Percept) -> tuple[float, float]:
        """Motor and arm velocity for this period, stepping the phases."""
        cfg = self.config
        phase = self.phase
        if phase in (GraspPhase.DONE, GraspPhase.STOPPED):
            return 0.0, 0.0
        if phase is GraspPhase.OPEN:
            return self._open(t, percept)
        if phase is GraspPhase.RELEASE:
            # Opening reads no force, only the marker: a stale infrared does not stop it,
            # and an estimate lost before the release is not watched for (nor said to be back).
            if self._lost is EventKind.ESTIMATE_LOST:
                self._lost = None
            if self._held_while_lost(t, self._marker_lost(t, percept)):
                return 0.0, 0.0
            pose = marker_pose(percept.marker)
            free = pose is not None and pose[0] < cfg.contact_deflection_m
            if (free and t - self._phase_t > 0.5) or motor <= 0.0:
                self._enter(t, GraspPhase.DONE)
                return 0.0, 0.0
            return -cfg.release_mm_s, 0.0
        est = self.estimate
        if self._held_while_lost(t, self._sensing_lost(t, percept, est)):
            return 0.0, 0.0  # hold position until the force can be read again
        limit_n = self.limits.max_force_n
        over = [f"{name} {f:.4g} N" for name, f, limit in (
            ("estimate", est.force_n, limit_n),
            ("per-frame ICFN", est.f_icfn_n, limit_n + cfg.icfn_margin_n)) if abs(f) > limit]
        if over:
            detail = f"{'; '.join(over)} beyond the ±{limit_n:g} N force limit"
            self.log.event(t, EventKind.FORCE_LIMIT, detail)
            self.stop(t, f"force limit: {detail}")
            return 0.0, 0.0
        self._contact(t, percept)
        target = self.plan.target_n
        if phase is GraspPhase.CLOSE:
            if not self._in_contact:
                if motor >= self.limits.stroke_mm:
                    self.log.event(t, EventKind.STROKE_END, "no contact within the stroke")
                    self._enter(t, GraspPhase.RELEASE)
                    return 0.0, 0.0
                return cfg.approach_mm_s, 0.0
            self._loading.append((motor, est.force_n))
            at_end = motor >= self.limits.stroke_mm
            if est.force_n >= target * (1.0 - cfg.hold_tolerance_rel) or at_end:
                if at_end:
                    self.log.event(t, EventKind.STROKE_END, f"estimate {est.force_n:.2f} N")
                self._enter(t, GraspPhase.HOLD)
                self._hold_started = False
                return 0.0, 0.0
            return self.pid.update(target, est.force_n, dt), 0.0
        # Hold, Lift, Sustain: the force is held.
        if not self._hold_started:
            self._look_for_grasped(percept)
            if t - self._phase_t < cfg.settle_s:
                return 0.0, 0.0
            self._hold_started = True
            contact_m = self._grasped_position_m()
            self.estimator.start_hold(t, motor, contact_m)
            self.pid.reset(0.0)
            self._stiffness_n_per_mm = _loading_stiffness(self._loading, est.force_n,
                                                          cfg.loading_share)
            self._regulated_n, self._move_mm = target, 0.0
            self._onset_t = t
            detail = f"estimate {est.force_n:.3f} N"
            if math.isfinite(contact_m):
                detail += f"; {ONSET_OBJECT} {contact_m * 1e3:.3f} mm"
            self.log.event(t, EventKind.HOLD_ONSET, detail)
            return 0.0, 0.0
        velocity = (self._regulate(target, est.force_n, dt)
                    if self.estimator.regulates_hold else 0.0)
        if motor >= self.limits.stroke_mm:
            velocity = min(velocity, 0.0)
        arm = 0.0
        if phase is GraspPhase.HOLD:
            # Counted from the onset, which ends the settle on its own clock: counted from
            # entering Hold, a settle of six periods summing a rounding under 0.2 s took
            # seven, and the hold ended a period short (most 20 s holds did).
            if t - self._onset_t >= self.plan.hold_s - TIME_SLACK_S:
                self._after_hold(t, arm_mm)
        elif phase is GraspPhase.LIFT:
            self._watch_slip(t, est)
            if arm_mm - self._lift_start_mm >= self.plan.lift_mm:
                self._enter(t, GraspPhase.SUSTAIN)
            else:
                arm = cfg.lift_mm_s
        elif phase is GraspPhase.SUSTAIN:
            self._watch_slip(t, est)
            if t - self._phase_t >= self.plan.sustain_s:
                self._finish(t)
        return velocity, arm

    def _regulate(self, target: float, force_n: float, dt: float) -> float:
        """The hold's motor velocity: the PID, and a new target's feed-forward move.

        A new target queues the travel the loading's stiffness says it needs;
        the motor covers it at up to ``target_move_mm_s`` while the PID
        regulates to the force that travel has reached (the new target less
        the stiffness times what is left), so it neither fights the move nor
        winds up on the step.  What the stiffness gets wrong the PID takes up.
        """
        cfg = self.config
        k = self._stiffness_n_per_mm
        if target != self._regulated_n:
            if cfg.target_move_mm_s > 0 and math.isfinite(k) and math.isfinite(self._regulated_n):
                self._move_mm += cfg.target_move_share * (target - self._regulated_n) / k
            self._regulated_n = target
        feed = 0.0
        if self._move_mm != 0.0:
            step = cfg.target_move_mm_s * dt
            done = min(max(self._move_mm, -step), step)
            self._move_mm -= done
            feed = done / dt
        reference = (target - k * self._move_mm / cfg.target_move_share if self._move_mm != 0.0
                     else target)
        return feed + self.pid.update(reference, force_n, dt)

    def _open(self, t: float, percept: Percept) -> tuple[float, float]:
        zeroed = percept.marker.status is TrackStatus.TRACKING
        if not (zeroed and percept.thermal is not None):
            return 0.0, 0.0
        if not self._temperature_ready(t, percept):
            return 0.0, 0.0
        if self.temperature.setpoint_c is not None and not self._rezeroed \
                and t - self._phase_t > 1.0:
            # The marker zeroed while the fingers were heating: zero it at temperature.
            self._rezeroed = True
            self.perception.tracker.reset()
            return 0.0, 0.0
        self._enter(t, GraspPhase.CLOSE)
        return self.config.approach_mm_s, 0.0

    def _after_hold(self, t: float, arm_mm: float) -> None:
        if self.plan.lift_mm > 0:
            self._lift_start_mm = arm_mm
            self._recent.clear()
            self._enter(t, GraspPhase.LIFT)
        else:
            self._finish(t)

    def _finish(self, t: float) -> None:
        if self.plan.release:
            self._enter(t, GraspPhase.RELEASE)
        else:
            self._enter(t, GraspPhase.DONE)

    def _watch_slip(self, t: float, est: ForceEstimate) -> None:
        self._recent.append((t, est.force_n))
        while self._recent and self._recent[0][0] < t - self.config.slip_window_s:
            self._recent.pop(0)
        peak = max(f for _, f in self._recent)
        if peak - est.force_n > self.config.slip_drop_rel * self.plan.target_n:
            self.log.event(t, EventKind.SLIP, f"estimate fell {peak - est.force_n:.2f} N "
                           f"in {self.config.slip_window_s:g} s")
            self._recent.clear()


def _stale(stream: str, frame_t_s: float, t_s: float, limit_s: float) -> str:
    """Why a frame of ``stream`` stamped ``frame_t_s`` is not current at ``t_s``."""
    if frame_t_s > t_s:
        return f"{stream} frame stamped {frame_t_s - t_s:.1f} s ahead of the loop's clock"
    return f"no {stream} frame for {t_s - frame_t_s:.1f} s (limit {limit_s:g} s)"


def _loading_stiffness(loading: list[tuple[float, float]], hold_n: float,
                       share: float) -> float:
    """The estimate's rise per millimetre of motor travel over the loading's top (N/mm).

    A least-squares line through the closing frames whose estimate is above
    ``share`` of ``hold_n`` (:func:`~relaxgrip.control.estimators.travel_slope`,
    as ``relax`` measures its closure stiffness); nan if fewer than three,
    under 1 µm of travel, or a slope that is not positive (nothing to feed
    forward with).
    """
    top = np.array([(m, f) for m, f in loading if math.isfinite(f) and f >= share * hold_n])
    if len(top) < 3:
        return math.nan
    slope = travel_slope(top[:, 0], top[:, 1])
    return float(slope) if slope is not None and float(slope) > 0 else math.nan
