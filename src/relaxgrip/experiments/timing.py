"""Latency of every stage of force perception (the paper's Fig. "network" b), measured.

The workload is a rendered grasp: the twin closes on the force ball while its
heaters warm the fingers, at 30 Hz, with an infrared frame rendered for every
tick so the thermal stage has as many samples as the others.  Frames are
rendered first and timed afterwards, frame after frame as the loop meets them,
on one thread.  Stages: marker pose (our tracker, and the plain full-frame
ArUco detection the paper times), thermal features, ICFN features, the ICFN
forward pass, the RCFN (its features and prediction), and the two end-to-end
latencies the paper adds up: instantaneous (pose, features, ICFN) and
relaxation-compensated (plus RCFN).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Command, Frame
from relaxgrip.clock import VirtualClock
from relaxgrip.physics.thermal import node_positions_m
from relaxgrip.twin import TWIN_VERSION, GripperTwin, TwinConfig
from relaxgrip.twin.render_ir import IrObject, IrRenderer
from relaxgrip.twin.sensors import IrSensorConfig

FloatArray = NDArray[np.float64]

__all__ = [
    "HOLD_ONSET_S", "PAPER_LATENCY_MS", "GraspFrames", "TimingResult", "render_grasp", "run_timing",
]

#: The paper's measured latencies (ms), §IV: ArUco pose 3.5, ICFN 1.3, RCFN 0.14;
#: instantaneous 4.8 and relaxation-compensated 4.94 in all.
PAPER_LATENCY_MS: dict[str, float] = {
    "aruco_pose": 3.5, "icfn": 1.3, "rcfn": 0.14, "instantaneous": 4.8, "compensated": 4.94,
}
#: ``render_grasp``'s motor stops here: the loading before, the hold after (s).
HOLD_ONSET_S = 9.1


@dataclass(frozen=True)
class GraspFrames:
    """Frames of a rendered grasp with the truth needed to score perception.

    Attributes
    ----------
    rgb : list of Frame
        RGB frames, one per 30 Hz tick.
    ir : list of Frame
        Infrared frames rendered at every tick (the twin's own stream is 1 Hz).
    motor_mm : list of float
        Encoder position at each tick (mm).
    marker2cam : list of ndarray
        True marker pose at each tick.
    rest2cam : ndarray
        True marker pose of the unloaded finger.
    """

    rgb: list[Frame]
    ir: list[Frame]
    motor_mm: list[float]
    marker2cam: list[FloatArray]
    rest2cam: FloatArray


def render_grasp(n_frames: int = 600, seed: int = 0,
                 config: TwinConfig | None = None) -> GraspFrames:
    """Render a grasp of the force ball: open for 1 s, close, squeeze, hold from 9 s, heaters on
    (on the twin ``config``, our gripper by default)."""
    cfg = replace(config if config is not None else TwinConfig(), initial_temp_c=35.0, ir=None)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=seed, clock=clock)
    rig = cfg.rig
    ir_renderer = IrRenderer(rig, IrSensorConfig(), seed)
    nodes_m = node_positions_m(cfg.heat)
    radius_m = 0.5 * cfg.force_ball.width_m
    j = rig.marker_finger
    rgb, ir, motor, poses = [], [], [], []
    for k in range(n_frames):
        t = k / 30.0
        speed = 0.0 if t < 1.0 else 20.0 if t < 5.3 else 2.0 if t < 9.0 else 0.0
        twin.act(Command(speed, (0.6, 0.6)))
        clock.advance(1.0 / 30.0)
        obs = twin.observe()
        truth = obs.truth
        assert obs.rgb is not None
        assert truth is not None
        rgb.append(obs.rgb)
        motor.append(obs.motor_position_mm)
        poses.append(rig.marker2cam(truth.marker_deflection_m[j], truth.marker_slope_rad[j]))
        ball = IrObject((truth.contact_position_m, 0.0, 0.0), radius_m, 25.0, 0.95)
        image = ir_renderer.render(k, np.asarray(truth.finger_temps_c), nodes_m,
                                   truth.aperture_m, [ball], twin.material.ambient_c)
        ir.append(Frame(obs.t_s, k, image))
    return GraspFrames(rgb, ir, motor, poses, rig.marker2cam())


@dataclass(frozen=True)
class TimingResult:
    """Per-stage latency of force perception.

    Attributes
    ----------
    median_ms, p99_ms : dict of str to float
        Median and 99th percentile per stage (ms): ``aruco_pose`` (the
        tracker as the loop runs it), ``aruco_full_frame`` (detection on the
        whole frame, edge fit and pose, every frame), ``thermal`` (one
        infrared frame), ``features`` (ICFN features), ``icfn``, ``rcfn``
        (features and prediction), ``perception`` (the whole perception step
        per RGB frame, infrared once a second), ``instantaneous``
        (perception + ICFN) and ``compensated`` (+ RCFN).
    frames : int
        RGB frames timed per pass.
    passes : int
        Passes over the frames.
    """

    median_ms: dict[str, float]
    p99_ms: dict[str, float]
    frames: int
    passes: int

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form, with the paper's figures beside ours."""
        return {
            "twin_version": TWIN_VERSION,
            "frames": self.frames,
            "passes": self.passes,
            "median_ms": dict(self.median_ms),
            "p99_ms": dict(self.p99_ms),
            "paper_ms": dict(PAPER_LATENCY_MS),
            "speedup_compensated": PAPER_LATENCY_MS["compensated"] / self.median_ms["compensated"],
        }


def _timed(fn: Callable[[int], Any], indices: range | list[int]) -> tuple[list[float], list[Any]]:
    times, out = [], []
    for i in indices:
        t0 = time.perf_counter()
        out.append(fn(i))
        times.append(time.perf_counter() - t0)
    return times, out


def run_timing(seed: int = 0, quick: bool = False,
               config: TwinConfig | None = None) -> TimingResult:
    """Measure every stage on a rendered grasp with the shipped models.

    Parameters
    ----------
    seed : int
        Twin seed of the rendered grasp.
    quick : bool
        One pass over 450 frames instead of three over 600.
    config : TwinConfig, optional
        The twin (default: our gripper).
    """
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.perception.features import (
        RcfnFeatures,
        build_icfn_features,
        finger_temperature_c,
        marker_pose,
    )
    from relaxgrip.perception.marker import (
        MarkerTracker,
        PoseSolver,
        locate_marker,
        make_detector,
    )
    from relaxgrip.perception.pipeline import Perception
    from relaxgrip.perception.thermal import ThermalPerception

    n_frames, passes = (450, 1) if quick else (600, 3)
    cfg = config if config is not None else TwinConfig()
    grasp = render_grasp(n_frames, seed, cfg)
    rig = cfg.rig
    models = load_default_models()
    previous_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    samples: dict[str, list[float]] = {k: [] for k in (
        "aruco_pose", "aruco_full_frame", "thermal", "features", "icfn", "rcfn", "perception",
        "instantaneous", "compensated")}
    try:
        detector = make_detector(rig.marker.aruco_dictionary)
        solver = PoseSolver(rig.marker.size_m, rig.rgb.intrinsics)

        def full_frame(i: int) -> object:
            return locate_marker(np.asarray(grasp.rgb[i].image, dtype=np.uint8), detector, solver)

        for _ in range(passes):
            tracker = MarkerTracker(rig.rgb.intrinsics, rig.marker)
            thermal = ThermalPerception(rig)
            t, states = _timed(lambda i: tracker.update(grasp.rgb[i]), range(n_frames))  # noqa: B023
            samples["aruco_pose"] += t[tracker.zero_frames:]
            samples["aruco_full_frame"] += _timed(full_frame, range(n_frames))[0]
            t, warm = _timed(lambda i: thermal.extract(grasp.ir[i], grasp.motor_mm[i]),  # noqa: B023
                             range(n_frames))
            samples["thermal"] += t
            samples["features"] += _timed(
                lambda i: build_icfn_features(states[i], warm[i]), range(n_frames))[0]  # noqa: B023

            # The loop's own order, end to end: perception (infrared once a second),
            # the ICFN, then the RCFN once the hold has started.
            perception = Perception(rig)
            builder = RcfnFeatures()
            onset: int | None = None
            for i, rgb in enumerate(grasp.rgb):
                t0 = time.perf_counter()
                p = perception.update(rgb, grasp.ir[i - i % 30], grasp.motor_mm[i])
                t1 = time.perf_counter()
                f_inst = models.icfn.predict_one(p.features) if p.features is not None else math.nan
                t2 = time.perf_counter()
                if p.thermal is None or i < perception.tracker.zero_frames:
                    continue
                samples["perception"].append(t1 - t0)
                samples["icfn"].append(t2 - t1)
                samples["instantaneous"].append(t2 - t0)
                pose = marker_pose(p.marker)
                if pose is None:
                    continue
                if onset is None:
                    if rgb.t_s >= HOLD_ONSET_S:
                        onset = i
                        builder.start(rgb.t_s, pose, grasp.motor_mm[i])
                    else:
                        builder.observe(rgb.t_s, pose, grasp.motor_mm[i])
                    continue
                builder.observe(rgb.t_s, pose, grasp.motor_mm[i])
                x = builder.build(finger_temperature_c(p.thermal))
                if x is not None:
                    models.rcfn.relaxation(x, f_inst)
                t3 = time.perf_counter()
                samples["rcfn"].append(t3 - t2)
                samples["compensated"].append(t3 - t0)
    finally:
        cv2.setNumThreads(previous_threads)
    median = {k: float(np.median(v) * 1e3) for k, v in samples.items()}
    p99 = {k: float(np.percentile(v, 99) * 1e3) for k, v in samples.items()}
    return TimingResult(median, p99, n_frames, passes)
