"""The estimators' reading: ``relax``'s F_inst, the tare at contact, the hold's end."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from relaxgrip.control.estimators import IcfnEstimator, RelaxEstimator
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


class _OffsetIcfn:
    """An ICFN that reads ``offset`` at rest: the force is the first feature plus it."""

    def __init__(self, offset: float) -> None:
        self.offset = offset

    def predict_one(self, x: np.ndarray) -> float:
        return float(x[0]) + self.offset


def _free_then_loaded(est: IcfnEstimator, contact_t: float, before: Callable[[float], float],
                      end_t: float = 3.0) -> list[float]:
    """The force ``before(t)`` until ``contact_t``, 1 N from it; the estimator told of the
    contact at ``contact_t``; its readings."""
    out = []
    for t in np.arange(0.0, end_t, 1.0 / RATE_HZ):
        force = 1.0 if t >= contact_t else before(float(t))
        out.append(est.instantaneous(_percept(float(t), force)))
        if abs(t - contact_t) < 0.5 / RATE_HZ:
            est.contact(float(t))
    return out


def test_the_tare_takes_the_rest_reading_off_from_the_contact_on() -> None:
    est = IcfnEstimator(_OffsetIcfn(0.3), tare_window_s=1.0)  # type: ignore[arg-type]
    readings = _free_then_loaded(est, 2.0, lambda t: 0.0)
    assert est.tare_n == pytest.approx(0.3)
    assert readings[int(1.5 * RATE_HZ)] == pytest.approx(0.3)  # before the contact: untared
    assert readings[-1] == pytest.approx(1.0)
    est.reset()
    assert est.tare_n == 0.0


def test_the_tare_leaves_out_the_margin_before_the_contact() -> None:
    """The last frames before the contact may already touch: they read 5 N here."""
    touching = {margin: IcfnEstimator(_OffsetIcfn(0.3), tare_window_s=1.0,  # type: ignore[arg-type]
                                      tare_margin_s=margin) for margin in (0.0, 0.25)}
    for est in touching.values():
        _free_then_loaded(est, 2.0, lambda t: 5.0 if t > 1.4 else 0.0)
    assert touching[0.25].tare_n == pytest.approx(0.3)
    assert touching[0.0].tare_n == pytest.approx(5.3)


def test_a_reading_at_rest_within_the_networks_scatter_is_measured_not_tared() -> None:
    small = IcfnEstimator(_OffsetIcfn(0.05), tare_window_s=1.0)  # type: ignore[arg-type]
    readings = _free_then_loaded(small, 2.0, lambda t: 0.0)
    assert small.rest_n == pytest.approx(0.05)
    assert small.tare_n == 0.0
    assert readings[-1] == pytest.approx(1.05)
    below = IcfnEstimator(_OffsetIcfn(-0.2), tare_window_s=1.0)  # type: ignore[arg-type]
    _free_then_loaded(below, 2.0, lambda t: 0.0)
    assert below.tare_n == pytest.approx(-0.2)


def test_no_free_frames_or_no_window_means_no_tare() -> None:
    """No window is the default: the paper's baselines read the paper's ICFN as it is."""
    at_once = IcfnEstimator(_OffsetIcfn(0.3), tare_window_s=1.0)  # type: ignore[arg-type]
    _free_then_loaded(at_once, 0.0, lambda t: 0.0)
    assert at_once.tare_n == 0.0
    assert math.isnan(at_once.rest_n)
    off = IcfnEstimator(_OffsetIcfn(0.3))  # type: ignore[arg-type]
    readings = _free_then_loaded(off, 2.0, lambda t: 0.0)
    assert off.tare_n == 0.0
    assert readings[-1] == pytest.approx(1.3)
    assert RelaxEstimator(_Icfn(), rcfn=None).icfn.tare_window_s > 0  # type: ignore[arg-type]


def test_bad_tare_windows_are_refused() -> None:
    with pytest.raises(ValueError, match="tare"):
        IcfnEstimator(_Icfn(), tare_window_s=-1.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="tare"):
        IcfnEstimator(_Icfn(), tare_margin_s=math.nan)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="tare"):
        IcfnEstimator(_Icfn(), tare_min_n=-0.1)  # type: ignore[arg-type]


def test_relax_reads_the_icfn_again_once_the_hold_ends() -> None:
    """Opening the fingers after a hold: Eq. 10's closure term would read the opening."""
    est = RelaxEstimator(_Icfn(), rcfn=None, smoothing_s=0.0)  # type: ignore[arg-type]
    t = 0.0
    for motor in np.linspace(90.0, 100.0, 60):  # load to 4 N along 0.4 N/mm
        est.update(_percept(t, 4.0 + STIFFNESS_N_PER_MM * (motor - 100.0)), float(motor))
        t += 1.0 / RATE_HZ
    est.start_hold(t, 100.0)
    assert math.isfinite(est.f_onset_n)
    est.end_hold(t + 1.0)
    assert math.isnan(est.f_onset_n)
    after = est.update(_percept(t + 1.1, 0.2), 50.0)  # opened by 50 mm
    assert after.force_n == pytest.approx(0.2)
    assert math.isnan(after.hold_s)
    assert math.isnan(after.f_onset_n)


def _with_features(t: float, x: np.ndarray) -> Percept:
    marker = MarkerState(t, TrackStatus.TRACKING, delta_t_m=np.array([5e-4, 0.0, 0.0]),
                         delta_r_rad=np.zeros(3))
    return Percept(t, marker, None, math.inf, "", x, None)


def test_features_with_a_nan_entry_are_no_reading_not_zero_newtons() -> None:
    """Clipped at zero, the network's nan read 0 N: a valid estimate the controller closes on."""
    est = IcfnEstimator(_Icfn())  # type: ignore[arg-type]
    assert est.update(_with_features(0.0, np.array([5.0])), 50.0).valid
    bad = est.update(_with_features(1.0 / RATE_HZ, np.array([math.nan])), 50.0)
    assert math.isnan(bad.f_icfn_n)
    assert not bad.valid
    assert est.update(_with_features(2.0 / RATE_HZ, np.array([5.0])), 50.0).force_n == 5.0


def test_a_nan_frame_does_not_poison_the_loading_history() -> None:
    """With the unrelaxed ICFN a nan temperature entry went into the branches for good:
    every later frame read 0 N."""
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.perception.features import ICFN_SCHEMA

    models = load_default_models()
    assert models.unrelaxed is not None
    x = np.zeros(len(ICFN_SCHEMA))
    x[ICFN_SCHEMA.index("marker_dx_m")] = 5e-4
    for j in (0, 1):
        for i in range(5):
            x[ICFN_SCHEMA.index(f"f{j}_beam{i}_c")] = 40.0
        for stat, value in (("mean", 40.0), ("max", 41.0), ("min", 39.0), ("std", 0.5)):
            unit = "k" if stat == "std" else "c"
            x[ICFN_SCHEMA.index(f"f{j}_temp_{stat}_{unit}")] = value
    blind = x.copy()
    blind[ICFN_SCHEMA.index("f0_temp_mean_c")] = math.nan
    est = IcfnEstimator(models.icfn, smoothing_s=0.0, unrelaxed=models.unrelaxed)
    before = est.update(_with_features(0.0, x), 50.0).force_n
    assert before > 1.0
    assert not est.update(_with_features(1.0 / RATE_HZ, blind), 50.0).valid
    after = est.update(_with_features(2.0 / RATE_HZ, x), 50.0).force_n
    assert after == pytest.approx(before, rel=0.05)
