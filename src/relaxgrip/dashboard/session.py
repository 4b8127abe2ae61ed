"""The dashboard's live session: one backend run through the grasp controller in a thread.

:class:`LiveSession` owns a :class:`~relaxgrip.backend.Gripper`, a
:class:`~relaxgrip.control.GraspController` and the loop thread that runs
observe → step → act at the control rate, in the time of an injected clock (a
:class:`~relaxgrip.clock.WallClock` for the dashboard).  Backends that live in
virtual time (the twin, the MCU emulator in lockstep) get their virtual clock
moved with the session clock before every period, so they run in real time
too.  Their time is carried on from where it stood when the loop starts, not
jumped to the session clock's: the emulated MCU's 200 ms watchdog would see
the web server's start-up as a gap between its enable and the first Command.
A backend on a real link is opened again (``rearm``) in the loop thread just
before the first period, for the same watchdog.

The web server never waits on the loop: it reads :meth:`LiveSession.state`
(a plain dict, under a lock held for one period at most) and asks for changes
through the control methods, which check their input *before* they touch
anything (an :class:`~relaxgrip.errors.InputError` with a one-line message,
nothing changed).  The session only reads the truth for display; the
controller never sees it.

However the loop ends (closed, or an exception in a period), the motor is
stopped and the heaters are switched off.
"""

from __future__ import annotations

import datetime as dt
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Command, Gripper, Observation
from relaxgrip.clock import Clock, VirtualClock
from relaxgrip.control import (
    EstimatorKind,
    EventKind,
    GraspController,
    GraspPhase,
    GraspPlan,
    StiffnessMode,
    bundle_estimator,
    twin_limits,
)
from relaxgrip.control.runner import LoopRecorder
from relaxgrip.errors import InputError
from relaxgrip.fileio import check_writable
from relaxgrip.perception.marker import MarkerState
from relaxgrip.rig import RigGeometry

if TYPE_CHECKING:
    from relaxgrip.twin import TwinConfig

__all__ = ["DEFAULT_LIFT_MM", "OPEN_TOLERANCE_MM", "FramePair", "LiveSession", "open_session"]

#: Arm travel of the Lift control (mm).
DEFAULT_LIFT_MM = 30.0
#: Encoder position below which the gripper counts as open (mm).
OPEN_TOLERANCE_MM = 1.0
_IDLE = (GraspPhase.DONE, GraspPhase.STOPPED)


@dataclass(frozen=True)
class FramePair:
    """The latest frames and what perception made of the RGB one (for display).

    Attributes
    ----------
    rgb, ir : ndarray or None
        RGB ``(H, W, 3)`` uint8 and infrared ``(H, W)`` °C images.
    rgb_seq, ir_seq : int
        Frame counters (-1 without a frame).
    marker : MarkerState or None
        Tracking of the RGB frame.
    aperture_m : float
        Aperture at the time of the observation (m).
    beam_temps_c : tuple of tuple of float or None
        Beam temperatures perception read from the infrared frame (°C).
    """

    rgb: NDArray[np.uint8] | None
    ir: NDArray[np.float32] | None
    rgb_seq: int
    ir_seq: int
    marker: MarkerState | None
    aperture_m: float
    beam_temps_c: tuple[tuple[float, ...], ...] | None


@dataclass
class _Wanted:
    """What the operator has asked for (applied to the next grasp)."""

    target_n: float = 5.0
    mode: StiffnessMode | None = StiffnessMode.STIFF
    temp_c: float | None = None
    object_name: str | None = None
    events: list[str] = field(default_factory=list)


class LiveSession:
    """A backend and a controller, stepped in a background thread.

    Parameters
    ----------
    backend : Gripper
        The gripper, already reset.
    controller : GraspController
        The host loop (idle until :meth:`close_grasp`).
    clock : Clock
        Session time: paces the loop.
    backend_clock : VirtualClock, optional
        The backend's own virtual clock, advanced with ``clock`` before every
        period from where it stands when the loop starts (twin, emulator).
    rate_hz : float
        Control rate (the camera's, 30 Hz).
    objects : tuple of str
        Objects the operator may put between the fingers (twin only).
    set_object : callable, optional
        Places an object (``None``: none) in the backend; the twin's
        :meth:`~relaxgrip.twin.GripperTwin.set_object`.
    record_dir : Path
        Where MCAP recordings go.
    recorder_factory : callable, optional
        Makes a recorder for a path (default: :class:`relaxgrip.recording.McapRecorder`).
    rearm : callable, optional
        Called in the loop thread just before the first period: opens a link
        again whose watchdog has run since it was opened (a serial gripper's
        :meth:`~relaxgrip.backend.Gripper.reset`).
    """

    def __init__(self, backend: Gripper, controller: GraspController, clock: Clock, *,
                 backend_clock: VirtualClock | None = None, rate_hz: float = 30.0,
                 objects: tuple[str, ...] = (),
                 set_object: Callable[[str | None], None] | None = None,
                 object_name: str | None = None,
                 record_dir: Path = Path("."),
                 recorder_factory: Callable[[Path], LoopRecorder] | None = None,
                 rearm: Callable[[], object] | None = None) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise InputError(f"control rate must be > 0 Hz, got {rate_hz}")
        self.backend = backend
        self.controller = controller
        self.clock = clock
        self.backend_clock = backend_clock
        self.rate_hz = float(rate_hz)
        self.objects = objects
        self.record_dir = Path(record_dir)
        self._set_object = set_object
        self._recorder_factory = recorder_factory
        self._rearm = rearm
        self._backend_offset_s = 0.0
        self._wanted = _Wanted(object_name=object_name)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._obs: Observation | None = None
        self._recorder: LoopRecorder | None = None
        self.record_path: Path | None = None
        self.error: str | None = None
        #: Why the last recording stopped by itself (a full disk); the loop goes on.
        self.record_error: str | None = None
        self.periods = 0
        self.overruns = 0
        self._controls = 0
        self._closed = False
        controller.temperature.set_mode(StiffnessMode.STIFF)

    # -- lifecycle -------------------------------------------------------------------------

    @property
    def alive(self) -> bool:
        """Whether the loop thread is running."""
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Start the loop thread (once)."""
        if self._thread is not None:
            raise InputError("the session has already started")
        self._thread = threading.Thread(target=self._run, name="relaxgrip-loop", daemon=True)
        self._thread.start()

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the loop, then the motor and the heaters; close the recording and the backend.

        Closing again does nothing.
        """
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
        with self._lock:
            self._safe_off()
            self._stop_recording()
            try:
                self.backend.close()
            except Exception as exc:  # closing must not hide the shutdown
                self.error = self.error or f"closing the backend: {exc}"

    def _safe_off(self) -> None:
        try:
            self.backend.act(Command())
        except Exception as exc:  # best effort: the link may be gone
            self.error = self.error or f"stopping the gripper: {exc}"

    def _run(self) -> None:
        dt_s = 1.0 / self.rate_hz
        try:
            if self._rearm is not None:
                with self._lock:
                    self._rearm()
            if self.backend_clock is not None:
                self._backend_offset_s = self.backend_clock.now() - self.clock.now()
            t_next = self.clock.now()
            while not self._stop.is_set():
                with self._lock:
                    self._period()
                t_next += dt_s
                now = self.clock.now()
                if now > t_next + dt_s:  # fell behind: skip the missed periods, do not rush
                    self.overruns += 1
                    t_next = now
                self.clock.sleep_until(t_next)
        except Exception as exc:  # shown on the page; finally: safe
            with self._lock:  # one state: the page must not read the heaters on beside it
                self.error = f"control loop stopped: {type(exc).__name__}: {exc}"
                self.controller.stop(self._now(), "control loop stopped")
        finally:
            with self._lock:
                self._safe_off()
                self._stop_recording()

    def _period(self) -> None:
        if self.backend_clock is not None:
            self.backend_clock.sleep_until(self.clock.now() + self._backend_offset_s)
        obs = self.backend.observe()
        command = self.controller.step(obs)
        self.backend.act(command)
        if self._recorder is not None:
            try:
                self._recorder.step(obs, self.controller, command)
            except OSError as exc:  # a full disk ends the recording (sealed), not the grasp
                self.record_error = f"recording {self.record_path} stopped: {exc.strerror}"
                self._recorder = self.record_path = None
        self._obs = obs
        self.periods += 1

    # -- reading -------------------------------------------------------------------------

    def frames(self) -> FramePair:
        """The latest frames and the marker state, for display."""
        with self._lock:
            obs = self._obs
            percept = self.controller.percept
        rig: RigGeometry = self.controller.rig
        if obs is None:
            return FramePair(None, None, -1, -1, None, rig.open_aperture_m, None)
        beams = None
        if percept is not None and percept.thermal is not None:
            beams = tuple(f.beam_temps_c for f in percept.thermal.fingers)
        return FramePair(
            None if obs.rgb is None else obs.rgb.image,  # type: ignore[arg-type]
            None if obs.ir is None else obs.ir.image,  # type: ignore[arg-type]
            -1 if obs.rgb is None else obs.rgb.seq, -1 if obs.ir is None else obs.ir.seq,
            None if percept is None else percept.marker,
            rig.aperture_m(obs.motor_position_mm), beams)

    def state(self) -> dict[str, Any]:
        """Everything the page shows, as plain Python (nan for what is unknown)."""
        with self._lock:
            return self._state()

    def _state(self) -> dict[str, Any]:
        c = self.controller
        obs = self._obs
        est = c.estimate
        temps = [math.nan, math.nan]
        percept = c.percept
        if percept is not None and percept.thermal is not None:
            temps = list(c.temperature.readings_c(percept.thermal))
        t = obs.t_s if obs is not None else math.nan
        contact = c.log.first(EventKind.CONTACT)
        since_contact = (t - contact.t_s if contact is not None and c.phase not in _IDLE
                         and c.phase is not GraspPhase.RELEASE else math.nan)
        truth = obs.truth if obs is not None else None
        truth_temps = ([sum(f) / len(f) for f in truth.finger_temps_c]
                       if truth is not None else [math.nan, math.nan])
        mode = c.temperature.mode
        wanted = self._wanted
        return {
            "t_s": t,
            "phase": c.phase.value,
            "backend": self.backend.info.name,
            "backend_version": self.backend.info.version,
            "estimator": c.estimator.name,
            "target_n": wanted.target_n if c.phase in _IDLE else c.plan.target_n,
            "estimate_n": est.force_n,
            "icfn_n": est.f_icfn_n,
            "k_n": est.k_n,
            "tau_s": est.tau_s,
            "hold_s": est.hold_s,
            "since_contact_s": since_contact,
            "truth_n": truth.contact_force_n if truth is not None else math.nan,
            "truth_temps_c": truth_temps,
            "temps_c": temps,
            "setpoint_c": math.nan if c.temperature.setpoint_c is None
            else c.temperature.setpoint_c,
            "mode": None if mode is None else mode.value,
            "temp_status": c.temperature.status.value,
            "duty": list(c.command.heater_duty),
            "marker": None if percept is None else percept.marker.status.value,
            "motor_mm": obs.motor_position_mm if obs is not None else math.nan,
            "arm_mm": obs.arm_height_mm if obs is not None else math.nan,
            "object": wanted.object_name,
            "objects": list(self.objects),
            "modes": [m.value for m in StiffnessMode],
            "recording": None if self.record_path is None else str(self.record_path),
            "events": c.log.summary()[-6:],  # a repeated reason once, with its count
            "alive": self.alive,
            "error": self.error or self.record_error,
            "periods": self.periods,
            "controls": self._controls,
        }

    def count_control(self) -> int:
        """Count one control taken; the count, which :meth:`state` shows from now on."""
        with self._lock:
            self._controls += 1
            return self._controls

    # -- controls: check, then change --------------------------------------------------

    def _now(self) -> float:
        return (self._obs.t_s if self._obs is not None
                else self.clock.now() + self._backend_offset_s)

    def _check_running(self) -> None:
        if not self.alive:
            raise InputError(self.error or "the control loop is not running")

    def set_target(self, target_n: float) -> None:
        """Force target (N) for the running grasp and the next ones."""
        value = self.controller.limits.check_target_n(target_n)
        with self._lock:
            self._wanted.target_n = value
            if self.controller.phase not in _IDLE:
                self.controller.set_target(value)

    def set_mode(self, mode: str) -> None:
        """Stiffness mode (its temperature setpoint), from now on."""
        try:
            value = StiffnessMode(mode)
        except ValueError:
            known = ", ".join(m.value for m in StiffnessMode)
            raise InputError(f"unknown stiffness mode {mode!r}; known: {known}") from None
        with self._lock:
            self._wanted.mode, self._wanted.temp_c = value, None
            if self.controller.phase is not GraspPhase.STOPPED:
                self.controller.temperature.set_mode(value)

    def set_temperature(self, temp_c: float) -> None:
        """Finger temperature setpoint (°C), from now on."""
        value = float(temp_c)
        self.controller.temperature.limits.check_setpoint(value)
        with self._lock:
            self._wanted.mode, self._wanted.temp_c = None, value
            if self.controller.phase is not GraspPhase.STOPPED:
                self.controller.temperature.set_temperature(value)

    def set_object(self, name: str) -> None:
        """Put a catalogue object between the open fingers (``"none"``: take it away)."""
        if self._set_object is None:
            raise InputError(f"the {self.backend.info.name} backend has no object to choose: "
                             "the object is whatever is between the fingers")
        if name != "none" and name not in self.objects:
            raise InputError(f"unknown object {name!r}; known: {', '.join(self.objects)}")
        with self._lock:
            self._check_open("changing the object")
            self._set_object(None if name == "none" else name)
            self._wanted.object_name = None if name == "none" else name

    def _check_open(self, what: str) -> None:
        phase = self.controller.phase
        motor = self._obs.motor_position_mm if self._obs is not None else 0.0
        if phase not in _IDLE or motor > OPEN_TOLERANCE_MM:
            raise InputError(f"{what} needs the gripper open and idle (phase {phase.value}, "
                             f"motor at {motor:.1f} mm): release first")

    def close_grasp(self) -> None:
        """Start a grasp: reach the temperature, close to the target force, then hold."""
        self._check_running()
        with self._lock:
            self._check_open("closing")
            w = self._wanted
            plan = GraspPlan(target_n=w.target_n, mode=w.mode, temp_c=w.temp_c,
                             hold_s=math.inf, release=False)
            self.controller.start(plan, self._now())

    def hold(self) -> None:
        """Hold the force now (while closing in contact, or back from a lift)."""
        with self._lock:
            self.controller.hold(self._now())

    def lift(self, lift_mm: float = DEFAULT_LIFT_MM) -> None:
        """Lift the held object, then keep it up."""
        with self._lock:
            arm = self._obs.arm_height_mm if self._obs is not None else 0.0
            self.controller.lift(self._now(), arm, lift_mm)

    def release(self) -> None:
        """Open the fingers."""
        with self._lock:
            c = self.controller
            motor = self._obs.motor_position_mm if self._obs is not None else 0.0
            if c.phase in _IDLE and motor <= OPEN_TOLERANCE_MM:
                raise InputError("nothing to release: the gripper is open")
            if c.phase is GraspPhase.RELEASE:
                return
            c.release(self._now())

    def stop(self) -> None:
        """Stop the motor and switch the heaters off."""
        with self._lock:
            self.controller.stop(self._now())
            self._safe_off()

    def set_recording(self, on: bool) -> Path | None:
        """Start recording to a new MCAP file in :attr:`record_dir`, or stop; the file's path."""
        with self._lock:
            if not on:
                path = self.record_path
                self._stop_recording()
                return path
            if self._recorder is not None:
                return self.record_path
            self._check_running()
            stamp = dt.datetime.now().strftime("%Y%m%d-%H%M%S-%f")
            path = self.record_dir / f"relaxgrip-{stamp}.mcap"
            try:
                if self._recorder_factory is not None:
                    recorder = self._recorder_factory(path)
                else:
                    from relaxgrip.recording import McapRecorder

                    recorder = McapRecorder(path)
                recorder.start(self.backend.info, self.controller, self._now())
            except OSError as exc:  # a disk too full for its first records: the grasp goes on
                raise InputError(f"cannot record to {path}: {exc.strerror or exc}") from None
            self._recorder, self.record_path, self.record_error = recorder, path, None
            return path

    def _stop_recording(self) -> None:
        recorder, path = self._recorder, self.record_path
        self._recorder = self.record_path = None
        close = getattr(recorder, "close", None)
        if close is not None:
            try:
                close()
            except OSError as exc:  # its summary did not fit: sealed without it
                self.record_error = f"recording {path} stopped: {exc.strerror}"


def open_session(backend: str = "twin", *, clock: Clock, seed: int = 0,
                 estimator: str = "observer", object_name: str = "force_ball",
                 record_dir: Path = Path("."), models_dir: Path | None = None,
                 observer_dir: Path | None = None,
                 config: TwinConfig | None = None) -> LiveSession:
    """A session on the twin, the MCU emulator (twin behind a pty) or a rig file's gripper.

    Parameters
    ----------
    backend : str
        ``twin``, ``emulator`` or ``serial:RIG.toml``.
    clock : Clock
        Session time (a :class:`~relaxgrip.clock.WallClock` for real time).
    seed : int
        Twin seed.
    estimator : str
        ``fixed``, ``icfn``, ``relax`` or ``observer`` (the default: the
        dashboard changes the temperature while holding, which Eq. 10 of
        ``relax`` does not follow).
    object_name : str
        Twin object between the fingers at the start.
    record_dir : Path
        Where recordings go.
    models_dir : Path, optional
        Model directory (default: the shipped models).
    observer_dir : Path, optional
        The ``observer`` estimator's directory (default: the shipped one).
    config : TwinConfig, optional
        The twin of ``twin`` and ``emulator`` (default: our gripper); a serial rig
        is its rig file's gripper.

    Returns
    -------
    LiveSession
        Not yet started.
    """
    from relaxgrip.learning.observer import load_observer
    from relaxgrip.learning.store import load_models
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.perception.features import ICFN_SCHEMA, RCFN_SCHEMA
    from relaxgrip.twin import GripperTwin, TwinConfig
    from relaxgrip.twin.objects import CATALOGUE, get_object

    try:
        kind = EstimatorKind(estimator)
    except ValueError:
        known = ", ".join(k.value for k in EstimatorKind)
        raise InputError(f"unknown estimator {estimator!r}; known: {known}") from None
    if seed < 0:
        raise InputError(f"seed must be >= 0, got {seed}")
    if not (backend in ("twin", "emulator") or backend.startswith("serial:")):
        raise InputError(f"--backend must be twin, emulator or serial:RIG.toml, got {backend!r}")
    if config is not None and backend.startswith("serial:"):
        raise InputError("--rig chooses the twin's gripper; a serial backend is the gripper of "
                         "its own rig file (serial:RIG.toml): give one of them")
    get_object(object_name)
    if not record_dir.is_dir():
        raise InputError(f"recording directory {record_dir} "
                         + ("is not a directory" if record_dir.exists() else "does not exist"))
    # A recording starts at the operator's click, long after this: find out now.
    check_writable(record_dir / "relaxgrip-recording.mcap", InputError)
    bundle = load_default_models() if models_dir is None else load_models(
        models_dir, icfn_feature_schema=ICFN_SCHEMA, rcfn_feature_schema=RCFN_SCHEMA)
    observer = None if observer_dir is None else load_observer(observer_dir)
    if backend.startswith("serial:"):
        from relaxgrip.hardware.gripper import open_rig_gripper
        from relaxgrip.hardware.rig_file import load_rig

        rig = load_rig(backend.removeprefix("serial:"))
        gripper = open_rig_gripper(rig, clock)
        try:
            gripper.reset()
            controller = GraspController(rig.geometry, bundle_estimator(kind, bundle, observer),
                                         heat=rig.heat, limits=rig.limits)
        except BaseException:  # the port and the camera threads are not left open
            gripper.close()
            raise
        return LiveSession(gripper, controller, clock, record_dir=record_dir,
                           rearm=gripper.reset)
    cfg = replace(config if config is not None else TwinConfig(), object_name=object_name)
    virtual = VirtualClock(clock.now())
    controller = GraspController(cfg.rig, bundle_estimator(kind, bundle, observer),
                                 heat=cfg.heat, limits=twin_limits(cfg))
    if backend == "emulator":
        from relaxgrip.hardware.emulator import ready_emulated_gripper

        emulated = ready_emulated_gripper(cfg, seed, virtual)
        return LiveSession(emulated, controller, clock, backend_clock=virtual,
                           object_name=object_name, record_dir=record_dir)
    twin = GripperTwin(cfg, seed=seed, clock=virtual)
    return LiveSession(twin, controller, clock, backend_clock=virtual,
                       objects=tuple(CATALOGUE), set_object=twin.set_object,
                       object_name=object_name, record_dir=record_dir)
