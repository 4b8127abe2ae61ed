"""The viscoelastic observer: tracking, persistence, scenario grammar, closed loop, band."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from relaxgrip.control.observer import ObserverEstimator
from relaxgrip.errors import InputError
from relaxgrip.experiments.profiles import (
    band_coverage,
    parse_disturbance,
    parse_target_profile,
    parse_temp_profile,
)
from relaxgrip.learning.history import LoadingHistory
from relaxgrip.learning.observer import (
    ObserverFileError,
    ObserverModel,
    load_default_observer,
    load_observer,
    save_observer,
)
from tests.clitools import run_main


def _model() -> ObserverModel:
    arrays = {
        "temps_c_": np.array([30.0, 40.0, 50.0, 60.0]),
        "tau_ref_s_": np.array([2.0, 20.0, 200.0]),
        "log_shift_": np.array([1.0, 0.0, -1.0, -1.6]),
        "branch_share_": np.array([[0.08, 0.10, 0.15], [0.08, 0.10, 0.15],
                                   [0.10, 0.13, 0.20], [0.12, 0.16, 0.24]]),
        "log_stiffness_": np.array([0.1, 0.0, -0.3, -0.5]),
        "band_t_s_": np.array([10.0, 100.0, 290.0]),
        "band_rel_": np.array([0.05, 0.08, 0.10]),
        "onset_rel_": np.array([0.05]),
    }
    return ObserverModel.from_arrays(arrays, ObserverModel().get_params())


def _deflection(t: float) -> float:
    """Steps of the deflection (smoothed over 0.1 s): 1 mm at 1 s, +0.2 at 60 s, -0.3 at 120 s."""
    def ramp(t0: float, h: float) -> float:
        return h * min(max((t - t0) / 0.1, 0.0), 1.0)
    return ramp(1.0, 1e-3) + ramp(60.0, 2e-4) + ramp(120.0, -3e-4)


def _temp(t: float) -> float:
    """40 °C, ramp to 55 °C over 100-130 s."""
    return 40.0 + 15.0 * min(max((t - 100.0) / 30.0, 0.0), 1.0)


def test_observer_tracks_a_continuous_prony_truth() -> None:
    """30 Hz frames (temperature held over each) vs. the ODE of Eq. 2 integrated finely."""
    model = _model()

    def rhs(t: float, f: np.ndarray) -> np.ndarray:
        _, k_i, tau = model.parameters(_temp(t))
        dd = (_deflection(t + 1e-6) - _deflection(t - 1e-6)) / 2e-6
        return k_i * dd - f / tau

    t_end = 200.0
    frames = np.arange(0.0, t_end, 1.0 / 30.0)
    sol = solve_ivp(rhs, (0.0, t_end), np.zeros(3), t_eval=frames, max_step=0.02,
                    rtol=1e-9, atol=1e-12)
    truth = np.array([model.parameters(_temp(t))[0] * _deflection(t) for t in frames]) \
        + sol.y.sum(axis=0)
    est = ObserverEstimator.__new__(ObserverEstimator)
    est.model = model
    est.history = LoadingHistory(model)
    est.reset = ObserverEstimator.reset.__get__(est)  # type: ignore[method-assign]
    est.icfn = type("Stub", (), {"reset": lambda self: None})()
    est.relax = None
    est.reset()
    got = []
    for t in frames:
        temp = _temp(float(t) - 1.0 / 60.0)  # held over the frame: its midpoint
        est.advance(float(t), _deflection(float(t)), temp)
        got.append(est.unit_force_m())
    got_a = np.array(got)
    loaded = frames > 2.0
    err = np.abs(got_a[loaded] - truth[loaded]) / np.max(truth)
    assert err.max() < 2e-3
    assert np.mean(err) < 2e-4


def test_save_load_round_trip_and_bad_files(tmp_path: Path) -> None:
    model = _model()
    save_observer(tmp_path / "m", model, {"note": "test"})
    back = load_observer(tmp_path / "m")
    for temp in (25.0, 42.0, 57.0, 70.0):
        a, b = model.parameters(temp), back.parameters(temp)
        assert a[0] == b[0]
        assert np.array_equal(a[1], b[1])
        assert np.array_equal(a[2], b[2])
    assert back.band_rel(150.0, 40.0) == model.band_rel(150.0, 40.0)
    with pytest.raises(ObserverFileError, match="missing"):
        load_observer(tmp_path / "none")
    npz = tmp_path / "m" / "observer.npz"
    npz.write_bytes(npz.read_bytes()[:-10])
    with pytest.raises(ObserverFileError, match="truncated or modified"):
        load_observer(tmp_path / "m")
    save_observer(tmp_path / "m", model, {})
    manifest = tmp_path / "m" / "manifest.json"
    data = json.loads(manifest.read_text())
    data["format_version"] = 99
    manifest.write_text(json.dumps(data))
    with pytest.raises(ObserverFileError, match="newer"):
        load_observer(tmp_path / "m")
    manifest.write_text("{not json")
    with pytest.raises(ObserverFileError, match="unreadable manifest"):
        load_observer(tmp_path / "m")
    save_observer(tmp_path / "m2", model, {})
    manifest = tmp_path / "m2" / "manifest.json"
    data = json.loads(manifest.read_text())
    data["observer"]["params"]["band_scale"] = -1.0  # a manifest's parameter, not an array
    manifest.write_text(json.dumps(data))
    with pytest.raises(ObserverFileError, match=r"manifest\.json and observer\.npz: band_scale"):
        load_observer(tmp_path / "m2")


def test_shipped_observer_loads_with_physical_parameters() -> None:
    model = load_default_observer()
    _, k_cold, tau_cold = model.parameters(35.0)
    _, k_hot, tau_hot = model.parameters(55.0)
    assert np.all(tau_hot < tau_cold)  # relaxation speeds up with temperature
    assert np.all(k_cold > 0)
    assert np.all(k_hot > 0)
    assert 0.0 < model.band_rel(100.0, 40.0) < 0.5


def test_profile_grammar() -> None:
    ramp = parse_temp_profile("ramp:40:55:150:30")
    assert ramp.value_at(100.0, 40.0) == 40.0
    assert ramp.value_at(165.0, 40.0) == pytest.approx(47.5)
    assert ramp.value_at(200.0, 40.0) == 55.0
    step = parse_target_profile("step:3:150")
    assert step.value_at(149.9, 5.0) == 5.0
    assert step.value_at(150.0, 5.0) == 3.0
    push = parse_disturbance("push:2:200:10")
    assert push.value_at(199.0, 0.0) == 0.0
    assert push.value_at(205.0, 0.0) == 2.0
    assert push.value_at(211.0, 0.0) == 0.0
    for bad, parse in (("ramp:40:55:150", parse_temp_profile), ("ramp:40:99:1:1",
                       parse_temp_profile), ("step:x:1", parse_target_profile),
                       ("step:30:1", parse_target_profile), ("push:2:-1", parse_disturbance),
                       ("pull:2:1", parse_disturbance), ("step:3:nan", parse_target_profile)):
        with pytest.raises(InputError):
            parse(bad)


@pytest.mark.parametrize("args", [["--temp-profile", "ramp:40"], ["--target-profile", "jump:1:2"],
                                  ["--disturbance", "push:9:1"],
                                  ["--compare", "--target-profile", "step:3:150"]])
def test_cli_rejects_bad_profiles(args: list[str], monkeypatch: pytest.MonkeyPatch,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_main(["hold", "--estimator", "observer", *args], monkeypatch, capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1


def test_cli_error_echoes_the_input_as_typed(monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    # ":abc:" is an emoji code to rich: the error must show what the user typed.
    code, _, err = run_main(["hold", "--disturbance", "push:abc:1"], monkeypatch, capsys)
    assert code == 2
    assert "'push:abc:1'" in err


def test_band_coverage() -> None:
    truth = np.array([1.0, 2.0, 3.0, 4.0, np.nan])
    lo = np.array([0.5, 2.5, np.nan, 3.0, 0.0])
    hi = np.array([1.5, 3.0, 4.0, 4.0, 9.0])
    assert band_coverage(truth, lo, hi) == pytest.approx(2 / 3)
    assert math.isnan(band_coverage(truth, np.full(5, np.nan), hi))


def test_short_closed_loop_hold_with_observer_and_profiles() -> None:
    from relaxgrip.experiments.controlled_hold import run_hold

    result = run_hold("observer", duration_s=6.0, seed=0,
                      target_profile=parse_target_profile("step:4:3"),
                      disturbance=parse_disturbance("push:1:4"))
    m = result.metrics()
    assert math.isfinite(m["mae_n"])
    assert m["mae_n"] < 1.0
    assert 0.0 <= m["band_coverage"] <= 1.0
    assert result.target_t_n[-1] == 4.0
    assert result.target_t_n[0] == 5.0
    est = result.estimate_n[np.isfinite(result.estimate_n)]
    assert est.size > 100


def _arrays(model: ObserverModel) -> dict[str, np.ndarray]:
    """A model's arrays as a file written before the share spread would hold them."""
    return {name: np.array(getattr(model, name)) for name in (
        "temps_c_", "tau_ref_s_", "log_shift_", "branch_share_", "log_stiffness_",
        "band_t_s_", "band_rel_", "onset_rel_")}


def _scaled_shares(model: ObserverModel, share: float) -> ObserverModel:
    arrays = _arrays(model)
    arrays["branch_share_"] = arrays["branch_share_"] * share
    return ObserverModel.from_arrays(arrays, model.get_params())


class _ChainStub:
    reads_other = False


class _RelaxStub:
    f_onset_n = 5.0

    def __init__(self) -> None:
        self.chain = _ChainStub()

    def reset(self) -> None:
        pass

    def start_hold(self, t_s: float, motor_position_mm: float, contact_m: float = math.nan) -> None:
        pass


def _stubbed(model: ObserverModel) -> ObserverEstimator:
    """An observer with the default share-fit settings and a stub ``relax`` (F_inst 5 N)."""
    est = ObserverEstimator.__new__(ObserverEstimator)
    est.model = model
    est.history = LoadingHistory(model)
    est.icfn = type("Stub", (), {"reset": lambda self: None})()
    est.relax = _RelaxStub()  # type: ignore[assignment]
    est.onset_window_s, est.share_fit_s, est.share_fit_temp_k = 0.6, 280.0, 1.0
    est.share_fit_motor_mm_s, est.share_bounds = 0.3, (0.5, 1.5)
    est.share_fit_deflection_rel, est.share_fit_settle_s = 0.02, 5.0
    est.share_fit_deflection_floor_m = 10e-6
    est.anchor_window_s = (10.0, 2.0)
    est.chain_weight = 1.0
    est.reset()
    return est


def test_branch_share_is_fitted_to_eq10_while_it_holds_and_kept_after() -> None:
    """A run whose branches carry 0.8 of the population's share: the fit finds 0.8 while
    the temperature stays, then carries the run through a 40 -> 55 °C ramp that Eq. 10
    (here: 0.5 N off by its end) no longer describes."""
    from relaxgrip.control.estimators import ForceEstimate

    model = _model()
    run = _stubbed(_scaled_shares(model, 0.8))
    est = _stubbed(model)
    onset, u_onset = 1.2, math.nan
    errors_after = []
    for t in np.arange(0.0, 200.0, 1.0 / 30.0):
        temp = _temp(float(t) - 1.0 / 60.0)
        d = 1e-3 * min(max((t - 1.0) / 0.1, 0.0), 1.0)
        run.advance(float(t), d, temp)
        est.advance(float(t), d, temp)
        if t < onset:
            continue
        if math.isnan(u_onset):
            u_onset = run.unit_force_m()
        truth = 5.0 * run.unit_force_m() / u_onset
        eq10 = truth + 0.5 * (temp - 40.0) / 15.0  # Eq. 10 drifts off as the finger heats
        got = est._with_share(ForceEstimate(eq10, math.nan), math.nan, float(t) - onset,
                              est.unit_force_m(), 100.0, d)
        if t > 130.0:
            errors_after.append(got.force_n - truth)
    assert est.share == pytest.approx(0.8, abs=0.01)
    assert not est._fitting
    assert np.max(np.abs(errors_after)) < 0.01


def test_a_moving_motor_ends_the_share_fit() -> None:
    est = _stubbed(_model())
    from relaxgrip.control.estimators import ForceEstimate

    for i, t in enumerate(np.arange(0.0, 20.0, 1.0 / 30.0)):
        est.advance(float(t), 1e-3, 40.0)
        motor = 100.0 if t < 10.0 else 100.0 - 2.0 * min(t - 10.0, 1.0)  # a new target at 10 s
        est._with_share(ForceEstimate(5.0, math.nan), math.nan, float(t), est.unit_force_m(),
                        motor, 1e-3)
        if i == 200:
            assert est._fitting
    assert not est._fitting


def test_a_new_hold_fits_its_share_anew() -> None:
    """A hold that starts again (without a new grasp) forgets the last hold's fit, its end
    and the motor it saw: the new fit runs while the motor stays at its new place."""
    from relaxgrip.control.estimators import ForceEstimate

    est = _stubbed(_model())
    est.start_hold(0.0, 100.0)
    for t in np.arange(0.0, 12.0, 1.0 / 30.0):
        est.advance(float(t), 1e-3, 40.0)
        motor = 100.0 - 2.0 * min(max(t - 10.0, 0.0), 1.0)
        est._with_share(ForceEstimate(5.0, math.nan), math.nan, float(t), est.unit_force_m(),
                        motor, 1e-3)
    first_fitting = est._fitting
    assert not first_fitting
    est.start_hold(12.0, 98.0)
    assert est._fitting
    assert est.share == 1.0
    assert not est._offsets
    for t in np.arange(12.0, 20.0, 1.0 / 30.0):
        est.advance(float(t), 1e-3, 40.0)
        est._with_share(ForceEstimate(5.0, math.nan), math.nan, float(t) - 12.0,
                        est.unit_force_m(), 98.0, 1e-3)
    assert est._fitting


def test_a_push_that_moves_the_marker_but_not_the_motor_ends_the_share_fit() -> None:
    """The controller reading Eq. 10 barely moves the motor under a push, but the marker's
    finger gives 5 % in a second: that ends the fit.  Creep of 1 % a second does not,
    nor a faster one in the first seconds, while the hold settles, nor the marker's
    noise on a light grip."""
    from relaxgrip.control.estimators import ForceEstimate

    def run(deflection: Callable[[float], float]) -> float:
        est = _stubbed(_model())
        for t in np.arange(0.0, 30.0, 1.0 / 30.0):
            d = deflection(float(t))
            est.advance(float(t), d, 40.0)
            est._with_share(ForceEstimate(5.0, math.nan), math.nan, float(t),
                            est.unit_force_m(), 100.0, d)
            if not est._fitting:
                return float(t)
        return math.inf

    assert run(lambda t: 1e-3 * (1.0 + 0.01 * t)) == math.inf
    assert run(lambda t: 1e-3 * (1.0 + 0.1 * -math.expm1(-t / 2.0))) == math.inf  # 5 %/s at 0
    assert 20.0 < run(lambda t: 1e-3 * (1.0 - 0.05 * min(max(t - 20.0, 0.0) / 0.2, 1.0))) < 20.5
    # A light grip: 0.25 mm with 1 % of frame noise (two frames differ by 1.4 % SD);
    # the averages over 0.2 s and the 10 µm floor keep it fitting, a 50 µm push does not.
    noise = np.random.default_rng(3).standard_normal(900)

    def light(t: float, push_m: float = 0.0) -> float:
        return float(0.25e-3 * (1.0 + 0.01 * noise[round(t * 30.0)]) - push_m * (t >= 20.0))

    assert run(light) == math.inf
    assert 20.0 < run(lambda t: light(t, 50e-6)) < 20.5


@pytest.mark.parametrize("kwargs", [{"share_fit_s": -1.0}, {"share_fit_temp_k": 0.0},
                                    {"share_fit_motor_mm_s": 0.0}, {"share_bounds": (1.1, 1.5)},
                                    {"share_fit_deflection_rel": 0.0},
                                    {"share_fit_deflection_floor_m": -1e-6},
                                    {"share_fit_settle_s": -1.0},
                                    {"share_bounds": (0.0, 1.5)},
                                    {"anchor_window_s": (2.0, 10.0)}])
def test_share_fit_settings_that_cannot_work_are_refused(kwargs: dict[str, object]) -> None:
    with pytest.raises(ValueError, match="share"):
        ObserverEstimator(None, _model(), **kwargs)  # type: ignore[arg-type]


def test_eq10_is_the_estimate_while_it_holds_and_the_observer_continues_from_it() -> None:
    """Eq. 10 0.05 N off the model's force, and noisy: the estimate is Eq. 10 during the fit;
    after a new target moves the motor the observer carries Eq. 10's mean offset from it
    over 2-10 s before the fit ended, in proportion to its own force, so the estimate
    does not jump."""
    from relaxgrip.control.estimators import ForceEstimate

    est = _stubbed(_model())
    rng = np.random.default_rng(0)
    offsets: list[tuple[float, float]] = []
    after: list[float] = []
    last = end = own_end = math.nan
    for t in np.arange(0.0, 40.0, 1.0 / 30.0):
        d = 1e-3 if t < 20.0 else 1e-3 - 1e-4 * min(t - 20.0, 1.0)
        est.advance(float(t), d, 40.0)
        u = est.unit_force_m()
        eq10 = (5.05 * u / est._u_on if math.isfinite(est._u_on) else 5.05)
        eq10 += 0.01 * rng.standard_normal()
        motor = 100.0 if t < 20.0 else 100.0 - 2.0 * min(t - 20.0, 1.0)
        got = est._with_share(ForceEstimate(eq10, math.nan), math.nan, float(t), u, motor, d)
        own = est.scale_n_per_m * (u - (est.share - 1.0) * est.relaxed_m())
        if est._fitting:
            assert got.force_n == eq10
            offsets.append((float(t), eq10 - own))
            last = got.force_n
            continue
        if math.isnan(end):
            end, own_end = float(t), own
            assert got.force_n == pytest.approx(last, abs=0.03)
        after.append((got.force_n - own) * own_end / own)
    assert 20.0 < end < 21.0
    assert len(after) > 100
    assert np.ptp(after) == pytest.approx(0.0, abs=1e-12)
    window = [o for h, o in offsets if end - 10.0 <= h <= end - 2.0]
    assert after[0] == pytest.approx(float(np.mean(window)), abs=1e-12)


def test_after_the_fit_its_offset_and_calibration_carry_in_proportion_to_the_force() -> None:
    """relax's calibration moves with the temperature and time it reads (here 0.01 N a
    second); the observer takes it off while Eq. 10 is the estimate.  After the fit (the
    motor moves at 20 s and the marker's deflection falls to 0.6 of itself, as a new
    target does) it carries the calibration and Eq. 10's offset of the fit's last frame
    in proportion to its own force: the table describes holds started at a temperature
    and force, not the observer after a ramp or a step."""
    from relaxgrip.control.estimators import ForceEstimate

    est = _stubbed(_model())
    last_calibration = last_estimate = math.nan
    after: list[tuple[float, float, float]] = []
    for t in np.arange(0.0, 40.0, 1.0 / 30.0):
        d = 1e-3 * (1.0 - 0.4 * min(max(t - 20.5, 0.0), 1.0))
        est.advance(float(t), d, 40.0)
        u = est.unit_force_m()
        eq10 = 5.0 * u / est._u_on if math.isfinite(est._u_on) else 5.0
        calibration = 0.05 + 0.01 * float(t)
        motor = 100.0 if t < 20.0 else 100.0 - 2.0 * min(t - 20.0, 1.0)
        got = est._with_share(ForceEstimate(eq10 + 0.02 - calibration, math.nan,
                                            calibration_n=calibration),
                              math.nan, float(t), u, motor, d)
        if est._fitting:
            assert got.force_n == pytest.approx(eq10 + 0.02 - calibration)
            last_calibration, last_estimate = calibration, got.force_n
            continue
        own = est.scale_n_per_m * (u - (est.share - 1.0) * est.relaxed_m())
        after.append((own, got.calibration_n, got.force_n))
    assert len(after) > 100
    owns, calibrations, forces = (np.array(c) for c in zip(*after, strict=True))
    assert calibrations[0] == pytest.approx(last_calibration, rel=1e-3)
    assert np.ptp(calibrations / owns) == pytest.approx(0.0, abs=1e-12)
    assert np.ptp(forces / owns) == pytest.approx(0.0, abs=1e-12)
    assert calibrations[-1] < 0.7 * last_calibration  # the force fell to about 0.6
    assert forces[0] == pytest.approx(last_estimate, abs=0.01)  # no jump when it takes over


@pytest.mark.parametrize("weight", [1.0, 0.5, 0.0])
def test_after_the_fit_the_chain_that_reads_both_fingers_takes_its_weight(
        weight: float) -> None:
    """Where relax's chain reads the other finger in the infrared frame, after the fit (a
    new target at 20 s) the estimate is ``chain_weight`` of relax's and the rest the
    observer's own; while the fit runs it is relax's either way."""
    from relaxgrip.control.estimators import ForceEstimate

    def run(reads_other: bool) -> list[tuple[bool, float, float]]:
        est = _stubbed(_model())
        est.chain_weight = weight
        assert est.relax is not None
        est.relax.chain.reads_other = reads_other  # type: ignore[misc]
        rows = []
        for t in np.arange(0.0, 40.0, 1.0 / 30.0):
            d = 1e-3 * (1.0 - 0.4 * min(max(t - 20.5, 0.0), 1.0))
            est.advance(float(t), d, 40.0)
            u = est.unit_force_m()
            relax = 4.9 - 0.01 * float(t)  # relax's reading, the chain's blended in
            motor = 100.0 if t < 20.0 else 100.0 - 2.0 * min(t - 20.0, 1.0)
            got = est._with_share(ForceEstimate(relax, math.nan, chain_n=0.1), math.nan,
                                  float(t), u, motor, d)
            rows.append((est._fitting, got.force_n, relax))
        return rows

    own, read = run(False), run(True)
    assert [r[0] for r in own] == [r[0] for r in read]
    fitting = np.array([r[0] for r in read])
    assert fitting[:300].all()
    assert not fitting[-300:].any()
    own_f = np.array([r[1] for r in own])
    read_f = np.array([r[1] for r in read])
    relax_f = np.array([r[2] for r in read])
    np.testing.assert_array_equal(read_f[fitting], own_f[fitting])
    np.testing.assert_allclose(read_f[~fitting],
                               own_f[~fitting] + weight * (relax_f[~fitting] - own_f[~fitting]),
                               atol=1e-12)
    assert weight == 0.0 or np.abs(read_f[-1] - own_f[-1]) > 0.05


def test_a_chain_weight_out_of_range_is_refused() -> None:
    from relaxgrip.learning.training import load_default_models

    bundle = load_default_models()
    with pytest.raises(ValueError, match="chain's weight"):
        ObserverEstimator(bundle.icfn, _model(), chain_weight=1.5)


def test_band_widens_after_the_fit_by_what_a_share_error_would_move_the_estimate() -> None:
    """Spread 0.1 of the relaxing share: after the fit ends (a new target at 20 s) and a
    40 -> 55 °C ramp relaxes the branches, the band grows by z_0.975 times the drift
    between two runs whose shares differ by that spread; none at the end of the fit, and
    none at all for an observer file without a spread."""
    from scipy.stats import norm

    from relaxgrip.control.estimators import ForceEstimate

    arrays = _arrays(_model())
    no_spread = ObserverModel.from_arrays(arrays, ObserverModel().get_params())
    arrays["share_spread_"] = np.full(4, 0.1)
    model = ObserverModel.from_arrays(arrays, ObserverModel().get_params())
    assert no_spread.band_drift_rel(50.0) == 0.0
    assert model.band_drift_rel(50.0) == pytest.approx(0.1 * norm.ppf(0.975))

    est, plain, other = _stubbed(model), _stubbed(no_spread), _stubbed(_scaled_shares(model, 1.1))
    rows = []
    for t in np.arange(0.0, 120.0, 1.0 / 30.0):
        temp = 40.0 + 15.0 * min(max((t - 30.0) / 30.0, 0.0), 1.0)
        d = 1e-3 * min(max((t - 1.0) / 0.1, 0.0), 1.0) if t < 20.0 else 1e-3 - 1e-4 * min(
            t - 20.0, 1.0)
        motor = 100.0 if t < 20.0 else 100.0 - 2.0 * min(t - 20.0, 1.0)
        for e in (est, plain, other):
            e.advance(float(t), d, temp)
        if t < 1.2:
            continue
        u = est.unit_force_m()
        eq10 = 5.0 * u / est._u_on if math.isfinite(est._u_on) else 5.0  # share 1 fits
        got = est._with_share(ForceEstimate(eq10, math.nan), math.nan, float(t) - 1.2, u, motor,
                              d)
        ref = plain._with_share(ForceEstimate(eq10, math.nan), math.nan, float(t) - 1.2,
                                plain.unit_force_m(), motor, d)
        assert got.force_n == ref.force_n
        assert ref.band_hi_n - ref.force_n == pytest.approx(no_spread.band_rel(t - 1.2, 40.0) * 5.0)
        rows.append((t, est._fitting, got.force_n, got.band_hi_n - got.force_n,
                     other.unit_force_m(), model.band_rel(t - 1.2, 40.0) * 5.0))
    assert est.share == pytest.approx(1.0, abs=1e-6)
    end = next(i for i, r in enumerate(rows) if not r[1])
    _t_end, _, f_end, half_end, u_other_end, base_end = rows[end]
    assert half_end == pytest.approx(base_end)
    u_other_on = rows[0][4]
    for _t, _, f, half, u_other, base in rows[end + 100::200]:
        drift = abs((f - f_end) - 5.0 * (u_other - u_other_end) / u_other_on)
        # The share also moves the onset scale: a second-order term the band leaves out.
        assert half - base == pytest.approx(norm.ppf(0.975) * drift, rel=0.1, abs=2e-3)
    assert rows[-1][3] - rows[-1][5] > 0.02  # the ramp relaxes the finger: a real widening


def test_share_spread_is_saved_and_checked(tmp_path: Path) -> None:
    arrays = _arrays(_model())
    arrays["share_spread_"] = np.array([0.05, 0.1, 0.15, 0.2])
    model = ObserverModel.from_arrays(arrays, ObserverModel().get_params())
    save_observer(tmp_path / "m", model, {})
    back = load_observer(tmp_path / "m")
    assert np.array_equal(back.share_spread_, arrays["share_spread_"])
    assert back.band_drift_rel(45.0) == model.band_drift_rel(45.0) > 0
    for bad in (np.array([0.1, 0.1]), np.array([0.1, -0.1, 0.1, 0.1])):
        arrays["share_spread_"] = bad
        with pytest.raises(ValueError, match="share_spread_"):
            ObserverModel.from_arrays(arrays, ObserverModel().get_params())


def test_drift_scale_is_its_own_and_old_files_keep_one_scale(tmp_path: Path) -> None:
    """The drift part scales with ``drift_scale`` alone and the held-out part with
    ``band_scale``; a file from before the two had their own scales (no ``drift_scale``
    among its parameters) takes the band scale for both, as the band then had."""
    arrays = _arrays(_model())
    arrays["share_spread_"] = np.array([0.05, 0.1, 0.15, 0.2])
    params = ObserverModel().get_params()
    one = ObserverModel.from_arrays(arrays, params)
    split = ObserverModel.from_arrays(arrays, {**params, "band_scale": 0.5, "drift_scale": 2.0})
    assert split.band_drift_rel(45.0) == pytest.approx(2.0 * one.band_drift_rel(45.0))
    assert split.band_rel(100.0, 40.0) == pytest.approx(0.5 * one.band_rel(100.0, 40.0))
    save_observer(tmp_path / "m", split, {})
    assert load_observer(tmp_path / "m").drift_scale == 2.0
    old = {k: v for k, v in params.items() if k != "drift_scale"}
    legacy = ObserverModel.from_arrays(arrays, {**old, "band_scale": 0.3})
    assert legacy.drift_scale == 0.3
    assert legacy.band_drift_rel(45.0) == pytest.approx(0.3 * one.band_drift_rel(45.0))
    for bad in ({"drift_scale": -1.0}, {"band_scale": 0.0}, {"drift_scale": math.nan},
                {"band_scale": "wide"}, {"band_scale": math.inf}, {"band_floor_n": -0.01},
                {"band_floor_n": math.inf}):
        with pytest.raises(ValueError, match="band_scale must be > 0, drift_scale and "
                                             "band_floor_n >= 0"):
            ObserverModel.from_arrays(arrays, {**params, **bad})


def test_the_band_floor_adds_newtons_and_old_files_have_none(tmp_path: Path) -> None:
    """The floor is added to the band in and before the hold, whatever the force; a file
    from before the band had one (no ``band_floor_n``) has none."""
    arrays = _arrays(_model())
    params = ObserverModel().get_params()
    plain = ObserverModel.from_arrays(arrays, params)
    floored = ObserverModel.from_arrays(arrays, {**params, "band_floor_n": 0.02})
    for f in (1.0, 8.0):
        assert floored.band_half_n(100.0, f, 40.0) == pytest.approx(
            plain.band_half_n(100.0, f, 40.0) + 0.02)
        assert plain.band_half_n(100.0, f, 40.0) == pytest.approx(plain.band_rel(100.0, 40.0) * f)
        assert floored.closing_half_n(f, 40.0) == pytest.approx(
            plain.closing_half_n(f, 40.0) + 0.02)
    assert floored.closing_half_n(0.0, 40.0) == 0.02  # around an open gripper's zero too
    save_observer(tmp_path / "m", floored, {})
    assert load_observer(tmp_path / "m").band_floor_n == 0.02
    assert load_observer(tmp_path / "m").provenance()["band_floor_n"] == 0.02
    old = {k: v for k, v in params.items() if k != "band_floor_n"}
    assert ObserverModel.from_arrays(arrays, old).band_floor_n == 0.0


def test_the_band_temperature_factors_widen_its_relative_part(tmp_path: Path) -> None:
    """The factor is interpolated between its temperatures and held beyond, 1 without a
    temperature read; it multiplies the relative parts, not the floor.  Saved, loaded and
    carried in provenance; files from before have none; bad ones are refused."""
    arrays = _arrays(_model())
    params = {**ObserverModel().get_params(), "band_floor_n": 0.01}
    plain = ObserverModel.from_arrays(arrays, params)
    hot = ObserverModel.from_arrays(arrays, {**params, "band_temps_c": [40.0, 55.0],
                                             "band_temp_factors": [1.0, 3.0]})
    for temp, factor in ((30.0, 1.0), (40.0, 1.0), (47.5, 2.0), (55.0, 3.0), (70.0, 3.0),
                         (math.nan, 1.0)):
        assert hot.band_factor(temp) == pytest.approx(factor)
        assert hot.band_rel(100.0, temp) == pytest.approx(factor * plain.band_rel(100.0, temp))
        assert hot.band_half_n(100.0, 5.0, temp) - 0.01 == pytest.approx(
            factor * (plain.band_half_n(100.0, 5.0, temp) - 0.01))
        assert hot.closing_half_n(5.0, temp) - 0.01 == pytest.approx(
            factor * (plain.closing_half_n(5.0, temp) - 0.01))
    assert plain.band_factor(55.0) == 1.0
    save_observer(tmp_path / "m", hot, {})
    back = load_observer(tmp_path / "m")
    assert (back.band_temps_c, back.band_temp_factors) == ((40.0, 55.0), (1.0, 3.0))
    assert back.provenance()["band_temp_factors"] == [1.0, 3.0]
    old = {k: v for k, v in params.items() if not k.startswith("band_temp")}
    assert ObserverModel.from_arrays(arrays, old).band_temp_factors == ()
    for temps, factors in (([40.0], []), ([55.0, 40.0], [1.0, 2.0]), ([40.0], [0.0]),
                           ([40.0], [math.nan]), ([math.inf], [1.0]), ([40.0], ["wide"])):
        with pytest.raises(ValueError, match="band temperature factors must be one number"):
            ObserverModel.from_arrays(arrays, {**params, "band_temps_c": temps,
                                               "band_temp_factors": factors})
    with pytest.raises(ValueError, match="bad observer parameters"):
        ObserverModel.from_arrays(arrays, {**params, "band_temps_c": 40.0,
                                           "band_temp_factors": 1.0})


def test_in_a_hot_hold_the_band_widens_by_its_factor_there() -> None:
    """Through the whole loop at 55 °C: the band's parts but the floor are the factor's
    times as wide as without it, at the temperature the infrared camera reads."""
    from relaxgrip.experiments.scenarios import scenario_hold
    from relaxgrip.learning.observer import load_default_observer

    plain = load_default_observer()
    plain.band_temps_c, plain.band_temp_factors = (), ()
    hot = load_default_observer()
    hot.band_temps_c, hot.band_temp_factors = (40.0, 55.0), (1.0, 3.0)
    halves = []
    for model in (plain, hot):
        hold = scenario_hold("observer", "hot", seed=0, duration_s=8.0, observer=model)
        half = 0.5 * (hold.series("band_hi_n") - hold.series("band_lo_n"))
        halves.append(half - hold.series("band_drift_n") - model.band_floor_n)
    ratio = halves[1] / halves[0]
    ratio = ratio[np.isfinite(ratio)]
    assert ratio.size > 200
    # The camera reads the fingers within a few tenths of a kelvin of 55 °C.
    assert np.all((ratio > 2.9) & (ratio <= 3.0 + 1e-9))


def test_in_a_hold_the_push_ends_the_share_fit_when_it_moves_the_marker() -> None:
    """Through the whole loop: the frames' marker pose reaches the share fit, which ends
    (the observer's ``chain_n`` stops) within a tenth of a second of a 2 N push at 12 s,
    where the motor alone would end it 0.17 s after.  (The object is not located: where
    it is, the chain reads both fingers and stays in the estimate after the fit.)"""
    from relaxgrip.experiments.controlled_hold import run_hold
    from relaxgrip.experiments.profiles import parse_disturbance

    hold = run_hold("observer", 5.0, 20.0, 40.0, seed=2014,
                    disturbance=parse_disturbance("push:2:12"), locate_object=False)
    fitting = hold.t_s[np.isfinite(hold.series("chain_n"))]
    assert fitting.min() == pytest.approx(5.0, abs=0.05)  # the chain's reading starts at 5 s
    assert 12.0 < fitting.max() < 12.1
