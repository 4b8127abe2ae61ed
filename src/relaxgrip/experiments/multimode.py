"""The paper's Fig. "modes" b: what each stiffness mode can and cannot grasp.

Three contrasts on the twin, each the same grasp in two modes, scored on the
twin's truth; no outcome is set by hand, each comes from the contact physics
(:mod:`relaxgrip.physics.contact`):

**1 kg pinch** (:func:`run_pinch`).  The grasp controller pinches the 1 kg
weight at the gripper's largest force target (10 N), lifts it 30 mm and
sustains, in the stiff and the compliant mode, with the ``icfn`` estimator.
Friction must carry 9.8 N: ``2 N (mu cos(theta) - sin(theta))`` with
``mu = 0.6``, where ``theta`` is the tilt of the bent finger's contact face.
At the same force the compliant finger bends further, its face tilts more and
friction carries less; and holding the perceived deflection while the warm
finger relaxes, the grip force decays.  The pinch is on the distal pads at
:data:`PINCH_CONTACT_M` (60 mm of the 110 mm finger): on the twin, a contact
beyond about 70 mm tilts even the stiff finger too far at 10 N to carry 1 kg.

**Empty can** (:func:`run_squeeze`).  A position-controlled grasp, the same
command in both modes: close at the approach speed to an aperture of
:data:`SQUEEZE_APERTURE_SHARE` of the can's width, hold, lift, sustain.  The
closure is shared by the two fingers and the can in series, so the stiffer
the fingers the larger the share the can takes and the larger the force: the
stiff fingers push the can past its 5 N yield (it keeps a permanent dent), the
compliant fingers take the closure themselves and the can stays intact, still
held by friction (it weighs 0.15 N).

**Flat box** (:func:`run_pinch` on the ``flat_box``).  The controller grasps
the low-friction box (``mu = 0.2``, 2.9 N) at :data:`ADHESIVE_TARGET_N` in
the adhesive mode (pads at the fingertips heated past their activation) and
in the stiff mode (pads cold: force closure alone).  Friction alone carries
about 1.3 N at that force, so force closure drops the box; the heated pads
add their pull-off and hold it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Command
from relaxgrip.clock import VirtualClock
from relaxgrip.control import (
    MAX_TARGET_N,
    EstimatorKind,
    ForceControlConfig,
    IcfnEstimator,
    StiffnessMode,
    TemperatureLoop,
)
from relaxgrip.control.temperature import MODE_SETPOINTS_C
from relaxgrip.errors import InputError
from relaxgrip.experiments.stiffness_modulation import (
    ROOM_C,
    GraspRun,
    run_grasp,
)
from relaxgrip.experiments.tasks import TaskResult, finite_figures
from relaxgrip.learning.store import ModelBundle
from relaxgrip.learning.training import load_default_models
from relaxgrip.perception.pipeline import Perception
from relaxgrip.serialize import json_safe
from relaxgrip.twin import TWIN_VERSION, GripperTwin, TwinConfig, get_object

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = [
    "ADHESIVE_TARGET_N",
    "PINCH_CONTACT_M",
    "PINCH_TARGET_N",
    "SQUEEZE_APERTURE_SHARE",
    "MultimodeResult",
    "SqueezeRun",
    "adhesive_task",
    "can_task",
    "pinch_1kg_task",
    "run_adhesive",
    "run_multimode",
    "run_pinch",
    "run_squeeze",
]

#: Pinch force of the 1 kg weight (N): the controller's largest target.
PINCH_TARGET_N = MAX_TARGET_N
#: Where the fingers pinch the weight (m from the base): the distal pads.
PINCH_CONTACT_M = 0.060
#: Grasp force of the flat box in both modes (N).
ADHESIVE_TARGET_N = 5.0
#: The can's grasp closes the fingers to this share of its width.
SQUEEZE_APERTURE_SHARE = 0.8
#: Lift (mm) and Sustain of every grasp here (s); ``quick`` halves the Sustain.
LIFT_MM = 30.0
HOLD_S = 2.0
SUSTAIN_S = 6.0


def _sustain_s(quick: bool) -> float:
    return 0.5 * SUSTAIN_S if quick else SUSTAIN_S


def run_pinch(object_name: str, target_n: float, mode: StiffnessMode | str, seed: int = 0,
              models: ModelBundle | None = None, contact_position_m: float | None = None,
              quick: bool = False, config: TwinConfig | None = None) -> GraspRun:
    """One force-controlled grasp, lift and sustain of ``object_name`` (``icfn`` estimator).

    Parameters
    ----------
    object_name : str
        Catalogue object.
    target_n : float
        Force target (N).
    mode : StiffnessMode or str
        Stiffness mode.
    seed : int
        Twin seed.
    models : ModelBundle, optional
        The shipped models by default.
    contact_position_m : float, optional
        Contact position along the fingers (m; default: :data:`PINCH_CONTACT_M` on the
        paper's finger, at its share of the twin's).
    quick : bool
        Shorter Sustain.
    config : TwinConfig, optional
        The twin (default: our gripper).

    Returns
    -------
    GraspRun
        With the whole loop, the truth flags and the criteria of a grasp.
    """
    base = config if config is not None else TwinConfig()
    at = base.paper_position_m(PINCH_CONTACT_M) if contact_position_m is None \
        else contact_position_m
    # The paper's contrast: the warm finger's grip decays under the per-frame ICFN.
    return run_grasp(object_name, target_n, mode, seed, models, estimator=EstimatorKind.ICFN,
                     contact_position_m=at, hold_s=HOLD_S, lift_mm=LIFT_MM,
                     sustain_s=_sustain_s(quick), config=base)


def run_adhesive(mode: StiffnessMode | str, seed: int = 0, models: ModelBundle | None = None,
                 quick: bool = False, config: TwinConfig | None = None) -> GraspRun:
    """Grasp, lift and sustain the flat box at :data:`ADHESIVE_TARGET_N` in ``mode``, at
    the twin's usual contact (80 mm on our gripper)."""
    base = config if config is not None else TwinConfig()
    return run_pinch("flat_box", ADHESIVE_TARGET_N, mode, seed, models,
                     contact_position_m=base.contact_position_m, quick=quick, config=base)


@dataclass(frozen=True)
class SqueezeRun:
    """One position-controlled grasp: close to a fixed aperture, hold, lift, sustain.

    Attributes
    ----------
    object_name : str
        Catalogue object.
    mode : str
        Stiffness mode.
    seed : int
        Twin seed.
    aperture_mm : float
        Commanded closed aperture between the undeflected contact faces (mm).
    width_mm : float
        The object's width (mm).
    t_s : ndarray
        Time (s).
    phase : tuple of str
        Step of the grasp at each sample (``open``, ``close``, ``hold``,
        ``lift``, ``sustain``).
    truth_n : ndarray
        True contact force (N).
    estimate_n : ndarray
        The (smoothed) ICFN estimate through perception (N), for display.
    arm_mm : ndarray
        Arm height (mm).
    lifted, slipping, crushed : ndarray of bool
        Twin truth per sample.
    plastic_m : ndarray
        The object's permanent set per sample (m).
    twin_version : str
        Twin that produced it.
    """

    object_name: str
    mode: str
    seed: int
    aperture_mm: float
    width_mm: float
    t_s: FloatArray
    phase: tuple[str, ...]
    truth_n: FloatArray
    estimate_n: FloatArray
    arm_mm: FloatArray
    lifted: BoolArray
    slipping: BoolArray
    crushed: BoolArray
    plastic_m: FloatArray
    twin_version: str = TWIN_VERSION

    @property
    def squeeze_mm(self) -> float:
        """Closure past first touch of the undeflected fingers (mm)."""
        return self.width_mm - self.aperture_mm

    @property
    def held(self) -> bool:
        """Lifted and still in the grip at the end, never slipping (truth)."""
        return bool(self.lifted[-1] and not self.slipping.any()
                    and self.arm_mm[-1] >= LIFT_MM - 0.5)

    @property
    def is_crushed(self) -> bool:
        """Whether the object was crushed (a visible permanent set)."""
        return bool(self.crushed.any())

    def figures(self) -> dict[str, float]:
        """Peak force, permanent set, final force and lift."""
        return {
            "squeeze_mm": self.squeeze_mm,
            "peak_true_n": float(np.max(self.truth_n)),
            "final_true_n": float(self.truth_n[-1]),
            "plastic_mm": float(self.plastic_m[-1] * 1e3),
            "arm_height_mm": float(self.arm_mm[-1]),
            "yield_n": get_object(self.object_name).yield_force_n,
        }

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python summary (no arrays)."""
        return json_safe({"object": self.object_name, "mode": self.mode, "seed": self.seed,
                          "aperture_mm": self.aperture_mm, "held": self.held,
                          "crushed": self.is_crushed, "twin_version": self.twin_version,
                          **self.figures()})


def run_squeeze(object_name: str, mode: StiffnessMode | str, seed: int = 0,
                models: ModelBundle | None = None,
                aperture_share: float = SQUEEZE_APERTURE_SHARE,
                contact_position_m: float | None = None, quick: bool = False,
                config: TwinConfig | None = None) -> SqueezeRun:
    """Close to ``aperture_share`` of the object's width, hold, lift and sustain.

    The gripper is position-controlled (the encoder only): the fingers close
    at the controller's approach speed to the commanded aperture and stay
    there.  Perception runs alongside for the displayed estimate and the
    temperature loop holds the mode; neither sees the truth, which only scores
    the run.

    Parameters
    ----------
    object_name : str
        Catalogue object.
    mode : StiffnessMode or str
        ``stiff``, ``medium`` or ``compliant``.
    seed : int
        Twin seed.
    models : ModelBundle, optional
        The ICFN for the displayed estimate (default: the shipped models).
    aperture_share : float
        Closed aperture as a share of the object's width, in (0, 1).
    contact_position_m : float, optional
        Contact position along the fingers (m; default: the twin's usual contact).
    quick : bool
        Shorter Sustain.
    config : TwinConfig, optional
        The twin (default: our gripper).

    Returns
    -------
    SqueezeRun
    """
    kind = StiffnessMode(mode)
    if not 0.0 < aperture_share < 1.0:
        raise InputError(f"aperture share must be in (0, 1), got {aperture_share}")
    bundle = models if models is not None else load_default_models()
    setpoint = MODE_SETPOINTS_C[kind]
    base = config if config is not None else TwinConfig()
    cfg = replace(base, object_name=object_name,
                  contact_position_m=(base.contact_position_m if contact_position_m is None
                                      else contact_position_m),
                  ambient_c=ROOM_C, initial_temp_c=setpoint)
    obj = cfg.object_spec(object_name)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=seed, clock=clock)
    perception = Perception(cfg.rig)
    temperature = TemperatureLoop(cfg.heat)
    temperature.set_mode(kind)
    estimator = IcfnEstimator(bundle.icfn)
    cc = ForceControlConfig()
    aperture_m = aperture_share * obj.width_m
    target_mm = (cfg.rig.open_aperture_m - aperture_m) * 1e3
    dt = 1.0 / cfg.rig.rgb.rate_hz
    settle_s = 2.0
    t_closed = settle_s + target_mm / cc.approach_mm_s + 1.0
    t_lift = t_closed + HOLD_S
    t_sustain = t_lift + LIFT_MM / cc.lift_mm_s
    t_end = t_sustain + _sustain_s(quick)
    rows: list[tuple[float, float, float, float, bool, bool, bool, float]] = []
    phases: list[str] = []
    try:
        for k in range(math.ceil(t_end / dt) + 1):
            obs = twin.observe()
            t = obs.t_s
            percept = perception.update(obs.rgb, obs.ir, obs.motor_position_mm)
            duty = temperature.update(percept.thermal, t)
            est = estimator.update(percept, obs.motor_position_mm)
            error_mm = target_mm - obs.motor_position_mm
            velocity = 0.0 if t < settle_s else float(np.clip(5.0 * error_mm, -cc.approach_mm_s,
                                                               cc.approach_mm_s))
            arm = 0.0
            if t < settle_s:
                step = "open"
            elif t < t_closed:
                step = "close"
            elif t < t_lift:
                step = "hold"
            elif obs.arm_height_mm < LIFT_MM:
                step, arm = "lift", cc.lift_mm_s
            else:
                step = "sustain"
            twin.act(Command(velocity, duty, arm))
            truth = obs.truth
            if truth is None:
                raise InputError("the squeeze needs a backend with ground truth")
            rows.append((t, truth.contact_force_n, est.force_n, obs.arm_height_mm,
                         truth.object_lifted, truth.object_slipping, truth.object_crushed,
                         truth.object_plastic_m))
            phases.append(step)
            clock.sleep_until((k + 1) * dt)
    finally:
        twin.close()
    cols = list(zip(*rows, strict=True))
    f64 = [np.array(cols[i], dtype=np.float64) for i in (0, 1, 2, 3, 7)]
    flags = [np.array(cols[i], dtype=bool) for i in (4, 5, 6)]
    return SqueezeRun(object_name, kind.value, seed, aperture_m * 1e3, obj.width_m * 1e3,
                      f64[0], tuple(phases), f64[1], f64[2], f64[3], flags[0], flags[1],
                      flags[2], f64[4])


# -- scoring ---------------------------------------------------------------------------------


def _grasp_figures(prefix: str, run: GraspRun) -> dict[str, float]:
    keys = ("window_mean_true_n", "sustain_mean_true_n", "final_true_n", "peak_true_n",
            "arm_height_mm", "temp_c", "plastic_mm")
    figs = run.figures()
    out = {f"{prefix}_{k}": figs[k] for k in keys}
    slip = np.flatnonzero(run.slipping)
    out[f"{prefix}_first_slip_s"] = float(run.t_s[slip[0]]) if slip.size else math.nan
    return out


def _grasp_held(run: GraspRun) -> bool:
    """Lifted, held to the end of Sustain, never slipping, not crushed (truth)."""
    c = run.criteria()
    return c["lifted_and_held"] and c["no_slip"] and c["not_crushed"]


def pinch_result(seed: int, stiff: GraspRun, compliant: GraspRun) -> TaskResult:
    """The 1 kg pinch contrast: the stiff mode lifts and holds it, the compliant mode does not."""
    criteria = {"stiff_lifts_and_holds": _grasp_held(stiff),
                "compliant_fails_to_hold": not _grasp_held(compliant)}
    figures = {**_grasp_figures("stiff", stiff), **_grasp_figures("compliant", compliant),
               "weight_n": get_object(stiff.object_name).weight_n}
    detail = {"object": stiff.object_name, "target_n": stiff.target_n,
              "contact_position_m": stiff.contact_position_m, "estimator": stiff.estimator,
              "twin_version": stiff.twin_version}
    return TaskResult("pinch-1kg", seed, criteria, finite_figures(figures), detail)


def can_result(seed: int, stiff: SqueezeRun, compliant: SqueezeRun) -> TaskResult:
    """The can contrast: the compliant mode holds it intact, the stiff mode crushes it."""
    criteria = {"compliant_not_crushed": not compliant.is_crushed,
                "compliant_holds": compliant.held,
                "stiff_crushes": stiff.is_crushed}
    figures = {**{f"stiff_{k}": v for k, v in stiff.figures().items()},
               **{f"compliant_{k}": v for k, v in compliant.figures().items()}}
    detail = {"object": stiff.object_name, "aperture_mm": stiff.aperture_mm,
              "twin_version": stiff.twin_version}
    return TaskResult("can", seed, criteria, finite_figures(figures), detail)


def adhesive_result(seed: int, adhesive: GraspRun, force_closure: GraspRun) -> TaskResult:
    """The flat-box contrast: the adhesive mode holds it, force closure alone drops it."""
    criteria = {"adhesive_holds": _grasp_held(adhesive),
                "force_closure_drops": not _grasp_held(force_closure)}
    figures = {**_grasp_figures("adhesive", adhesive),
               **_grasp_figures("force_closure", force_closure),
               "weight_n": get_object(adhesive.object_name).weight_n}
    detail = {"object": adhesive.object_name, "target_n": adhesive.target_n,
              "force_closure_mode": force_closure.mode, "twin_version": adhesive.twin_version}
    return TaskResult("adhesive", seed, criteria, finite_figures(figures), detail)


@dataclass(frozen=True)
class MultimodeResult:
    """The paper's Fig. "modes" b: three contrasts, each the same grasp in two modes.

    Attributes
    ----------
    seed : int
        Twin seed of every run.
    quick : bool
        Whether the Sustains were shortened.
    pinch : dict of str to GraspRun
        The 1 kg pinch by mode (``stiff``, ``compliant``).
    can : dict of str to SqueezeRun
        The can squeeze by mode (``stiff``, ``compliant``).
    adhesive : dict of str to GraspRun
        The flat box by mode (``adhesive``, ``stiff``: force closure alone).
    twin_version : str
        Twin that produced it.
    """

    seed: int
    quick: bool
    pinch: dict[str, GraspRun]
    can: dict[str, SqueezeRun]
    adhesive: dict[str, GraspRun]
    twin_version: str = TWIN_VERSION

    def tasks(self) -> dict[str, TaskResult]:
        """Each contrast scored as its task."""
        s = StiffnessMode.STIFF.value
        c = StiffnessMode.COMPLIANT.value
        a = StiffnessMode.ADHESIVE.value
        return {
            "pinch-1kg": pinch_result(self.seed, self.pinch[s], self.pinch[c]),
            "can": can_result(self.seed, self.can[s], self.can[c]),
            "adhesive": adhesive_result(self.seed, self.adhesive[a], self.adhesive[s]),
        }

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form: every run and each contrast's verdict."""
        return json_safe({
            "experiment": "multimode", "seed": self.seed, "quick": self.quick,
            "twin_version": self.twin_version,
            "pinch": {m: r.to_dict() for m, r in self.pinch.items()},
            "can": {m: r.to_dict() for m, r in self.can.items()},
            "adhesive": {m: r.to_dict() for m, r in self.adhesive.items()},
            "tasks": {name: t.to_dict() for name, t in self.tasks().items()},
        })


def _pinch_runs(seed: int, models: ModelBundle, quick: bool,
                config: TwinConfig | None = None) -> dict[str, GraspRun]:
    return {m.value: run_pinch("weight_1kg", PINCH_TARGET_N, m, seed, models, quick=quick,
                               config=config)
            for m in (StiffnessMode.STIFF, StiffnessMode.COMPLIANT)}


def _can_runs(seed: int, models: ModelBundle, quick: bool,
              config: TwinConfig | None = None) -> dict[str, SqueezeRun]:
    return {m.value: run_squeeze("aluminium_can", m, seed, models, quick=quick, config=config)
            for m in (StiffnessMode.STIFF, StiffnessMode.COMPLIANT)}


def _adhesive_runs(seed: int, models: ModelBundle, quick: bool,
                   config: TwinConfig | None = None) -> dict[str, GraspRun]:
    return {m.value: run_adhesive(m, seed, models, quick=quick, config=config)
            for m in (StiffnessMode.ADHESIVE, StiffnessMode.STIFF)}


def run_multimode(seed: int = 0, quick: bool = False, models: ModelBundle | None = None,
                  config: TwinConfig | None = None) -> MultimodeResult:
    """Run the three contrasts of Fig. "modes" b.

    Parameters
    ----------
    seed : int
        Twin seed.
    quick : bool
        Shorter Sustains.
    models : ModelBundle, optional
        The shipped models by default.
    config : TwinConfig, optional
        The twin (default: our gripper).

    Returns
    -------
    MultimodeResult
    """
    bundle = models if models is not None else load_default_models()
    return MultimodeResult(seed, quick, _pinch_runs(seed, bundle, quick, config),
                           _can_runs(seed, bundle, quick, config),
                           _adhesive_runs(seed, bundle, quick, config))


def pinch_1kg_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """The stiff mode lifts the 1 kg weight by pinch; the compliant mode cannot."""
    runs = _pinch_runs(seed, load_default_models(), quick=False, config=config)
    return pinch_result(seed, runs["stiff"], runs["compliant"])


def can_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """The compliant mode holds the empty can intact; the same closure when stiff crushes it."""
    runs = _can_runs(seed, load_default_models(), quick=False, config=config)
    return can_result(seed, runs["stiff"], runs["compliant"])


def adhesive_task(seed: int = 0, config: TwinConfig | None = None) -> TaskResult:
    """The adhesive mode holds the flat box; force closure alone (stiff mode) drops it."""
    runs = _adhesive_runs(seed, load_default_models(), quick=False, config=config)
    return adhesive_result(seed, runs["adhesive"], runs["stiff"])
