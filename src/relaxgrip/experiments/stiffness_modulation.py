"""The paper's Fig. "grasp": force perception under stiffness modulation, and closed-loop grasps.

Two parts, both on the twin, both read through perception (the truth only
scores them):

**(a) Single-finger contacts** (Fig. "grasp" a–c).  A feather, a brush and a
wrench are pressed against the marker finger at the three stiffness states
(stiff: heaters off at room temperature, ≈22 °C; medium ≈40 °C; compliant
≈58 °C, held by the temperature loop on the infrared readings).  The *contact
stroke* is modelled as a displacement-controlled indentation: the other finger
is replaced by a rigid jaw (:attr:`relaxgrip.twin.TwinConfig.rigid_finger`)
that the motor drives as an indenter.  It stops :data:`STROKE_GAP_MM` short of
the object (whose width the experimenter knows), rests while the noise floor
is recorded, presses the object a fixed travel into the finger at a fixed
speed, dwells, and retracts (:class:`ContactStroke`, one per object:
:data:`STROKES`).  At a fixed travel the force is that of the finger and the
object in series, so a stiffer (colder) finger takes more force and, at the
same speed, a steeper rise; a soft object (feather, brush) takes most of the
travel itself, and the finger's deflection, the signal perception reads,
grows as the finger softens.  The estimate is the ICFN on the perceived
features (:class:`relaxgrip.control.IcfnEstimator`, the controller's
smoothing); per state the run reports the peak force and force rate, true and
estimated, the estimate's noise floor and whether the contact was detected.

**(b) Closed-loop grasps** (Fig. "grasp" d–f): the grasp controller runs
Open, Close, Hold, Lift and Sustain on a hammer at 5 N (stiff), an orange at
6 N (medium) and a balloon at 0.3 N (compliant).  The estimator is ``relax``
(:data:`GRASP_ESTIMATOR`): before the hold it reads each frame's force as
the unrelaxed ICFN times the share the loading history retains
(:mod:`relaxgrip.learning.history`), through the hold Eq. 10.  The paper's
per-frame ``icfn``, trained on samples up to 11 N, reads the balloon's 0.3 N
fingertip pinch (at 105 mm, beyond the datasets' 45-100 mm contacts) 0.1 N
high: the true force in Sustain was 0.19 N on seed 0, outside the band, and
the grasp failed on seeds 0-2, where ``relax`` holds 0.238 / 0.252 / 0.276 N
in Sustain.  The hammer and the orange are held with either, on seeds 0-2.
(With the ICFN's samples up to 8 N, ``icfn`` held the balloon at 0.243 /
0.244 / 0.257 N.)

The balloon (110 mm across) is pinched at the fingertips
(:data:`BALLOON_CONTACT_M`): held mid-finger it hides the outer beams from the
base-mounted infrared camera, the beams read the balloon's temperature and the
ICFN, fed those features, reads −2.5 N at 0.3 N.  A grasp succeeds when the
object is lifted and still held at the end of Sustain, never crushed, never
slipping (all twin truth), and the true force stays within
:func:`force_band_n` of the target from the hold onset to the end of Sustain.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import BackendInfo, Command, Observation
from relaxgrip.clock import VirtualClock
from relaxgrip.control import (
    MODE_SETPOINTS_C,
    EstimatorKind,
    GraspController,
    GraspPhase,
    GraspPlan,
    IcfnEstimator,
    LoopResult,
    StiffnessMode,
    TemperatureLoop,
    bundle_estimator,
    check_target_n,
    run_loop,
    twin_limits,
)
from relaxgrip.control.phases import PHASES
from relaxgrip.errors import InputError
from relaxgrip.experiments.tasks import TaskResult, finite_figures
from relaxgrip.learning.store import ModelBundle
from relaxgrip.learning.training import load_default_models
from relaxgrip.perception.features import marker_pose
from relaxgrip.perception.pipeline import Perception
from relaxgrip.perception.thermal import ThermalPerception
from relaxgrip.serialize import json_safe
from relaxgrip.twin import TWIN_VERSION, GripperTwin, TwinConfig, get_object
from relaxgrip.validate import check_positive

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = [
    "BALLOON_CONTACT_M",
    "CONTACT_MODES",
    "CONTACT_OBJECTS",
    "GRASP_ESTIMATOR",
    "GRASP_TASKS",
    "ROOM_C",
    "STROKES",
    "ContactRun",
    "ContactStroke",
    "GraspRun",
    "GraspTask",
    "StiffnessModulationResult",
    "balloon_task",
    "brush_task",
    "feather_task",
    "force_band_n",
    "hammer_task",
    "orange_task",
    "run_contact",
    "run_grasp",
    "run_stiffness_modulation",
    "wrench_task",
]

#: Room temperature of these experiments (°C): the stiff state, heaters off (paper ≈22 °C).
ROOM_C = 22.0
#: The stiffness states of the single-finger contacts, stiffest first.
CONTACT_MODES: tuple[StiffnessMode, ...] = (
    StiffnessMode.STIFF, StiffnessMode.MEDIUM, StiffnessMode.COMPLIANT)
#: The objects of the single-finger contacts, in the paper's order.
CONTACT_OBJECTS: tuple[str, ...] = ("feather", "brush", "wrench")
#: The indenter stops this far short of the object before the stroke (mm).
STROKE_GAP_MM = 1.0
#: Least-squares window of the force rates (s): a few camera frames, so that
#: the estimate's frame-to-frame noise does not dominate its rate.
RATE_WINDOW_S = 0.2
#: A contact counts as detected when the estimate or the marker deflection
#: rises this many baseline standard deviations above its baseline mean.
DETECTION_SNR = 5.0
#: The estimator of the closed-loop grasps (see the module docstring).
GRASP_ESTIMATOR = EstimatorKind.RELAX
#: Contact position of the balloon pinch (m): at the fingertips (see the module docstring).
BALLOON_CONTACT_M = 0.105
#: Relative half-width of the force band of a grasp, and its floor (N).
BAND_REL = 0.15
BAND_MIN_N = 0.1


@dataclass(frozen=True)
class ContactStroke:
    """The indentation of one single-finger contact.

    Attributes
    ----------
    travel_mm : float
        How far the indenter presses past first touch (mm).
    speed_mm_s : float
        Press and retract speed (mm/s).
    dwell_s : float
        Time at full travel (s).
    rest_s : float
        Rest before the press (the noise floor is recorded over it) and after
        the retract (s).
    """

    travel_mm: float
    speed_mm_s: float = 10.0
    dwell_s: float = 1.0
    rest_s: float = 1.0

    def __post_init__(self) -> None:
        check_positive(self.travel_mm, "stroke travel")
        check_positive(self.speed_mm_s, "stroke speed")
        check_positive(self.dwell_s, "dwell time")
        check_positive(self.rest_s, "rest time")

    @property
    def ramp_s(self) -> float:
        """Duration of the press (and of the retract) (s)."""
        return (self.travel_mm + STROKE_GAP_MM) / self.speed_mm_s

    def to_dict(self) -> dict[str, float]:
        """Plain-Python form."""
        return {"travel_mm": self.travel_mm, "speed_mm_s": self.speed_mm_s,
                "dwell_s": self.dwell_s, "rest_s": self.rest_s}


#: One stroke per object: most of a feather's and a brush's width (they are far
#: softer than the finger and take the travel themselves), a few millimetres of a
#: wrench (rigid: the finger takes it all, ≈4 N in the stiff state).
STROKES: dict[str, ContactStroke] = {
    "feather": ContactStroke(travel_mm=8.0),
    "brush": ContactStroke(travel_mm=10.0),
    "wrench": ContactStroke(travel_mm=3.0),
}


def rate_n_per_s(t_s: FloatArray, force_n: FloatArray, window_s: float = RATE_WINDOW_S
                 ) -> FloatArray:
    """Force rate by a centred least-squares slope over ``window_s`` (N/s).

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Uniformly sampled times (s).
    force_n : ndarray, shape (n,)
        Force (N); nan samples give nan rates where they enter the window.
    window_s : float
        Window length (s); at least three samples.

    Returns
    -------
    ndarray, shape (n,)
        Slope at each sample, nan within half a window of either end.
    """
    out = np.full(force_n.shape, np.nan)
    if t_s.size < 3:
        return out
    dt = float(np.median(np.diff(t_s)))
    half = max(1, round(0.5 * window_s / dt))
    if t_s.size < 2 * half + 1:
        return out
    offsets = np.arange(-half, half + 1, dtype=np.float64)
    kernel = offsets / (dt * float(offsets @ offsets))
    # np.convolve flips the kernel: pass it reversed to correlate.
    out[half:-half] = np.convolve(force_n, kernel[::-1], mode="valid")
    return out


def _baseline(values: FloatArray) -> tuple[float, float]:
    """Mean and standard deviation of the finite samples (nan, nan if none)."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return math.nan, math.nan
    return float(v.mean()), float(v.std())


def _snr(peak: float, mean: float, std: float) -> float:
    """How many baseline standard deviations ``peak`` stands above the baseline mean."""
    if not (math.isfinite(peak) and math.isfinite(mean) and math.isfinite(std)):
        return math.nan
    rise = peak - mean
    return math.inf if std <= 0.0 and rise > 0.0 else (rise / std if std > 0.0 else 0.0)


@dataclass(frozen=True)
class ContactRun:
    """One single-finger contact stroke at one stiffness state, sampled at 30 Hz.

    Attributes
    ----------
    object_name : str
        Catalogue object pressed against the finger.
    mode : str
        Stiffness state (``stiff``, ``medium``, ``compliant``).
    setpoint_c : float
        Temperature asked of the loop (°C); room temperature for ``stiff``.
    seed : int
        Twin seed.
    stroke : ContactStroke
        The indentation.
    t_s : ndarray
        Time since the start of the press (s); the rest before it is negative.
    truth_n : ndarray
        True contact force (N).
    estimate_n : ndarray
        Smoothed ICFN estimate (N), what a controller would act on (never negative).
    icfn_raw_n : ndarray
        The ICFN's output unclipped, with the same smoothing (N): its noise
        about zero before contact is the estimate's noise floor.
    deflection_m : ndarray
        Marker deflection perceived (m).
    ir_temp_c : ndarray
        Marker finger's temperature read by the infrared camera (°C).
    indenter_mm : ndarray
        Indenter travel from its start position, by the encoder (mm).
    twin_version : str
        Twin that produced it.
    """

    object_name: str
    mode: str
    setpoint_c: float
    seed: int
    stroke: ContactStroke
    t_s: FloatArray
    truth_n: FloatArray
    estimate_n: FloatArray
    icfn_raw_n: FloatArray
    deflection_m: FloatArray
    ir_temp_c: FloatArray
    indenter_mm: FloatArray
    twin_version: str = TWIN_VERSION

    @property
    def _baseline_mask(self) -> BoolArray:
        return (self.t_s < 0.0) & (self.t_s >= -self.stroke.rest_s)

    @property
    def _stroke_mask(self) -> BoolArray:
        s = self.stroke
        return (self.t_s >= 0.0) & (self.t_s <= 2.0 * s.ramp_s + s.dwell_s + 0.5)

    def figures(self) -> dict[str, float]:
        """Peak force and rate (true and estimated), noise floors, detection, temperature."""
        base, stroke = self._baseline_mask, self._stroke_mask
        true_rate = rate_n_per_s(self.t_s, self.truth_n)
        est_rate = rate_n_per_s(self.t_s, self.estimate_n)
        est_mean, est_std = _baseline(self.icfn_raw_n[base])
        def_mean, def_std = _baseline(self.deflection_m[base])
        peak_est = float(np.nanmax(self.estimate_n[stroke]))
        peak_raw = float(np.nanmax(self.icfn_raw_n[stroke]))
        peak_def = float(np.nanmax(self.deflection_m[stroke]))
        return {
            "temp_c": float(np.nanmean(self.ir_temp_c[stroke])),
            "peak_true_n": float(np.max(self.truth_n[stroke])),
            "peak_est_n": peak_est,
            "peak_true_rate_n_per_s": float(np.nanmax(true_rate[stroke])),
            "peak_est_rate_n_per_s": float(np.nanmax(est_rate[stroke])),
            "est_floor_mean_n": est_mean,
            "est_floor_std_n": est_std,
            "est_snr": _snr(peak_raw, est_mean, est_std),
            "peak_deflection_m": peak_def,
            "deflection_floor_std_m": def_std,
            "deflection_snr": _snr(peak_def, def_mean, def_std),
        }

    @property
    def detected(self) -> bool:
        """Whether the estimate or the deflection rose :data:`DETECTION_SNR` σ above its floor."""
        f = self.figures()
        return bool(f["est_snr"] >= DETECTION_SNR or f["deflection_snr"] >= DETECTION_SNR)

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python summary (no arrays)."""
        return json_safe({"object": self.object_name, "mode": self.mode,
                          "setpoint_c": self.setpoint_c, "seed": self.seed,
                          "stroke": self.stroke.to_dict(), "detected": self.detected,
                          "twin_version": self.twin_version, **self.figures()})


def _mode_setpoint_c(mode: StiffnessMode) -> float | None:
    """The loop's setpoint for a mode (°C); ``None``: heaters off."""
    return MODE_SETPOINTS_C[mode]


def run_contact(
    object_name: str,
    mode: StiffnessMode | str,
    seed: int = 0,
    models: ModelBundle | None = None,
    stroke: ContactStroke | None = None,
    config: TwinConfig | None = None,
) -> ContactRun:
    """Press ``object_name`` against the marker finger once at a stiffness state.

    Parameters
    ----------
    object_name : str
        Catalogue object (see :data:`relaxgrip.twin.objects.CATALOGUE`).
    mode : StiffnessMode or str
        ``stiff`` (heaters off at :data:`ROOM_C`), ``medium`` or ``compliant``.
    seed : int
        Twin seed.
    models : ModelBundle, optional
        The ICFN (default: the shipped models).
    stroke : ContactStroke, optional
        The indentation (default: the object's entry of :data:`STROKES`, else 5 mm).
    config : TwinConfig, optional
        The twin (default: our gripper); its object, ambient and temperature are set here.

    Returns
    -------
    ContactRun
    """
    kind = StiffnessMode(mode)
    if kind is StiffnessMode.ADHESIVE:
        raise InputError("the single-finger contacts use the stiff, medium and compliant states")
    stroke = stroke if stroke is not None else STROKES.get(object_name, ContactStroke(5.0))
    bundle = models if models is not None else load_default_models()
    setpoint = _mode_setpoint_c(kind)
    base = replace(config if config is not None else TwinConfig(), object_name=object_name,
                   ambient_c=ROOM_C, initial_temp_c=setpoint)
    obj = base.object_spec(object_name)
    cfg = replace(base, rigid_finger=1 - base.rig.marker_finger)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=seed, clock=clock)
    # The jaw does not bend: only the marker finger is read bent.
    thermal = ThermalPerception(cfg.rig, loaded_fingers=(cfg.rig.marker_finger,))
    perception = Perception(cfg.rig, thermal=thermal)
    temperature = TemperatureLoop(cfg.heat)
    temperature.set_mode(kind)
    estimator = IcfnEstimator(bundle.icfn)
    raw_filter = IcfnEstimator(bundle.icfn)  # the same smoothing on the unclipped output
    dt = 1.0 / cfg.rig.rgb.rate_hz
    v_max = cfg.motor.max_velocity_mm_s
    # The experimenter's schedule of the indenter (encoder mm): settle, approach, rest, stroke.
    touch_mm = (cfg.rig.open_aperture_m - obj.width_m) * 1e3
    start_mm = touch_mm - STROKE_GAP_MM
    settle_s = 2.0
    approach_s = start_mm / v_max + 0.5
    t_press = settle_s + approach_s + stroke.rest_s
    ramp, dwell = stroke.ramp_s, stroke.dwell_s
    t_end = t_press + 2.0 * ramp + dwell + stroke.rest_s
    peak_mm = start_mm + stroke.travel_mm + STROKE_GAP_MM

    def reference(t: float) -> tuple[float, float]:
        """Indenter position (mm) and velocity (mm/s) the schedule asks for at ``t``."""
        if t < settle_s:
            return 0.0, 0.0
        if t < t_press:
            pos = min(start_mm, (t - settle_s) * v_max)
            return pos, (v_max if pos < start_mm else 0.0)
        u = t - t_press
        if u < ramp:
            return start_mm + u * stroke.speed_mm_s, stroke.speed_mm_s
        if u < ramp + dwell:
            return peak_mm, 0.0
        if u < 2.0 * ramp + dwell:
            return peak_mm - (u - ramp - dwell) * stroke.speed_mm_s, -stroke.speed_mm_s
        return start_mm, 0.0

    rows: list[tuple[float, float, float, float, float, float, float]] = []
    try:
        for k in range(math.ceil(t_end / dt) + 1):
            obs = twin.observe()
            percept = perception.update(obs.rgb, obs.ir, obs.motor_position_mm)
            duty = temperature.update(percept.thermal, obs.t_s)
            est = estimator.update(percept, obs.motor_position_mm)
            raw = (bundle.icfn.predict_one(percept.features) if percept.features is not None
                   else math.nan)
            raw_n = raw_filter.smoothed(raw, percept.t_s)
            # Velocity feed-forward led by the motor's lag (so that the indenter does not
            # overshoot the schedule), and a gentle correction of the position.
            ref_mm, _ = reference(obs.t_s)
            _, ref_v = reference(obs.t_s + cfg.motor.lag_s)
            velocity = float(np.clip(ref_v + 5.0 * (ref_mm - obs.motor_position_mm),
                                     -v_max, v_max))
            twin.act(Command(velocity, duty))
            pose = marker_pose(percept.marker)
            j = cfg.rig.marker_finger
            reading = (temperature.readings_c(percept.thermal)[j]
                       if percept.thermal is not None else math.nan)
            rows.append((obs.t_s - t_press, obs.truth.contact_force_n if obs.truth else math.nan,
                         est.force_n, raw_n, math.nan if pose is None else float(pose[0]), reading,
                         obs.motor_position_mm - start_mm))
            clock.sleep_until((k + 1) * dt)
    finally:
        twin.close()
    t, truth, est_n, raw_s, defl, temp, travel = (np.array(c, dtype=np.float64)
                                                  for c in zip(*rows, strict=True))
    return ContactRun(object_name, kind.value, ROOM_C if setpoint is None else setpoint, seed,
                      stroke, t, truth, est_n, raw_s, defl, temp, travel)


def _dwell_mask(run: ContactRun) -> BoolArray:
    """The second half of the dwell at full travel (the force has settled there)."""
    s = run.stroke
    return (run.t_s >= s.ramp_s + 0.5 * s.dwell_s) & (run.t_s <= s.ramp_s + s.dwell_s)


def contact_task_result(name: str, seed: int, runs: Sequence[ContactRun]) -> TaskResult:
    """Score one object's contacts over the stiffness states (stiffest first).

    Criteria: the contact is detected in every state; the compliant state
    amplifies the perceived deflection over the stiff one; the stiff state
    takes at least the compliant state's peak force.  For a rigid object (the
    wrench, where the finger takes the whole travel), also: the true and the
    estimated peak force and peak rate fall strictly from state to state as
    the finger softens, and the settled estimate is within 20 % of the true
    force in every state.
    """
    by_mode = {r.mode: r for r in runs}
    figs = {r.mode: r.figures() for r in runs}
    modes = [m.value for m in CONTACT_MODES if m.value in by_mode]
    criteria: dict[str, bool] = {f"detected_{m}": by_mode[m].detected for m in modes}
    stiff, soft = figs[StiffnessMode.STIFF.value], figs[StiffnessMode.COMPLIANT.value]
    criteria["compliant_amplifies_deflection"] = (
        soft["peak_deflection_m"] > stiff["peak_deflection_m"])
    criteria["stiff_peak_at_least_compliant"] = stiff["peak_true_n"] >= soft["peak_true_n"]
    obj = get_object(runs[0].object_name)
    rigid = obj.stiffness_n_per_m >= 1e4
    figures: dict[str, float] = {}
    for m in modes:
        run = by_mode[m]
        dwell = _dwell_mask(run)
        dwell_true = float(np.mean(run.truth_n[dwell]))
        dwell_est = float(np.nanmean(run.estimate_n[dwell]))
        figures.update({f"{m}_{k}": v for k, v in figs[m].items()})
        figures[f"{m}_dwell_true_n"] = dwell_true
        figures[f"{m}_dwell_est_n"] = dwell_est
        if rigid:
            criteria[f"estimate_within_20pct_{m}"] = abs(dwell_est - dwell_true) <= 0.2 * dwell_true
    if rigid:
        for key in ("peak_true_n", "peak_true_rate_n_per_s", "peak_est_n",
                    "peak_est_rate_n_per_s"):
            values = [figs[m][key] for m in modes]
            criteria[f"stiffer_larger_{key}"] = all(a > b for a, b in itertools.pairwise(values))
    figures["deflection_gain_compliant_over_stiff"] = (
        soft["peak_deflection_m"] / stiff["peak_deflection_m"])
    figures["peak_ratio_stiff_over_compliant"] = stiff["peak_true_n"] / soft["peak_true_n"]
    detail = {"object": obj.name, "stroke": runs[0].stroke.to_dict(), "twin_version": TWIN_VERSION,
              "modes": modes}
    return TaskResult(name, seed, criteria, finite_figures(figures), detail)


def run_contacts(object_name: str, seed: int = 0, models: ModelBundle | None = None,
                 stroke: ContactStroke | None = None, config: TwinConfig | None = None,
                 ) -> tuple[ContactRun, ...]:
    """One contact stroke of ``object_name`` at every state of :data:`CONTACT_MODES`."""
    bundle = models if models is not None else load_default_models()
    return tuple(run_contact(object_name, mode, seed, bundle, stroke, config)
                 for mode in CONTACT_MODES)


# -- (b) closed-loop grasps ---------------------------------------------------------------


def force_band_n(target_n: float) -> float:
    """Half-width of a grasp's force band: 15 % of the target, at least 0.1 N (N).

    0.1 N is about the ICFN's resolution near zero force (its frame-to-frame
    noise after the controller's smoothing, and its bias at the fingertips).
    """
    return max(BAND_REL * check_target_n(target_n), BAND_MIN_N)


@dataclass(frozen=True)
class GraspTask:
    """One of the paper's closed-loop grasps.

    Attributes
    ----------
    name : str
        Task name (``hammer``, ``orange``, ``balloon``).
    object_name : str
        Catalogue object.
    target_n : float
        Force target (N).
    mode : StiffnessMode
        Stiffness mode of the grasp.
    contact_position_m : float
        Where the object meets the fingers (m from the base).
    """

    name: str
    object_name: str
    target_n: float
    mode: StiffnessMode
    contact_position_m: float = 0.080


#: The paper's Fig. "grasp" d–f.
GRASP_TASKS: dict[str, GraspTask] = {
    t.name: t for t in (
        GraspTask("hammer", "hammer", 5.0, StiffnessMode.STIFF),
        GraspTask("orange", "orange", 6.0, StiffnessMode.MEDIUM),
        GraspTask("balloon", "balloon", 0.3, StiffnessMode.COMPLIANT, BALLOON_CONTACT_M),
    )
}


class _TruthRecorder:
    """A twin seen by the loop as it is, whose truth flags the experiment keeps on the side."""

    def __init__(self, twin: GripperTwin) -> None:
        self.twin = twin
        self.slipping: list[bool] = []
        self.crushed: list[bool] = []
        self.plastic_m: list[float] = []

    @property
    def info(self) -> BackendInfo:
        return self.twin.info

    def reset(self, seed: int | None = None) -> Observation:
        return self.twin.reset(seed)

    def observe(self) -> Observation:
        obs = self.twin.observe()
        truth = obs.truth
        if truth is not None:
            self.slipping.append(truth.object_slipping)
            self.crushed.append(truth.object_crushed)
            self.plastic_m.append(truth.object_plastic_m)
        return obs

    def act(self, command: Command) -> None:
        self.twin.act(command)

    def close(self) -> None:
        self.twin.close()


@dataclass(frozen=True)
class GraspRun:
    """One closed-loop grasp through Open, Close, Hold, Lift and Sustain, scored on the truth.

    Attributes
    ----------
    object_name : str
        Catalogue object.
    mode : str
        Stiffness mode.
    target_n, band_n : float
        Force target and the half-width of the band the true force must stay in (N).
    estimator : str
        Force estimator of the controller.
    seed : int
        Twin seed.
    contact_position_m : float
        Nominal contact position along the fingers (m).
    lift_mm, sustain_s : float
        Lift height (mm) and time in Sustain (s) planned.
    loop : LoopResult
        Every series of the run (with the truth columns) and the phase log.
    slipping, crushed : ndarray of bool
        Twin truth per loop sample: the object slipping in the grip, crushed.
    plastic_m : ndarray
        Permanent set of the object per loop sample (m).
    twin_version : str
        Twin that produced it.
    """

    object_name: str
    mode: str
    target_n: float
    band_n: float
    estimator: str
    seed: int
    contact_position_m: float
    lift_mm: float
    sustain_s: float
    loop: LoopResult
    slipping: BoolArray
    crushed: BoolArray
    plastic_m: FloatArray
    twin_version: str = TWIN_VERSION

    @property
    def t_s(self) -> FloatArray:
        """Loop time (s)."""
        return self.loop["t_s"]

    @property
    def phase_names(self) -> list[str]:
        """Phase of every sample."""
        return [PHASES[int(p)].value for p in self.loop["phase"]]

    def window(self) -> BoolArray:
        """Samples from the hold onset to the end (Hold, Lift, Sustain)."""
        onset = self.loop.hold_onset_s()
        if onset is None:
            return np.zeros(self.t_s.shape, dtype=bool)
        return self.t_s >= onset - 1e-9

    def _phase_mask(self, phase: GraspPhase) -> BoolArray:
        return np.asarray(self.loop["phase"] == PHASES.index(phase))

    @property
    def completed(self) -> bool:
        """Whether the grasp went through Sustain to its end."""
        log = self.loop.log
        return (log.entered(GraspPhase.SUSTAIN) is not None
                and self.loop.phase_at(-1) is GraspPhase.DONE)

    @property
    def held(self) -> bool:
        """Lifted by the planned height and still in the grip at the end (truth)."""
        return bool(self.loop["truth_lifted"][-1] == 1.0
                    and self.loop["arm_mm"][-1] >= self.lift_mm - 0.5)

    def criteria(self) -> dict[str, bool]:
        """The success criteria, each from the twin's truth."""
        win = self.window()
        err = np.abs(self.loop["truth_force_n"][win] - self.target_n)
        return {
            "completed_sustain": self.completed,
            "lifted_and_held": self.completed and self.held,
            "not_crushed": not bool(self.crushed.any()),
            "no_slip": not bool(self.slipping.any()),
            "force_within_band": bool(win.any() and float(err.max()) <= self.band_n),
        }

    def figures(self) -> dict[str, float]:
        """The numbers behind the criteria (SI units in the keys)."""
        win = self.window()
        truth = self.loop["truth_force_n"]
        est = self.loop["estimate_n"]
        sustain = self._phase_mask(GraspPhase.SUSTAIN)
        temps = 0.5 * (self.loop["ir_temp_0_c"] + self.loop["ir_temp_1_c"])
        onset = self.loop.hold_onset_s()
        nan = math.nan
        err = truth[win] - self.target_n if win.any() else np.array([nan])
        est_err = (est[win] - truth[win]) if win.any() else np.array([nan])
        return {
            "target_n": self.target_n,
            "band_n": self.band_n,
            "hold_onset_s": nan if onset is None else onset,
            "window_mean_true_n": float(np.mean(truth[win])) if win.any() else nan,
            "window_max_abs_error_n": float(np.max(np.abs(err))),
            "window_mae_n": float(np.mean(np.abs(err))),
            "window_est_mae_n": float(np.nanmean(np.abs(est_err))),
            "sustain_mean_true_n": float(np.mean(truth[sustain])) if sustain.any() else nan,
            "sustain_mean_est_n": float(np.nanmean(est[sustain])) if sustain.any() else nan,
            "peak_true_n": float(np.max(truth)),
            "final_true_n": float(truth[-1]),
            "arm_height_mm": float(self.loop["arm_mm"][-1]),
            "temp_c": float(np.nanmean(temps[win])) if win.any() else nan,
            "plastic_mm": float(self.plastic_m[-1] * 1e3) if self.plastic_m.size else 0.0,
            "controller_slip_events": float(sum(e.kind.value == "slip"
                                                for e in self.loop.log.events)),
            "duration_s": float(self.t_s[-1] - self.t_s[0]),
        }

    @property
    def success(self) -> bool:
        """Whether every criterion held."""
        return all(self.criteria().values())

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python summary: criteria, figures and the phase log (no arrays)."""
        return json_safe({
            "object": self.object_name, "mode": self.mode, "estimator": self.estimator,
            "seed": self.seed, "contact_position_m": self.contact_position_m,
            "lift_mm_planned": self.lift_mm, "sustain_s": self.sustain_s,
            "success": self.success, "criteria": self.criteria(), "figures": self.figures(),
            "log": self.loop.log.to_dict(), "twin_version": self.twin_version})


def run_grasp(
    object_name: str,
    target_n: float,
    mode: StiffnessMode | str,
    seed: int = 0,
    models: ModelBundle | None = None,
    estimator: EstimatorKind | str = GRASP_ESTIMATOR,
    contact_position_m: float | None = None,
    hold_s: float = 3.0,
    lift_mm: float = 30.0,
    sustain_s: float = 8.0,
    band_n: float | None = None,
    ambient_c: float = ROOM_C,
    config: TwinConfig | None = None,
) -> GraspRun:
    """Grasp ``object_name`` at ``target_n`` in ``mode``: Open, Close, Hold, Lift, Sustain.

    Parameters
    ----------
    object_name : str
        Catalogue object, between the open fingers.
    target_n : float
        Force target (N), in (0, 10].
    mode : StiffnessMode or str
        Stiffness mode; the fingers start at its temperature (room temperature
        for ``stiff``), and the temperature loop holds it.
    seed : int
        Twin seed.
    models : ModelBundle, optional
        ICFN and RCFN (default: the shipped models).
    estimator : {"icfn", "relax", "fixed"}
        The controller's force estimator.
    contact_position_m : float, optional
        Nominal contact position along the fingers (m; default: the twin's usual
        contact, 80 mm on our gripper).
    hold_s, lift_mm, sustain_s : float
        Time in Hold (s), arm lift (mm), time in Sustain (s).
    band_n : float, optional
        Half-width of the force band (N); default :func:`force_band_n`.
    ambient_c : float
        Room temperature (°C).
    config : TwinConfig, optional
        The twin (default: our gripper); its object, contact, ambient and
        temperature are set here.

    Returns
    -------
    GraspRun
    """
    kind = StiffnessMode(mode)
    est_kind = EstimatorKind(estimator)
    check_target_n(target_n)
    bundle = models if models is not None else load_default_models()
    base = config if config is not None else TwinConfig()
    cfg = replace(base, object_name=object_name,
                  contact_position_m=(base.contact_position_m if contact_position_m is None
                                      else contact_position_m),
                  ambient_c=ambient_c, initial_temp_c=_mode_setpoint_c(kind))
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=seed, clock=clock)
    recorder = _TruthRecorder(twin)
    controller = GraspController(cfg.rig, bundle_estimator(est_kind, bundle), heat=cfg.heat,
                                 limits=twin_limits(cfg))
    plan = GraspPlan(target_n=target_n, mode=kind, hold_s=hold_s, lift_mm=lift_mm,
                     sustain_s=sustain_s, release=False)
    # Settling and re-zeroing, the full closing stroke at the approach speed, the
    # climb to the target, the lift: all bounded, with a margin for the force loop.
    cc = controller.config
    budget = (cc.temp_settle_s + 5.0 + controller.limits.stroke_mm / cc.approach_mm_s + 15.0
              + hold_s + lift_mm / cc.lift_mm_s + sustain_s)
    try:
        loop = run_loop(recorder, controller, clock, plan, budget)
    finally:
        twin.close()
    n = loop["t_s"].size
    return GraspRun(
        object_name, kind.value, target_n,
        band_n if band_n is not None else force_band_n(target_n), est_kind.value, seed,
        cfg.contact_position_m, lift_mm, sustain_s, loop,
        np.array(recorder.slipping[:n], dtype=bool), np.array(recorder.crushed[:n], dtype=bool),
        np.array(recorder.plastic_m[:n], dtype=np.float64))


def run_grasp_task(task: GraspTask, seed: int = 0, models: ModelBundle | None = None,
                   quick: bool = False, config: TwinConfig | None = None) -> GraspRun:
    """Run one of :data:`GRASP_TASKS` (``quick``: shorter Hold and Sustain) on the twin
    ``config`` (our gripper by default), where the paper held it on its finger."""
    hold_s, sustain_s = (2.0, 4.0) if quick else (3.0, 8.0)
    base = config if config is not None else TwinConfig()
    return run_grasp(task.object_name, task.target_n, task.mode, seed, models,
                     contact_position_m=base.paper_position_m(task.contact_position_m),
                     hold_s=hold_s, sustain_s=sustain_s, config=base)


def grasp_task_result(name: str, run: GraspRun) -> TaskResult:
    """A grasp as a :class:`TaskResult`."""
    detail = {"object": run.object_name, "mode": run.mode, "estimator": run.estimator,
              "contact_position_m": run.contact_position_m, "twin_version": run.twin_version,
              "phases": [[t, p.value] for t, p in run.loop.log.transitions],
              "events": [e.to_dict() for e in run.loop.log.events]}
    return TaskResult(name, run.seed, run.criteria(), finite_figures(run.figures()), detail)


# -- the whole figure ------------------------------------------------------------------------


@dataclass(frozen=True)
class StiffnessModulationResult:
    """The paper's Fig. "grasp": single-finger contacts (a–c) and closed-loop grasps (d–f).

    Attributes
    ----------
    seed : int
        Twin seed of every run.
    quick : bool
        Whether the grasps were shortened.
    contacts : tuple of ContactRun
        Every object at every stiffness state (objects in the paper's order,
        stiffest state first).
    grasps : dict of str to GraspRun
        The grasps by task name.
    twin_version : str
        Twin that produced it.
    """

    seed: int
    quick: bool
    contacts: tuple[ContactRun, ...]
    grasps: dict[str, GraspRun] = field(default_factory=dict)
    twin_version: str = TWIN_VERSION

    def contact_runs(self, object_name: str) -> tuple[ContactRun, ...]:
        """One object's runs, stiffest state first."""
        return tuple(r for r in self.contacts if r.object_name == object_name)

    def objects(self) -> list[str]:
        """The contact objects, in order."""
        return list(dict.fromkeys(r.object_name for r in self.contacts))

    def contact_tasks(self) -> dict[str, TaskResult]:
        """Each contact object scored as its task."""
        return {o: contact_task_result(o, self.seed, self.contact_runs(o)) for o in self.objects()}

    def grasp_tasks(self) -> dict[str, TaskResult]:
        """Each grasp scored as its task."""
        return {name: grasp_task_result(name, run) for name, run in self.grasps.items()}

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form: every contact and grasp, and each task's verdict."""
        tasks = {**self.contact_tasks(), **self.grasp_tasks()}
        return json_safe({
            "experiment": "stiffness_modulation", "seed": self.seed, "quick": self.quick,
            "twin_version": self.twin_version,
            "contacts": [r.to_dict() for r in self.contacts],
            "grasps": {name: run.to_dict() for name, run in self.grasps.items()},
            "tasks": {name: task.to_dict() for name, task in tasks.items()},
        })


def run_stiffness_modulation(seed: int = 0, quick: bool = False,
                             models: ModelBundle | None = None,
                             config: TwinConfig | None = None) -> StiffnessModulationResult:
    """Run the whole of Fig. "grasp": nine contact strokes and three grasps.

    Parameters
    ----------
    seed : int
        Twin seed.
    quick : bool
        Shorter Hold and Sustain in the grasps (the contacts are short anyway).
    models : ModelBundle, optional
        ICFN and RCFN (default: the shipped models).
    config : TwinConfig, optional
        The twin (default: our gripper).

    Returns
    -------
    StiffnessModulationResult
    """
    bundle = models if models is not None else load_default_models()
    contacts = tuple(r for obj in CONTACT_OBJECTS
                     for r in run_contacts(obj, seed, bundle, config=config))
    grasps = {name: run_grasp_task(task, seed, bundle, quick, config)
              for name, task in GRASP_TASKS.items()}
    return StiffnessModulationResult(seed, quick, contacts, grasps)


# -- tasks ------------------------------------------------------------------------------------


def _grasp_task(name: str, seed: int, config: TwinConfig | None) -> TaskResult:
    return grasp_task_result(name, run_grasp_task(GRASP_TASKS[name], seed, config=config))


def _contact_task(name: str, seed: int, config: TwinConfig | None) -> TaskResult:
    return contact_task_result(name, seed, run_contacts(name, seed, config=config))


def hammer_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """Grasp the hammer at 5 N in the stiff mode, lift it and sustain (Fig. "grasp" d)."""
    return _grasp_task("hammer", seed, config)


def orange_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """Grasp the orange at 6 N in the medium mode, lift it and sustain (Fig. "grasp" e)."""
    return _grasp_task("orange", seed, config)


def balloon_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """Grasp the balloon at 0.3 N in the compliant mode, lift it and sustain (Fig. "grasp" f)."""
    return _grasp_task("balloon", seed, config)


def feather_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """Touch the finger with a feather at the three stiffness states (Fig. "grasp" a)."""
    return _contact_task("feather", seed, config)


def brush_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """Touch the finger with a brush at the three stiffness states (Fig. "grasp" b)."""
    return _contact_task("brush", seed, config)


def wrench_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """Press a wrench against the finger at the three stiffness states (Fig. "grasp" c)."""
    return _contact_task("wrench", seed, config)
