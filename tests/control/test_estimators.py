"""The ``relax`` estimator's F_inst: the loading before the onset and the hold's start."""

from __future__ import annotations

import math

import numpy as np
import pytest

from relaxgrip.control.estimators import RelaxEstimator
from relaxgrip.perception.marker import MarkerState, TrackStatus
from relaxgrip.perception.pipeline import Percept

RATE_HZ = 30.0
STIFFNESS_N_PER_MM = 0.4  # the closed chain's: ICFN force per mm of motor travel


class _Icfn:
    """Stands in for the ICFN: the force is the first feature."""

    def predict_one(self, x: np.ndarray) -> float:
        return float(x[0])


def _percept(t: float, force: float) -> Percept:
    marker = MarkerState(t, TrackStatus.TRACKING, delta_t_m=np.array([1e-3 * force, 0.0, 0.0]),
                         delta_r_rad=np.zeros(3))
    return Percept(t, marker, None, math.inf, "", np.array([force]), None)


def _onset_force(noise: np.ndarray, onset_before_s: float) -> float:
    """Load at 1 mm/s to 5 N, stop, hold; the per-frame ICFN has ``noise`` on it."""
    est = RelaxEstimator(_Icfn(), rcfn=None, onset_before_s=onset_before_s)  # type: ignore[arg-type]
    t_onset = 10.0
    frames = np.arange(0.0, t_onset + 0.6 + 1e-9, 1.0 / RATE_HZ)
    for i, t in enumerate(frames):
        motor = 100.0 + min(t, t_onset) - t_onset  # mm: 1 mm/s, at rest from the onset
        if i == round(t_onset * RATE_HZ):
            est.start_hold(t, motor)
        force = 5.0 + STIFFNESS_N_PER_MM * (motor - 100.0)
        est.update(_percept(float(t), force + noise[i]), motor)
    return est.f_onset_n


def test_f_inst_carries_the_loading_to_the_onset_along_the_closure_stiffness() -> None:
    quiet = np.zeros(400)
    assert _onset_force(quiet, onset_before_s=1.0) == pytest.approx(5.0, abs=1e-9)


def test_f_inst_averages_the_frames_before_the_onset_too() -> None:
    """Per-frame ICFN noise of 0.15 N: the onset's error shrinks with the loading frames added."""
    errors: dict[float, list[float]] = {0.0: [], 1.0: []}
    for seed in range(40):
        noise = np.random.default_rng(seed).normal(0.0, 0.15, 400)
        for before in errors:
            errors[before].append(_onset_force(noise, before) - 5.0)
    rms = {before: float(np.sqrt(np.mean(np.square(e)))) for before, e in errors.items()}
    # 19 frames after the onset against 19 + 31: sqrt(50 / 19) = 1.6 times smaller.
    assert rms[1.0] < 0.75 * rms[0.0]
    assert rms[1.0] == pytest.approx(0.15 / math.sqrt(50), rel=0.3)


@pytest.mark.parametrize("kwargs", [
    {"stiffness_window_s": 0.0},
    {"onset_before_s": -1.0},
    {"onset_window_s": math.nan},
    {"onset_before_s": 0.0, "onset_window_s": 0.0},
])
def test_windows_that_average_nothing_are_refused(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="window"):
        RelaxEstimator(_Icfn(), rcfn=None, **kwargs)  # type: ignore[arg-type]
