"""Perception benchmark: latency of every stage, and pose error against the twin's truth.

The workload is a rendered grasp: the twin closes on the force ball while
its heaters warm the fingers, 20 s at 30 Hz (600 RGB frames), with an
infrared frame rendered for every tick too so the thermal stage has as many
samples.  Frames are rendered first and timed afterwards, each stage on one
OpenCV thread, frame after frame as in the loop (so each frame arrives cold
in the caches, as a camera's would).  The ground truth of the relative marker
pose comes from the rig geometry and the twin's bending at the marker.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from relaxgrip.bench.core import BenchResult
from relaxgrip.experiments.timing import GraspFrames, render_grasp
from relaxgrip.perception.features import build_icfn_features
from relaxgrip.perception.marker import (
    MarkerState,
    MarkerTracker,
    PoseSolver,
    locate_marker,
    make_detector,
    rotation_angle,
)
from relaxgrip.perception.pipeline import Perception
from relaxgrip.perception.thermal import ThermalFeatures, ThermalPerception
from relaxgrip.twin import TwinConfig

FloatArray = NDArray[np.float64]

__all__ = ["bench_perception"]

#: The paper's measured ArUco pose extraction time (Fig. "network" b).
PAPER_ARUCO_MS = 3.5


def _per_item(fn: Callable[[int], Any], n: int) -> tuple[list[float], list[Any]]:
    times, out = [], []
    for i in range(n):
        t0 = time.perf_counter()
        out.append(fn(i))
        times.append(time.perf_counter() - t0)
    return times, out


def _stats(prefix: str, seconds: list[float]) -> dict[str, float]:
    ms = np.asarray(seconds) * 1e3
    return {
        f"{prefix}_ms_median": float(np.median(ms)),
        f"{prefix}_ms_p99": float(np.percentile(ms, 99)),
    }


def _pose_errors(states: list[MarkerState], grasp: GraspFrames) -> dict[str, float]:
    """RMS errors of the relative pose: in-plane and depth translation (mm), rotation (deg)."""
    rest = grasp.rest2cam
    in_plane, depth, angle = [], [], []
    for state, pose in zip(states, grasp.marker2cam, strict=True):
        if not state.ok or state.delta_t_m is None or state.delta_r_rad is None:
            continue
        err = state.delta_t_m - (pose[:3, 3] - rest[:3, 3])
        in_plane.append(float(err[0] ** 2 + err[1] ** 2))
        depth.append(float(err[2] ** 2))
        measured, _ = cv2.Rodrigues(state.delta_r_rad)
        angle.append(rotation_angle(measured @ (pose[:3, :3] @ rest[:3, :3].T).T) ** 2)
    return {
        "mm_rms": 1e3 * math.sqrt(statistics.fmean(in_plane)),
        "depth_mm_rms": 1e3 * math.sqrt(statistics.fmean(depth)),
        "deg_rms": math.degrees(math.sqrt(statistics.fmean(angle))),
        "frames_scored": float(len(angle)),
    }


def bench_perception(repeat: int, n_frames: int = 600) -> BenchResult:
    """Per-stage perception latency (median, p99) over ``n_frames`` frames, ``repeat`` passes.

    Three tracker settings are timed and scored: the default (edge fit between
    detections, detector at least every 5th frame), the detector on every
    frame, and plain ``CORNER_REFINE_SUBPIX`` corners without the edge fit.
    """
    grasp = render_grasp(n_frames)
    cfg = TwinConfig()
    rig = cfg.rig
    n = len(grasp.rgb)
    passes = max(1, repeat)
    figures: dict[str, Any] = {"frames": n, "passes": passes}

    def tracked(**options: Any) -> tuple[list[float], list[MarkerState]]:
        times: list[float] = []
        states: list[MarkerState] = []
        for _ in range(passes):
            tracker = MarkerTracker(rig.rgb.intrinsics, rig.marker, **options)

            def track(i: int, tracker: MarkerTracker = tracker) -> MarkerState:
                return tracker.update(grasp.rgb[i])

            t, states = _per_item(track, n)
            times += t[tracker.zero_frames:]
        return times, states

    t_tracked, states = tracked()
    t_detect, states_detect = tracked(verify_every=1)
    t_subpix, states_subpix = tracked(edge_refine=False)
    figures.update(_stats("tracked", t_tracked))
    figures.update(_stats("tracked_detect", t_detect))
    figures.update(_stats("tracked_subpix", t_subpix))

    detector = make_detector(rig.marker.aruco_dictionary)
    solver = PoseSolver(rig.marker.size_m, rig.rgb.intrinsics)

    def full_frame(i: int) -> object:
        return locate_marker(np.asarray(grasp.rgb[i].image, dtype=np.uint8), detector, solver)

    t_full: list[float] = []
    for _ in range(passes):
        t_full += _per_item(full_frame, n)[0]
    figures.update(_stats("full_frame", t_full))

    thermal = ThermalPerception(rig)
    t_thermal: list[float] = []
    features_in: list[ThermalFeatures] = []
    for _ in range(passes):
        t, features_in = _per_item(lambda i: thermal.extract(grasp.ir[i], grasp.motor_mm[i]), n)
        t_thermal += t
    figures.update(_stats("thermal", t_thermal))

    t_features = _per_item(lambda i: build_icfn_features(states[i], features_in[i]), n)[0]
    figures.update(_stats("features", t_features))

    # The whole stage as the loop runs it: RGB every tick, infrared once a second.
    t_frame: list[float] = []
    for _ in range(passes):
        perception = Perception(rig)

        def perceive(i: int, perception: Perception = perception) -> object:
            return perception.update(grasp.rgb[i], grasp.ir[i - i % 30], grasp.motor_mm[i])

        t_frame += _per_item(perceive, n)[0][perception.tracker.zero_frames:]
    figures.update(_stats("per_frame", t_frame))

    for label, scored in (("", states), ("_detect", states_detect), ("_subpix", states_subpix)):
        errors = _pose_errors(scored, grasp)
        figures[f"pose_err{label}_mm_rms"] = errors["mm_rms"]
        figures[f"pose_err{label}_depth_mm_rms"] = errors["depth_mm_rms"]
        figures[f"pose_err{label}_deg_rms"] = errors["deg_rms"]
        figures[f"frames_scored{label}"] = int(errors["frames_scored"])
    figures["paper_aruco_ms"] = PAPER_ARUCO_MS
    headline_keys = ("tracked_ms_median", "tracked_ms_p99", "tracked_detect_ms_median",
                     "tracked_subpix_ms_median", "full_frame_ms_median", "thermal_ms_median",
                     "features_ms_median", "per_frame_ms_median", "per_frame_ms_p99",
                     "pose_err_mm_rms", "pose_err_deg_rms", "pose_err_detect_mm_rms",
                     "pose_err_detect_deg_rms", "pose_err_subpix_mm_rms",
                     "pose_err_subpix_deg_rms")
    return BenchResult(
        "perception",
        f"{n} rendered frames of a grasp, per stage, one OpenCV thread, {passes} pass(es)",
        t_frame,
        notes={k: v for k, v in figures.items() if k not in headline_keys},
        headline={k: figures[k] for k in headline_keys},
    )
