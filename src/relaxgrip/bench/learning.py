"""Benchmarks of the learning half: inference per frame, and the paper-size pipeline."""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from relaxgrip.bench.core import BenchResult

__all__ = ["bench_estimation", "bench_learning_pipeline"]

#: The paper's ICFN and RCFN inference times (Fig. "network" b): 1.3 ms + 0.14 ms.
PAPER_INFERENCE_MS = 1.44
#: Length of the paper's recorded relaxation sequences (s).
PAPER_HOLD_S = 100.0


def bench_estimation(repeat: int) -> BenchResult:
    """ICFN + RCFN per frame on the features of a rendered grasp, shipped models."""
    from relaxgrip.experiments.timing import HOLD_ONSET_S, render_grasp
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.perception.features import RcfnFeatures, finger_temperature_c, marker_pose
    from relaxgrip.perception.pipeline import Perception
    from relaxgrip.twin import TwinConfig

    models = load_default_models()
    grasp = render_grasp(600)
    perception = Perception(TwinConfig().rig)
    frames: list[tuple[float, Any, Any, float, float]] = []
    for i, rgb in enumerate(grasp.rgb):
        p = perception.update(rgb, grasp.ir[i - i % 30], grasp.motor_mm[i])
        pose = marker_pose(p.marker)
        if p.features is not None and pose is not None and p.thermal is not None:
            frames.append((rgb.t_s, p.features, pose, finger_temperature_c(p.thermal),
                           grasp.motor_mm[i]))
    icfn, rcfn = models.icfn, models.rcfn
    t_icfn: list[float] = []
    t_rcfn: list[float] = []
    t_both: list[float] = []
    for _ in range(max(1, repeat)):
        builder = RcfnFeatures()
        # render_grasp's motor stops at 9 s: the loading before, the hold after.
        onset = next(i for i, frame in enumerate(frames) if frame[0] >= HOLD_ONSET_S)
        for t_s, _, pose, _, motor_mm in frames[:onset]:
            builder.observe(t_s, pose, motor_mm)
        builder.start(frames[onset][0], frames[onset][2], frames[onset][4])
        for t_s, features, pose, temp_c, motor_mm in frames[onset:]:
            t0 = time.perf_counter()
            f_inst = icfn.predict_one(features)
            t1 = time.perf_counter()
            builder.observe(t_s, pose, motor_mm)
            x = builder.build(temp_c)
            assert x is not None
            rcfn.relaxation(x, f_inst)
            t2 = time.perf_counter()
            t_icfn.append(t1 - t0)
            t_rcfn.append(t2 - t1)
            t_both.append(t2 - t0)
    median_us = {name: statistics.median(v) * 1e6
                 for name, v in (("icfn", t_icfn), ("rcfn", t_rcfn), ("both", t_both))}
    return BenchResult(
        "estimation",
        f"ICFN forward pass + RCFN features and prediction, {len(t_both) // max(1, repeat)} "
        f"hold frames x {repeat}",
        t_both,
        notes={"icfn_us_p99": float(np.percentile(t_icfn, 99) * 1e6),
               "paper_inference_ms": PAPER_INFERENCE_MS, "frames": len(frames)},
        headline={"estimation_ms_median": median_us["both"] / 1e3,
                  "icfn_us_median": median_us["icfn"], "rcfn_us_median": median_us["rcfn"]},
    )


def bench_learning_pipeline(repeat: int) -> BenchResult:
    """Dataset build on 2 workers, then training: the paper's size, then our default.

    The paper's size is 8,258 ICFN samples and 810 RCFN sequences of 100 s;
    our default dataset (the shipped models') has 10,700 ICFN samples (up to
    11 N) and holds each sequence 280 s.  One run each: they take minutes.
    """
    from relaxgrip.learning.build import build_dataset
    from relaxgrip.learning.datasets import PAPER_ICFN_SAMPLES, DatasetSpec
    from relaxgrip.learning.datastore import load_dataset
    from relaxgrip.learning.training import train_models

    def build_and_train(spec: DatasetSpec) -> tuple[float, float, dict[str, Any]]:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "data"
            t0 = time.perf_counter()
            manifest = build_dataset(out, spec, jobs=2)
            t1 = time.perf_counter()
            train_models(load_dataset(out))
            t2 = time.perf_counter()
        return t1 - t0, t2 - t1, manifest["counts"]

    paper = DatasetSpec(icfn_samples=PAPER_ICFN_SAMPLES, hold_s=PAPER_HOLD_S)
    paper_build, paper_train, counts = build_and_train(paper)
    default_build, default_train, _ = build_and_train(DatasetSpec())
    return BenchResult(
        "learning-pipeline",
        "810 RCFN sequences on 2 workers, then training: the paper's size (8,258 ICFN "
        "samples, 100 s holds), then the default (10,700 samples up to 11 N, 280 s holds)",
        [paper_build + paper_train],
        notes={"counts": counts},
        headline={"dataset_build_s": paper_build, "training_s": paper_train,
                  "default_dataset_build_s": default_build,
                  "default_training_s": default_train},
    )
