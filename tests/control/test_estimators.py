"""The estimators' reading: ``relax``'s Eq. 10, the observer's parts, the tare, the hold's end."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from relaxgrip.control.estimators import IcfnEstimator, RelaxEstimator
from relaxgrip.control.observer import PARTS, ObserverEstimator
from relaxgrip.learning.calibration import Calibration
from relaxgrip.perception.marker import MarkerState, TrackStatus
from relaxgrip.perception.pipeline import Percept
from relaxgrip.perception.thermal import FingerThermal, ThermalFeatures

RATE_HZ = 30.0
STIFFNESS_N_PER_MM = 0.4  # the closed chain's: ICFN force per mm of motor travel


class _Icfn:
    """Stands in for the ICFN: the force is the first feature."""

    def predict_one(self, x: np.ndarray) -> float:
        return float(x[0])


class _Rcfn:
    """Stands in for the RCFN: a fixed ``(K, tau)``, counting its calls."""

    def __init__(self, k_n: float = 0.5, tau_s: float = 40.0) -> None:
        self.k_n, self.tau_s, self.calls = k_n, tau_s, 0

    def relaxation(self, x: np.ndarray) -> tuple[float, float]:
        assert x.shape == (19,)  # temperature, onset pose, pose, pose velocity
        self.calls += 1
        return self.k_n, self.tau_s


def _thermal(t: float, temp_c: float = 40.0) -> ThermalFeatures:
    finger = FingerThermal(beam_temps_c=(temp_c,) * 5, mean_c=temp_c, max_c=temp_c,
                           min_c=temp_c, std_k=0.0, gradient_k_per_m=0.0)
    return ThermalFeatures(t, (finger, finger), 25.0, ())


def _percept(t: float, force: float, thermal: bool = False) -> Percept:
    marker = MarkerState(t, TrackStatus.TRACKING, delta_t_m=np.array([1e-3 * force, 0.0, 0.0]),
                         delta_r_rad=np.zeros(3))
    return Percept(t, marker, _thermal(t) if thermal else None, math.inf, "",
                   np.array([force]), None)


def test_relax_is_eq10_from_the_onsets_icfn_and_the_rcfns_k_and_tau() -> None:
    rcfn = _Rcfn(0.5, 40.0)
    est = RelaxEstimator(_Icfn(), rcfn, smoothing_s=0.0)  # type: ignore[arg-type]
    for i in range(30):
        est.update(_percept(i / RATE_HZ, 4.0 * i / 30), 90.0 + i / 30)
    est.start_hold(1.0, 91.0)
    out = None
    for i in range(1, 3001):
        t = 1.0 + i / RATE_HZ
        out = est.update(_percept(t, 5.0, thermal=True), 91.0 + 0.01 * i)  # the motor moves
    assert out is not None
    assert rcfn.calls > 0
    hold = 3000 / RATE_HZ
    assert out.f_onset_n == pytest.approx(5.0)
    assert out.force_n == pytest.approx(5.0 - 0.5 * (1.0 - math.exp(-hold / 40.0)))
    assert (out.k_n, out.tau_s, out.hold_s) == pytest.approx((0.5, 40.0, hold))
    assert math.isnan(out.band_lo_n)
    assert math.isnan(out.calibration_n)


def _onset_force(noise: np.ndarray, without: tuple[str, ...]) -> float:
    """Load at 1 mm/s to 5 N, stop, hold; the per-frame ICFN has ``noise`` on it."""
    est = ObserverEstimator(_Icfn(), _Rcfn(), without=without)  # type: ignore[arg-type]
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
    assert _onset_force(quiet, ()) == pytest.approx(5.0, abs=1e-9)


def test_the_loading_part_averages_the_frames_before_the_onset_too() -> None:
    """Per-frame ICFN noise of 0.15 N: the onset's error shrinks with the loading frames added."""
    errors: dict[tuple[str, ...], list[float]] = {("loading",): [], (): []}
    for seed in range(40):
        noise = np.random.default_rng(seed).normal(0.0, 0.15, 400)
        for without in errors:
            errors[without].append(_onset_force(noise, without) - 5.0)
    rms = {w: float(np.sqrt(np.mean(np.square(e)))) for w, e in errors.items()}
    # 19 frames after the onset against 19 + 31: sqrt(50 / 19) = 1.6 times smaller.
    assert rms[()] < 0.75 * rms[("loading",)]
    assert rms[()] == pytest.approx(0.15 / math.sqrt(50), rel=0.3)


def _closed_hold(without: tuple[str, ...], calibration: Calibration | None = None
                 ) -> tuple[float, float, float]:
    """Load along 0.4 N/mm, hold, then close 2 mm more: the observer's estimate, F_inst and
    band half-width at the end."""
    est = ObserverEstimator(_Icfn(), _Rcfn(0.0, 40.0), calibration,  # type: ignore[arg-type]
                            without=without)
    t = 0.0
    for motor in np.linspace(90.0, 100.0, 60):
        est.update(_percept(t, 4.0 + STIFFNESS_N_PER_MM * (motor - 100.0)), float(motor))
        t += 1.0 / RATE_HZ
    est.start_hold(t, 100.0)
    out = None
    for i in range(120):
        t += 1.0 / RATE_HZ
        motor = 100.0 + 2.0 * i / 119  # the ICFN reads the closure's force
        out = est.update(_percept(t, 4.0 + STIFFNESS_N_PER_MM * (motor - 100.0), thermal=True),
                         motor)
    assert out is not None
    return out.force_n, out.f_onset_n, out.band_hi_n - out.force_n


def test_the_closure_part_adds_the_force_of_the_controllers_closure() -> None:
    with_closure, onset, _ = _closed_hold(())
    assert onset == pytest.approx(4.0)
    assert with_closure == pytest.approx(4.0 + 2.0 * STIFFNESS_N_PER_MM)
    without, onset, _ = _closed_hold(("closure",))
    assert without == pytest.approx(onset)  # Eq. 10 (K = 0): the onset force throughout
    assert onset == pytest.approx(4.0, abs=0.1)


def test_the_calibration_part_takes_the_modelled_error_off_and_gives_the_band() -> None:
    cal = Calibration((0.1, 0.02, 0.0), 0.01)
    force, onset, half = _closed_hold(("closure",), cal)
    assert force == pytest.approx(onset - 0.1 - 0.02 * onset)
    assert half == pytest.approx(0.01 * (1.0 + onset))
    without, onset, no_band = _closed_hold(("closure", "calibration"), cal)
    assert without == pytest.approx(onset)
    assert math.isnan(no_band)


def test_unknown_parts_and_bad_windows_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown observer part"):
        ObserverEstimator(_Icfn(), _Rcfn(), without=("chain",))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="window"):
        ObserverEstimator(_Icfn(), _Rcfn(), onset_window_s=0.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="window"):
        RelaxEstimator(_Icfn(), _Rcfn(), onset_window_s=math.nan)  # type: ignore[arg-type]
    assert set(PARTS) == {"tare", "loading", "closure", "calibration"}


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
    assert RelaxEstimator(_Icfn(), _Rcfn()).icfn.tare_window_s == 0  # type: ignore[arg-type]
    assert ObserverEstimator(_Icfn(), _Rcfn()).icfn.tare_window_s > 0  # type: ignore[arg-type]


def test_bad_tare_windows_are_refused() -> None:
    with pytest.raises(ValueError, match="tare"):
        IcfnEstimator(_Icfn(), tare_window_s=-1.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="tare"):
        IcfnEstimator(_Icfn(), tare_margin_s=math.nan)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="tare"):
        IcfnEstimator(_Icfn(), tare_min_n=-0.1)  # type: ignore[arg-type]


@pytest.mark.parametrize("make", [RelaxEstimator, ObserverEstimator])
def test_eq10_estimators_read_the_icfn_again_once_the_hold_ends(make: Callable[..., object]
                                                                ) -> None:
    """Opening the fingers after a hold: the observer's closure term would read the opening."""
    est = make(_Icfn(), _Rcfn(), smoothing_s=0.0)
    t = 0.0
    for motor in np.linspace(90.0, 100.0, 60):  # load to 4 N along 0.4 N/mm
        est.update(_percept(t, 4.0 + STIFFNESS_N_PER_MM * (motor - 100.0)), float(motor))
        t += 1.0 / RATE_HZ
    est.start_hold(t, 100.0)  # type: ignore[attr-defined]
    est.update(_percept(t + 0.1, 4.0), 100.0)  # type: ignore[attr-defined]
    assert math.isfinite(est.f_onset_n)  # type: ignore[attr-defined]
    est.end_hold(t + 1.0)  # type: ignore[attr-defined]
    assert math.isnan(est.f_onset_n)  # type: ignore[attr-defined]
    after = est.update(_percept(t + 1.1, 0.2), 50.0)  # type: ignore[attr-defined]
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
