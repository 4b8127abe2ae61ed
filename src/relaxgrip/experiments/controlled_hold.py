"""The paper's holding experiment (§V-C, Fig. "sphere"): a 280 s force-controlled hold.

The gripper closes on the force-measurement ball to the target force and
holds it for ``duration_s`` under one of the estimators (``fixed``: no
holding control; ``icfn``: instantaneous estimate only; ``relax``: ICFN +
RCFN).  The controller never reads the truth; this experiment does, to score
the hold over the steady-state interval (100–280 s of a 280 s hold, scaled
with the duration): the true force against the target, and the estimate
against the true force.

On a serial rig (``backend="serial:RIG.toml"``: real hardware, or an
emulator process standing in for it) there is no truth: the rig's force
reference (``/relaxgrip/force_ref``, tared before the grasp) is the true
force instead, interpolated at each period on its own timestamps, and the
result says so (:attr:`HoldResult.reference`).

For ``relax`` it can also say where the estimate's error comes from
(:meth:`HoldResult.error_budget`): a copy of the twin taken at the hold onset
is held at the onset's aperture, with the loop's heater duties, and its true
force is the curve Eq. 10 predicts.  The estimate's mean error over the steady
state then splits exactly into the onset force ``F_inst``, Eq. 10's relaxation
and the force of the closure the controller adds after the onset.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Command, Gripper, Observation
from relaxgrip.clock import VirtualClock
from relaxgrip.control import (
    EstimatorKind,
    EventKind,
    GraspController,
    GraspPlan,
    LoopInterrupted,
    LoopResult,
    bundle_estimator,
    check_target_n,
    run_loop,
    twin_limits,
)
from relaxgrip.control.runner import LoopRecorder
from relaxgrip.errors import InputError
from relaxgrip.experiments.profiles import Profile, band_coverage
from relaxgrip.learning.observer import ObserverModel
from relaxgrip.learning.rcfn import reconstruct
from relaxgrip.learning.store import ModelBundle
from relaxgrip.learning.training import load_default_models
from relaxgrip.limits import OUR_LIMITS
from relaxgrip.perception.proximity import ProximityTarget
from relaxgrip.twin import TWIN_VERSION, GripperTwin, TwinConfig
from relaxgrip.validate import check_positive

FloatArray = NDArray[np.float64]
_Job = TypeVar("_Job")
_Out = TypeVar("_Out")

__all__ = [
    "HOLD_TEMP_RANGE_C",
    "MAX_HOLD_S",
    "MIN_HOLD_S",
    "HoldComparison",
    "HoldInterrupted",
    "HoldResult",
    "check_backend",
    "check_hold",
    "check_hold_duration_s",
    "check_hold_temp_c",
    "check_ramp_starts",
    "check_scenario_times",
    "compare_holds",
    "map_holds",
    "reference_force_n",
    "run_hold",
    "steady_window_s",
]

#: The paper's hold and its steady-state interval (s).
PAPER_DURATION_S = 280.0
PAPER_WINDOW_S = (100.0, 280.0)
#: Hold temperatures the experiment accepts (°C): our gripper's setpoint range (its limits).
HOLD_TEMP_RANGE_C = (OUR_LIMITS.min_setpoint_c, OUR_LIMITS.max_setpoint_c)
#: Time allowed to reach the hold (zeroing, heating, closing), on top of the hold (s).
SETUP_ALLOWANCE_S = 120.0
#: The loop's rate, the camera's (Hz): a hold of ``duration_s`` lasts ``duration_s`` times
#: it periods from its onset.
CONTROL_RATE_HZ = 30.0
#: The longest hold the experiment runs (s): an hour, 108,000 periods at 30 Hz.  The
#: models were fitted on holds of 100-280 s; a day's hold would keep 2.6 million rows.
MAX_HOLD_S = 3600.0
#: The shortest: its steady state, the last 64 % (100-280 s of 280 s), then spans 19
#: periods at 30 Hz.  A shorter one scored on a frame or none.
MIN_HOLD_S = 1.0


def check_hold_temp_c(temp_c: float) -> float:
    """Return a hold temperature if our gripper's limits take it as a setpoint."""
    return OUR_LIMITS.check_setpoint_c(temp_c, "hold temperature")


def check_hold_duration_s(duration_s: float, name: str = "hold duration") -> float:
    """Return a hold length (s) if it is finite and within :data:`MIN_HOLD_S`-:data:`MAX_HOLD_S`."""
    check_positive(duration_s, name)
    if duration_s < MIN_HOLD_S:
        raise InputError(f"{name} must be at least {MIN_HOLD_S:g} s, so that its steady state "
                         f"(the last 64 %) holds frames to score, got {duration_s:g}")
    if duration_s > MAX_HOLD_S:
        raise InputError(f"{name} must be at most {MAX_HOLD_S:g} s (an hour), got {duration_s:g}")
    return float(duration_s)


def check_scenario_times(duration_s: float, **profiles: Profile | None) -> None:
    """Refuse a profile that starts at or after the hold's end: it would change nothing.

    ``profiles`` by the name the error gives them (``temp_profile``: ``--temp-profile``).
    """
    for name, profile in profiles.items():
        if profile is not None and profile.start_s >= duration_s:
            option = "--" + name.replace("_", "-")
            raise InputError(f"{option} starts at {profile.start_s:g} s, not before the "
                             f"{duration_s:g} s hold ends")


def check_ramp_starts(target_n: float, temp_c: float, temp_profile: Profile | None = None,
                      target_profile: Profile | None = None) -> None:
    """Refuse a ramp that does not start from the hold's own target or temperature.

    The profile's ``before`` holds from the hold's onset to the ramp's start, so
    a ramp from another value would make the target or the setpoint jump at the
    onset, which no ramp asks for.  A step starts from the hold's value anyway.
    """
    ramps = ((target_profile, target_n, "--target-profile", "target", "N", "--target-n"),
             (temp_profile, temp_c, "--temp-profile", "temperature", "°C", "--temp-c"))
    for profile, held, option, what, unit, given in ramps:
        if profile is not None and not math.isnan(profile.before) and profile.before != held:
            raise InputError(f"{option} ramps from {profile.before:g} {unit} but the hold's "
                             f"{what} is {held:g} {unit} ({given}): the ramp must start from it")


def steady_window_s(duration_s: float) -> tuple[float, float]:
    """The steady-state interval of a hold: the paper's 100–280 s, scaled with the duration."""
    scale = duration_s / PAPER_DURATION_S
    return PAPER_WINDOW_S[0] * scale, PAPER_WINDOW_S[1] * scale


@dataclass(frozen=True)
class HoldResult:
    """One controlled hold, sampled at the control rate from the hold onset.

    Attributes
    ----------
    estimator : str
        ``fixed``, ``icfn`` or ``relax``.
    target_n, temp_c, duration_s : float
        Target force (N), finger temperature (°C), hold length (s).
    seed : int
        Twin seed.
    t_s : ndarray
        Time since the hold onset (s).
    truth_n, estimate_n : ndarray
        True contact force and the controller's estimate (N).
    loop : LoopResult
        The whole run (every series, phase log).
    twin_version : str
        Twin that produced it.
    target_series_n : ndarray or None
        The target at each sample when a target profile changed it.
    fixed_aperture_n : ndarray or None
        True force of a copy of the twin held at the onset's aperture from the
        onset on, at ``t_s`` (N); only for a hold run with ``budget=True``.
    twin_scatter : dict of str to float or None
        The run's scatter as the twin drew it (:meth:`relaxgrip.twin.twin.TwinMaterial.scatter`),
        ground truth beside the budget; only for a hold run with ``budget=True``.
    interrupted : bool
        The hold was stopped before its end (Ctrl-C, ``kill``, a hang-up): the
        series end where it stopped, and the figures are those of the part of
        the steady state it reached (none if it reached none).
    reference : str
        What ``truth_n`` is: ``truth`` (the twin's contact force) or
        ``force_ref`` (the rig's force reference, a serial rig having no truth).
    """

    estimator: str
    target_n: float
    temp_c: float
    duration_s: float
    seed: int
    t_s: FloatArray
    truth_n: FloatArray
    estimate_n: FloatArray
    loop: LoopResult
    twin_version: str = TWIN_VERSION
    target_series_n: FloatArray | None = None
    fixed_aperture_n: FloatArray | None = None
    twin_scatter: dict[str, float] | None = None
    interrupted: bool = False
    reference: str = "truth"

    @property
    def target_t_n(self) -> FloatArray:
        """The target at each sample (N): constant unless a target profile changed it."""
        if self.target_series_n is None:
            return np.full(self.t_s.shape, self.target_n)
        return self.target_series_n

    @property
    def window(self) -> tuple[float, float]:
        """The steady-state interval (s since the onset)."""
        return steady_window_s(self.duration_s)

    def series(self, name: str) -> FloatArray:
        """A column of the loop over the hold's samples (aligned with ``t_s``)."""
        t_loop = self.loop["t_s"] - (self.loop.hold_onset_s() or 0.0)
        rows = (t_loop >= 0.0) & (t_loop <= self.duration_s + 1e-9)
        out: FloatArray = self.loop[name][rows]
        return out

    def _mask(self) -> NDArray[np.bool_]:
        lo, hi = self.window
        # A force reference has no reading at the edges of its coverage: those samples go.
        return (self.t_s >= lo - 1e-9) & (self.t_s <= hi + 1e-9) & np.isfinite(self.truth_n)

    def metrics(self) -> dict[str, Any]:
        """The paper's hold statistics over the steady-state interval.

        ``iqr_n`` is the quartiles of the signed error (the issue's);
        ``abs_error_iqr_n`` those of its size, the paper's "interquartile range
        of [0.055, 0.076] N" beside its MAE of 0.066 N (a range of the signed
        error could not leave out its median of -0.041 N).

        Besides them, ``onset_error_n``: the true force at the hold's onset
        less the target, where the estimator stopped the closing.  A fixed
        aperture's error over the steady state follows it: that aperture
        holds what the onset reading left, less the finger's relaxation.
        """
        mask = self._mask()
        if not mask.any():
            raise InputError("the hold ended before its steady-state interval")
        err = self.truth_n[mask] - self.target_t_n[mask]
        est = self.estimate_n[mask] - self.truth_n[mask]
        est = est[np.isfinite(est)]
        q25, q75 = np.percentile(err, [25, 75])
        a25, a75 = np.percentile(np.abs(err), [25, 75])
        coverage = band_coverage(self.truth_n, self.series("band_lo_n"),
                                 self.series("band_hi_n"))
        extra = {} if math.isnan(coverage) else {"band_coverage": coverage}
        return {**extra,
            "mae_n": float(np.mean(np.abs(err))),
            "rmse_n": float(np.sqrt(np.mean(err * err))),
            "mean_signed_error_n": float(np.mean(err)),
            "median_signed_error_n": float(np.median(err)),
            "iqr_n": [float(q25), float(q75)],
            "abs_error_iqr_n": [float(a25), float(a75)],
            "est_error_mean_n": float(np.mean(est)) if est.size else math.nan,
            "est_rmse_n": float(np.sqrt(np.mean(est * est))) if est.size else math.nan,
            "onset_error_n": float(self.truth_n[0] - self.target_t_n[0]),
        }

    def error_budget(self) -> dict[str, float]:
        """Where ``relax``'s estimate error over the steady state comes from (N).

        With ``F_fix(t)`` the true force of the twin held at the onset's
        aperture, ``F_inst``, ``K`` and ``tau`` the estimator's Eq. 10 and
        ``F_est`` its estimate, the mean of ``F_est - F_true`` over the steady
        state is the sum of

        * ``onset_n``: ``F_inst - F_fix(0)``, the onset force as read;
        * ``relaxation_n``: the true fixed-aperture relaxation
          ``F_fix(0) - F_fix(t)`` less Eq. 10's ``K (1 - exp(-t / tau))``
          (negative when Eq. 10 predicts more relaxation than the twin shows);
        * ``closure_n``: what the estimator adds to Eq. 10 (the closure since the
          onset) less what that closure adds to the true force, ``F_true - F_fix``;
        * ``calibration_n``, with a calibrated model directory only: the
          calibrated closed-loop error taken off the estimate (negative when
          the calibration found the estimate high);
        * ``chain_n``, when the closed chain's reading was blended in
          (:mod:`relaxgrip.control.chain`): what it added to the estimate.

        ``total_n`` is their sum, the mean estimate error.

        Raises
        ------
        InputError
            If the hold was not run with ``budget=True``.
        """
        if self.fixed_aperture_n is None:
            raise InputError("no error budget: run the relax hold with budget=True (--budget)")
        mask = self._mask()
        columns = np.vstack([self.series(name)[mask]
                             for name in ("hold_s", "f_onset_n", "k_n", "tau_s")])
        est, truth, fixed = self.estimate_n[mask], self.truth_n[mask], self.fixed_aperture_n[mask]
        ok = np.all(np.isfinite(np.vstack([columns, est])), axis=0)
        if not ok.any():
            raise InputError("no error budget: the estimator gave no Eq. 10 terms in the "
                             "steady state")
        hold_s, f_inst, k_n, tau_s = columns[:, ok]
        eq10 = reconstruct(hold_s, f_inst, k_n, tau_s)
        est, truth, fixed = est[ok], truth[ok], fixed[ok]
        calibrated = self.series("calibration_n")[mask][ok]
        calibration = np.nan_to_num(calibrated)
        chained = self.series("chain_n")[mask][ok]
        chain = np.nan_to_num(chained)
        f_fix0 = self.fixed_aperture_n[0]
        out = {"onset_n": float(np.mean(f_inst - f_fix0)),
               "relaxation_n": float(np.mean((f_fix0 - fixed) - (f_inst - eq10))),
               "closure_n": float(np.mean((est - chain + calibration - eq10)
                                          - (truth - fixed)))}
        if np.isfinite(calibrated).any():
            out["calibration_n"] = -float(np.mean(calibration))
        if np.isfinite(chained).any():
            out["chain_n"] = float(np.mean(chain))
        out["total_n"] = sum(out.values())
        return out

    @property
    def held_s(self) -> float:
        """How long the hold ran from its onset (s; 0 if it never started)."""
        return float(self.t_s[-1]) if self.t_s.size else 0.0

    @property
    def reference_note(self) -> dict[str, str]:
        """What the figures' true force is, for a hold without the twin's truth."""
        if self.reference == "truth":
            return {}
        return {"reference": self.reference,
                "reference_note": "no ground truth on this backend: the true force of every "
                                  "figure is the rig's force reference (/relaxgrip/force_ref), "
                                  "tared before the grasp"}

    def to_dict(self) -> dict[str, Any]:
        """The ``relaxgrip hold --json`` object (``"interrupted": true`` for a stopped one)."""
        lo, hi = self.window
        if self.interrupted:
            figures = self.metrics() if self._mask().any() else {}
            return {
                "interrupted": True, **self.reference_note, "twin_version": self.twin_version,
                "estimator": self.estimator, "target_n": self.target_n, "temp_c": self.temp_c,
                "seed": self.seed, "duration_s": self.duration_s, "held_s": self.held_s,
                "window_s": [lo, hi], **figures,
                "events": [e.to_dict() for e in self.loop.log.events],
            }
        budget = {} if self.fixed_aperture_n is None else {"error_budget": self.error_budget()}
        if self.twin_scatter is not None:
            budget["twin_scatter"] = self.twin_scatter
        return {
            **self.reference_note,
            "twin_version": self.twin_version, "estimator": self.estimator,
            "target_n": self.target_n, "temp_c": self.temp_c, "seed": self.seed,
            "duration_s": self.duration_s, "window_s": [lo, hi], **self.metrics(), **budget,
            "events": [e.to_dict() for e in self.loop.log.events],
        }


class HoldInterrupted(KeyboardInterrupt):
    """A stop signal ended :func:`run_hold`; :attr:`result` is the hold so far
    (:attr:`HoldResult.interrupted`).  The motor was stopped and the heaters switched off."""

    def __init__(self, result: HoldResult) -> None:
        super().__init__("interrupted")
        self.result = result


def check_hold(estimator: EstimatorKind | str, target_n: float, temp_c: float,
               duration_s: float) -> EstimatorKind:
    """The estimator named, once every argument of a hold is checked."""
    try:
        kind = EstimatorKind(estimator)
    except ValueError:
        known = ", ".join(k.value for k in EstimatorKind)
        raise InputError(f"unknown estimator {estimator!r}; known: {known}") from None
    check_target_n(target_n)
    check_hold_temp_c(temp_c)
    check_hold_duration_s(duration_s)
    return kind


#: Backends a hold runs on: the twin itself, or the twin behind the MCU emulator; and
#: ``serial:RIG.toml``, the gripper a rig file names (:data:`SERIAL_PREFIX`).
HOLD_BACKENDS = ("twin", "emulator")
#: A backend ``serial:RIG.toml``: the real gripper (or an emulator process) of that rig file.
SERIAL_PREFIX = "serial:"
#: Time allowed on a serial rig to reach the hold, on top of it (s): its fingers start at
#: room temperature and heat to the hold's (1-3 min at full duty).
SERIAL_SETUP_ALLOWANCE_S = 300.0
#: The MCU behind the emulator: the protocol's Python state machine, or the compiled
#: firmware in simavr (docs/firmware.md).
HOLD_MCUS = ("python", "firmware")


def check_mcu(mcu: str, backend: str) -> str:
    """``mcu`` if the emulator can run it for ``backend``.

    Raises
    ------
    InputError
        An unknown MCU, or the firmware asked of the twin backend (it has no MCU).
    """
    if mcu not in HOLD_MCUS:
        raise InputError(f"--mcu must be python or firmware, got {mcu!r}")
    if mcu == "firmware" and backend != "emulator":
        raise InputError("--mcu firmware runs the firmware behind the emulator: use it with "
                         "--backend emulator")
    return mcu


def check_backend(backend: str, disturbance: Profile | None = None) -> str:
    """``backend`` if a hold can run on it (a push on the object needs the twin itself).

    Raises
    ------
    InputError
        An unknown backend, or a disturbance asked of the emulator.
    """
    if backend.startswith(SERIAL_PREFIX):
        if not backend.removeprefix(SERIAL_PREFIX):
            raise InputError("--backend serial:RIG.toml names the rig file after 'serial:'")
    elif backend not in HOLD_BACKENDS:
        raise InputError(f"unknown backend {backend!r}; known: {', '.join(HOLD_BACKENDS)}, "
                         "serial:RIG.toml")
    if disturbance is not None and backend != "twin":
        raise InputError("a disturbance (a push on the object) needs the twin backend")
    return backend


def _make_backend(backend: str, cfg: TwinConfig, seed: int, clock: VirtualClock,
                  mcu: str = "python") -> Gripper:
    """The twin, or the twin behind an in-process MCU emulator on a pty (reset, ready)."""
    if backend == "twin":
        return GripperTwin(cfg, seed=seed, clock=clock)
    from relaxgrip.hardware.emulator import ready_emulated_gripper

    return ready_emulated_gripper(cfg, seed, clock, firmware=mcu == "firmware")


def run_hold(
    estimator: EstimatorKind | str = EstimatorKind.RELAX,
    target_n: float = 5.0,
    duration_s: float = PAPER_DURATION_S,
    temp_c: float = 40.0,
    seed: int = 0,
    models: ModelBundle | None = None,
    config: TwinConfig | None = None,
    backend: str = "twin",
    recorder: LoopRecorder | None = None,
    temp_profile: Profile | None = None,
    target_profile: Profile | None = None,
    disturbance: Profile | None = None,
    observer: ObserverModel | None = None,
    budget: bool = False,
    locate_object: bool = True,
    mcu: str = "python",
) -> HoldResult:
    """Close on the force ball to ``target_n`` at ``temp_c`` and hold it for ``duration_s``.

    Parameters
    ----------
    estimator : {"fixed", "icfn", "relax"}
        Force estimator (and, for ``fixed``, no regulation during the hold).
    target_n : float
        Target force (N), in (0, 10].
    duration_s : float
        Hold length after the onset (s).
    temp_c : float
        Finger temperature (°C), held by the temperature loop on the infrared
        readings; the fingers start there.
    seed : int
        Twin seed (the run's scatter and noise).
    models : ModelBundle, optional
        ICFN and RCFN (default: the shipped models).
    config : TwinConfig, optional
        Twin (default: our gripper, the force ball at its usual contact, cameras on;
        :func:`relaxgrip.hardware.rig_twin.twin_config_for_rig` gives any rig's).
    backend : {"twin", "emulator", "serial:RIG.toml"}
        ``twin`` drives the twin directly; ``emulator`` puts the same twin
        behind the MCU emulator, so that every command and frame crosses a
        real pseudo-terminal serial link (in virtual-time lockstep);
        ``serial:RIG.toml`` holds on the gripper that rig file names, in
        wall-clock time, scored against its force reference (``config`` and
        ``seed`` are the twin's: not used).
    recorder : LoopRecorder, optional
        Records every period (e.g. :class:`relaxgrip.recording.McapRecorder`);
        the caller closes it.
    temp_profile, target_profile, disturbance : Profile, optional
        Temperature setpoint (°C), force target (N) and push on the object (N,
        twin backend only) over the hold time (:mod:`relaxgrip.experiments.profiles`).
    observer : ObserverModel, optional
        The ``observer`` estimator's parameters (default: the shipped ones).
    budget : bool
        Also hold a copy of the twin at the onset's aperture, for
        :meth:`HoldResult.error_budget` (``relax`` on the twin backend only).
    locate_object : bool
        Have perception find the object (its catalogue width and colour) while
        the motor settles before the hold, the closed chain take its marker
        share from where it sits and read the other finger in the infrared
        frame there (beyond the paper; ``ChainParams.ir_weight``).  False:
        the operator does not say what is grasped, and the chain guesses the
        other finger from the marker's.
    mcu : {"python", "firmware"}
        The emulator's MCU: the protocol's Python state machine, or the compiled
        firmware in simavr (``backend="emulator"`` only).

    Returns
    -------
    HoldResult

    Raises
    ------
    InputError
        A target, temperature or estimator out of range; a ramp that does not
        start from the hold's target or temperature (:func:`check_ramp_starts`);
        a budget asked of another estimator or backend; or the hold never
        started (no contact, target out of reach).
    """
    kind = check_hold(estimator, target_n, temp_c, duration_s)
    check_scenario_times(duration_s, temp_profile=temp_profile, target_profile=target_profile,
                         disturbance=disturbance)
    check_ramp_starts(target_n, temp_c, temp_profile, target_profile)
    check_backend(backend, disturbance)
    check_mcu(mcu, backend)
    if budget and (kind is not EstimatorKind.RELAX or backend != "twin"):
        raise InputError("an error budget splits relax's Eq. 10 on the twin: use --estimator "
                         "relax with the twin backend")
    bundle = models if models is not None else load_default_models()
    if backend.startswith(SERIAL_PREFIX):
        if config is not None:
            raise InputError("a serial backend is the gripper of its own rig file "
                             "(serial:RIG.toml): no twin config with it")
        return _serial_hold(kind, target_n, duration_s, temp_c, seed, bundle,
                            backend.removeprefix(SERIAL_PREFIX), recorder, temp_profile,
                            target_profile, observer, locate_object)
    base = config if config is not None else TwinConfig()
    cfg = replace(base, initial_temp_c=temp_c)
    clock = VirtualClock()
    twin = _make_backend(backend, cfg, seed, clock, mcu)
    try:  # closed however it ends: the emulator's thread and pty with it
        controller = GraspController(cfg.rig, bundle_estimator(kind, bundle, observer),
                                     heat=cfg.heat, limits=twin_limits(cfg))
        plan = GraspPlan(target_n=target_n, temp_c=temp_c, hold_s=duration_s, release=False,
                         grasped=_as_known(cfg) if locate_object else None)
        on_step = _scenario(twin, temp_profile, target_profile, disturbance, temp_c, target_n)
        frozen: list[GripperTwin] = []
        if budget:
            assert isinstance(twin, GripperTwin)
            on_step = _copy_at_onset(twin, frozen, on_step)
        try:
            loop = run_loop(twin, controller, clock, plan, duration_s + SETUP_ALLOWANCE_S,
                            rate_hz=CONTROL_RATE_HZ, recorder=recorder, on_step=on_step)
        except LoopInterrupted as stopped:
            loop, interrupted = stopped.result, True
        else:
            interrupted = False
    finally:
        twin.close()
    onset = loop.hold_onset_s()
    if interrupted:
        t = loop["t_s"] - (math.inf if onset is None else onset)  # never started: no samples
        keep = (t >= 0.0) & (t <= duration_s + 1e-9)
        raise HoldInterrupted(HoldResult(
            kind.value, target_n, temp_c, duration_s, seed, t[keep],
            loop["truth_force_n"][keep], loop["estimate_n"][keep], loop,
            target_series_n=None if target_profile is None
            else target_profile.values(t[keep], target_n), interrupted=True))
    if onset is None:
        events = "; ".join(loop.log.summary())
        raise InputError(f"the hold never started ({events or 'no contact'})")
    t = loop["t_s"] - onset
    keep = (t >= 0.0) & (t <= duration_s + 1e-9)
    targets = None if target_profile is None else target_profile.values(t[keep], target_n)
    fixed = scatter = None
    if frozen:
        # The push the loop's twin felt from each step on (the scenario sets it after it).
        hold_s = loop["hold_s"][keep]
        pushes = (np.zeros(hold_s.size) if disturbance is None else
                  np.array([disturbance.value_at(h, 0.0) if math.isfinite(h) else 0.0
                            for h in hold_s]))
        fixed = _hold_aperture(frozen[0], loop["t_s"][keep], loop["duty_0"][keep],
                               loop["duty_1"][keep], pushes)
        scatter = frozen[0].material.scatter()
    return HoldResult(kind.value, target_n, temp_c, duration_s, seed, t[keep],
                      loop["truth_force_n"][keep], loop["estimate_n"][keep], loop,
                      target_series_n=targets, fixed_aperture_n=fixed, twin_scatter=scatter)


def _serial_hold(kind: EstimatorKind, target_n: float, duration_s: float, temp_c: float,
                 seed: int, bundle: ModelBundle, rig_path: str, recorder: LoopRecorder | None,
                 temp_profile: Profile | None, target_profile: Profile | None,
                 observer: ObserverModel | None, locate_object: bool) -> HoldResult:
    """:func:`run_hold` on the gripper of a rig file, scored against its force reference."""
    from relaxgrip.clock import WallClock
    from relaxgrip.hardware.gripper import open_rig_gripper
    from relaxgrip.hardware.rig_file import load_rig
    from relaxgrip.perception.marker import warm_up

    rig = load_rig(rig_path)
    rig.limits.check_target_n(target_n)
    rig.limits.check_setpoint_c(temp_c)
    clock = WallClock()
    # Everything slow first: once enabled, the MCU's watchdog wants a command every 200 ms.
    controller = GraspController(rig.geometry, bundle_estimator(kind, bundle, observer),
                                 heat=rig.heat, limits=rig.limits)
    warm_up()
    gripper = open_rig_gripper(rig, clock)
    try:  # closed however it ends: motor stopped, heaters off, MCU disabled
        gripper.reset()
        gripper.tare_force_ref()  # the fingers open: nothing touches the force ball yet
        ball = rig.force_ball
        grasped = ProximityTarget(ball.width_m, ball.color_rgb,
                                  grasp_position_m=rig.finger.contact_m)
        plan = GraspPlan(target_n=target_n, temp_c=temp_c, hold_s=duration_s, release=False,
                         grasped=grasped if locate_object else None)
        on_step = _scenario(gripper, temp_profile, target_profile, None, temp_c, target_n)
        try:
            loop = run_loop(gripper, controller, clock, plan,
                            duration_s + SERIAL_SETUP_ALLOWANCE_S, rate_hz=CONTROL_RATE_HZ,
                            recorder=recorder, on_step=on_step)
        except LoopInterrupted as stopped:
            loop, interrupted = stopped.result, True
        else:
            interrupted = False
        version = f"{gripper.info.name} rig {rig.name!r}: {gripper.info.version}"
    finally:
        gripper.close()
    reference = reference_force_n(loop)
    onset = loop.hold_onset_s()
    if onset is None and not interrupted:
        events = "; ".join(loop.log.summary())
        raise InputError(f"the hold never started ({events or 'no contact'})")
    t = loop["t_s"] - (math.inf if onset is None else onset)
    keep = (t >= 0.0) & (t <= duration_s + 1e-9)
    targets = None if target_profile is None else target_profile.values(t[keep], target_n)
    result = HoldResult(kind.value, target_n, temp_c, duration_s, seed, t[keep],
                        reference[keep], loop["estimate_n"][keep], loop, twin_version=version,
                        target_series_n=targets, interrupted=interrupted,
                        reference="force_ref")
    if interrupted:
        raise HoldInterrupted(result)
    return result


#: Longest gap between two force-reference readings that a loop period's reference is
#: interpolated across (s).
MAX_REFERENCE_GAP_S = 0.5


def reference_force_n(loop: LoopResult) -> FloatArray:
    """The force reference at each period of ``loop`` (N): its readings (columns
    ``force_ref_t_s``, ``force_ref_n``) interpolated on their own timestamps; nan outside
    them and in a gap longer than :data:`MAX_REFERENCE_GAP_S`."""
    t_ref, f_ref = loop["force_ref_t_s"], loop["force_ref_n"]
    ok = np.isfinite(t_ref) & np.isfinite(f_ref)
    t_ref, f_ref = t_ref[ok], f_ref[ok]
    t = loop["t_s"]
    out = np.full(t.shape, math.nan)
    if t_ref.size < 2:
        return out
    order = np.argsort(t_ref, kind="stable")
    t_ref, f_ref = t_ref[order], f_ref[order]
    inside = (t >= t_ref[0]) & (t <= t_ref[-1])
    k = np.clip(np.searchsorted(t_ref, t, side="right"), 1, t_ref.size - 1)
    short = (t_ref[k] - t_ref[k - 1]) <= MAX_REFERENCE_GAP_S
    out[inside & short] = np.interp(t[inside & short], t_ref, f_ref)
    return out


def _as_known(config: TwinConfig) -> ProximityTarget | None:
    """The held object as the operator knows it: its width and colour (the rig's force ball's)."""
    spec = config.object
    return None if spec is None else ProximityTarget(spec.width_m, spec.color_rgb,
                                                     grasp_position_m=config.contact_position_m)


def _copy_at_onset(twin: GripperTwin, into: list[GripperTwin],
                   then: Callable[[Observation, GraspController], bool | None] | None,
                   ) -> Callable[[Observation, GraspController], bool | None]:
    """A loop hook that copies the twin once, at the step the hold onset is logged."""

    def step(obs: Observation, controller: GraspController) -> bool | None:
        if not into and any(e.kind is EventKind.HOLD_ONSET for e in controller.log.events):
            into.append(copy.deepcopy(twin))
        return None if then is None else then(obs, controller)

    return step


def _hold_aperture(twin: GripperTwin, t_s: FloatArray, duty_0: FloatArray,
                   duty_1: FloatArray, push_n: FloatArray) -> FloatArray:
    """True force of ``twin`` (a copy from the onset) at ``t_s``, its motor stopped.

    The heaters follow the loop's duties, so the copy's temperature follows
    the loop's, and a push (``push_n``, set at each step for the period after
    it) pushes it as it pushed the loop's object; only the aperture differs.
    """
    out = np.empty(t_s.size)
    out[0] = twin.contact_force_n
    for k in range(1, t_s.size):
        twin.set_external_force(float(push_n[k - 1]))
        twin.clock.sleep_until(float(t_s[k]))
        twin.act(Command(0.0, (float(duty_0[k]), float(duty_1[k]))))
        out[k] = twin.contact_force_n
    twin.close()
    return out


def _scenario(backend: Gripper, temp: Profile | None, target: Profile | None,
              push: Profile | None, temp_c: float, target_n: float
              ) -> Callable[[Observation, GraspController], bool | None] | None:
    """The loop's per-step hook that applies the profiles at their hold times."""
    if temp is None and target is None and push is None:
        return None
    pushed: GripperTwin | None = None
    if push is not None:
        assert isinstance(backend, GripperTwin), "check_backend refuses a push off the twin"
        pushed = backend

    def step(obs: Observation, controller: GraspController) -> None:
        hold_s = controller.estimate.hold_s
        if not math.isfinite(hold_s):
            return
        if temp is not None:
            value = temp.value_at(hold_s, temp_c)
            if value != controller.temperature.setpoint_c:
                controller.temperature.set_temperature(value)
        if target is not None:
            value = target.value_at(hold_s, target_n)
            if value != controller.plan.target_n:
                controller.set_target(value)
        if push is not None and pushed is not None:
            pushed.set_external_force(push.value_at(hold_s, 0.0))

    return step


@dataclass(frozen=True)
class HoldComparison:
    """The three estimators on the same seed (the paper's Fig. "sphere" b–f).

    Attributes
    ----------
    holds : dict of str to HoldResult
        By estimator name, in the paper's order.
    """

    holds: dict[str, HoldResult]

    def reductions(self) -> dict[str, float]:
        """MAE reduction of ``relax`` over the paper's baselines (share, 0.8 = 80 %)."""
        if "relax" not in self.holds:
            return {}
        ours = self.holds["relax"].metrics()["mae_n"]
        return {f"vs_{name}": 1.0 - ours / hold.metrics()["mae_n"]
                for name, hold in self.holds.items() if name in ("fixed", "icfn")}

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form: each hold's figures and the reductions."""
        return {"holds": {name: hold.to_dict() for name, hold in self.holds.items()},
                "mae_reduction": self.reductions()}


def _one_thread(run: Callable[[_Job], _Out], job: _Job) -> _Out:
    """``run(job)`` with OpenCV on one thread (the parallelism is across holds)."""
    import cv2

    cv2.setNumThreads(1)
    return run(job)


def map_holds(run: Callable[[_Job], _Out], jobs: Sequence[_Job],
              n_jobs: int = 1) -> list[_Out]:
    """``run`` on every job, results in order, ``n_jobs`` holds at once (joblib)."""
    if n_jobs > 1 and len(jobs) > 1:
        from joblib import Parallel, delayed

        return list(Parallel(n_jobs=min(n_jobs, len(jobs)))(
            delayed(_one_thread)(run, job) for job in jobs))
    return [_one_thread(run, job) for job in jobs]


def _run_one(args: tuple[str, float, float, float, int, ModelBundle, ObserverModel | None,
                         TwinConfig | None]) -> HoldResult:
    kind, target, duration, temp, seed, models, observer, config = args
    return run_hold(kind, target, duration, temp, seed, models, config=config,
                    observer=observer)


def compare_holds(
    estimators: Sequence[str] = tuple(EstimatorKind),
    target_n: float = 5.0,
    duration_s: float = PAPER_DURATION_S,
    temp_c: float = 40.0,
    seed: int = 0,
    models: ModelBundle | None = None,
    n_jobs: int = 1,
    observer: ObserverModel | None = None,
    config: TwinConfig | None = None,
) -> HoldComparison:
    """Run each estimator (every one by default) on the same seed (in parallel with
    ``n_jobs`` > 1), on the twin ``config`` (our gripper by default)."""
    for kind in estimators:
        check_hold(kind, target_n, temp_c, duration_s)
    bundle = models if models is not None else load_default_models()
    jobs = [(k, target_n, duration_s, temp_c, seed, bundle, observer, config)
            for k in estimators]
    results = map_holds(_run_one, jobs, n_jobs)
    return HoldComparison({r.estimator: r for r in results})
