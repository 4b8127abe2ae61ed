"""The perception stage as the loop uses it: frames in, marker, thermal, features, proximity out."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from relaxgrip.backend import Command, Frame, Observation
from relaxgrip.bench.perception import bench_perception
from relaxgrip.clock import VirtualClock
from relaxgrip.perception import (
    ICFN_SCHEMA,
    FeatureSchema,
    Percept,
    Perception,
    ProximityTarget,
    StreamSync,
    TrackStatus,
    build_icfn_features,
)
from relaxgrip.perception.marker import MarkerState
from relaxgrip.perception.thermal import FingerThermal, ThermalFeatures
from relaxgrip.physics.beam import deflection_share
from relaxgrip.twin import GripperTwin, TwinConfig, get_object
from tests.rigs import RIGS, twin_of


def run(perception: Perception, twin: GripperTwin, clock: VirtualClock, seconds: float,
        command: Command) -> list[tuple[Observation, Percept]]:
    out = []
    for _ in range(round(seconds * 30)):
        twin.act(command)
        clock.advance(1 / 30)
        obs = twin.observe()
        out.append((obs, perception.update(obs.rgb, obs.ir, obs.motor_position_mm)))
    return out


def test_schema_is_named_versioned_and_matches_the_paper_inputs() -> None:
    names = ICFN_SCHEMA.names
    assert len(ICFN_SCHEMA) == 29
    assert ICFN_SCHEMA.version.startswith("relaxgrip-icfn-features-v")
    assert names[:6] == ("marker_dx_m", "marker_dy_m", "marker_dz_m",
                         "marker_rx_rad", "marker_ry_rad", "marker_rz_rad")
    assert "marker_dx2_m2" in names
    assert sum(n.startswith("f0_beam") for n in names) == 5
    assert {"f1_temp_std_k", "f1_grad_k_per_m"} <= set(names)
    assert ICFN_SCHEMA.to_dict()["units"][ICFN_SCHEMA.index("f0_beam0_c")] == "degC"
    with pytest.raises(ValueError, match="unique"):
        FeatureSchema("v", ("a", "a"), ("m", "m"))


def test_features_fill_missing_beams_and_need_a_pose() -> None:
    finger = FingerThermal((40.0, math.nan, 42.0), 41.0, 42.5, 39.9, 0.5, math.nan)
    thermal = ThermalFeatures(0.0, (finger, finger), 25.0, ())
    tracking = MarkerState(0.0, TrackStatus.TRACKING, None, np.array([1e-3, 0.0, -2e-4]),
                           np.array([0.0, 0.05, 0.0]))
    v = build_icfn_features(tracking, thermal)
    assert v is not None
    assert v[ICFN_SCHEMA.index("marker_dx2_m2")] == pytest.approx(1e-6)
    beams = v[ICFN_SCHEMA.index("f0_beam0_c"): ICFN_SCHEMA.index("f0_beam0_c") + 5]
    assert beams.tolist() == [40.0, 41.0, 42.0, 41.0, 41.0]
    assert v[ICFN_SCHEMA.index("f0_grad_k_per_m")] == 0.0
    lost = MarkerState(0.0, TrackStatus.LOST)
    assert build_icfn_features(lost, thermal) is None


@pytest.mark.parametrize("rig", RIGS)
def test_grasp_features_track_the_bending_and_temperatures(rig: str) -> None:
    cfg = replace(twin_of(rig), initial_temp_c=45.0)
    j = cfg.rig.marker_finger
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    perception = Perception(twin.config.rig)
    run(perception, twin, clock, 1.0, Command(0.0, (0.4, 0.4)))
    rows = run(perception, twin, clock, 5.0, Command(20.0, (0.4, 0.4)))
    obs, percept = rows[-1]
    assert obs.truth is not None
    assert obs.truth.contact_force_n > 2.0
    assert percept.marker.status is TrackStatus.TRACKING
    assert percept.features is not None
    f = dict(zip(ICFN_SCHEMA.names, percept.features, strict=True))
    # The rendered finger bends as the rig's beam model: the marker's share of the contact's
    # deflection is the beam's (at its effective temperature; the field is not uniform).
    deflection = obs.truth.marker_deflection_m[j]
    share = deflection_share(cfg.rig.marker.position_m, obs.truth.contact_position_m,
                             obs.truth.finger_effective_temp_c[j], cfg.finger)
    assert deflection == pytest.approx(share * obs.truth.finger_deflection_m[j], rel=0.03)
    # The camera's x is the finger's bending direction (less the toe-in's cosine).
    toe = math.radians(cfg.rig.rgb.toe_in_deg)
    assert f["marker_dx_m"] == pytest.approx(deflection * math.cos(toe), rel=0.05)
    assert abs(f["marker_dy_m"]) < 2e-5
    assert abs(f["marker_ry_rad"]) == pytest.approx(obs.truth.marker_slope_rad[j], rel=0.05)
    true_mean = float(np.mean(obs.truth.finger_temps_c[0]))
    assert f["f0_temp_mean_c"] == pytest.approx(true_mean, abs=1.5)  # ±1 K camera offset
    assert percept.ir_age_s < 1.0


def test_ir_stream_is_held_and_aged_and_a_missing_one_gives_no_features() -> None:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(ir=None), seed=0, clock=clock)
    perception = Perception(twin.config.rig)
    rows = run(perception, twin, clock, 1.0, Command())
    percept = rows[-1][1]
    assert percept.marker.status is TrackStatus.TRACKING
    assert percept.thermal is None
    assert percept.ir_age_s == math.inf
    assert percept.features is None
    sync = StreamSync(3.0)
    assert sync.stale(0.0)
    sync.hold(ThermalFeatures(10.0, _fingers(), 25.0, ()))
    assert sync.age_s(12.0) == pytest.approx(2.0)
    assert not sync.stale(12.0)
    assert sync.stale(13.5)


def _fingers() -> tuple[FingerThermal, FingerThermal]:
    f = FingerThermal((25.0,) * 5, 25.0, 25.0, 25.0, 0.0, 0.0)
    return f, f


def test_bad_frames_give_invalid_states_not_exceptions() -> None:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(), seed=0, clock=clock)
    perception = Perception(twin.config.rig)
    obs = twin.observe()
    truncated = Frame(0.0, 1, np.zeros((200, 640, 3), np.uint8))
    broken_ir = Frame(0.0, 1, np.full((192, 256), np.nan, np.float32))
    percept = perception.update(truncated, broken_ir, obs.motor_position_mm)
    assert percept.marker.status is TrackStatus.INVALID
    assert "640x200" in percept.marker.message
    assert "non-finite" in percept.ir_error
    assert percept.features is None
    missing = perception.update(None, None, obs.motor_position_mm)
    assert missing.marker.status is TrackStatus.INVALID


def test_same_frame_twice_is_processed_once() -> None:
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(), seed=0, clock=clock)
    perception = Perception(twin.config.rig)
    obs = twin.observe()
    first = perception.update(obs.rgb, obs.ir, obs.motor_position_mm)
    assert perception.update(obs.rgb, obs.ir, obs.motor_position_mm) is first


@pytest.mark.parametrize("name", ["paper_cup", "force_ball"])
def test_visual_proximity_during_the_approach(name: str) -> None:
    obj = get_object(name)
    cfg = TwinConfig(object_name=name, object_distance_m=0.25, ir=None)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    perception = Perception(cfg.rig)
    perception.set_target(ProximityTarget(obj.width_m, obj.color_rgb))
    run(perception, twin, clock, 1.5, Command(20.0))  # narrow the aperture a little
    rows = run(perception, twin, clock, 9.0, Command(0.0, approach_velocity_mm_s=30.0))
    errors = []
    for obs, percept in rows[::15]:
        assert obs.truth is not None
        proximity = percept.proximity
        assert proximity is not None
        assert proximity.found
        assert proximity.position_m == pytest.approx(proximity.ahead_m + 0.080)
        errors.append(proximity.ahead_m - obs.truth.object_ahead_m)
    assert rows[-1][0].truth is not None
    assert rows[-1][0].truth.object_ahead_m == pytest.approx(0.0)
    assert np.max(np.abs(errors)) < 0.012


def test_bench_reports_the_issue_figures() -> None:
    result = bench_perception(1, n_frames=60)
    for key in ("tracked_ms_median", "full_frame_ms_median", "pose_err_mm_rms",
                "pose_err_deg_rms", "per_frame_ms_median", "thermal_ms_median"):
        assert result.headline[key] > 0.0
    assert result.headline["pose_err_mm_rms"] < 0.05
    assert result.headline["pose_err_deg_rms"] < 0.3


def test_rcfn_features_onset_velocity_closure_ratio_and_hold_time() -> None:
    from relaxgrip.perception.features import RCFN_SCHEMA, RcfnFeatures

    builder = RcfnFeatures()
    assert builder.build(40.0) is None  # before the onset
    # Loading: 2 mm/s of motor closure bends the marker 0.5 mm/s once in contact at t = 1 s.
    for k in range(31):
        t = 0.1 * k
        dx = max(0.0, 0.5e-3 * (t - 1.0))
        builder.observe(t, np.array([dx, 0, 0, 0, 0.1 * dx, 0]), 2.0 * t)
    onset = np.array([1.0e-3, 0, 0, 0, 1.0e-4, 0])
    builder.start(3.0, onset, 6.0)
    assert builder.closure_ratio == pytest.approx(4.0)  # 2 mm / 0.5 mm, contact frames only
    builder.observe(4.0, onset + np.array([2e-5, 0, 0, 0, 0, 0]), 6.0)
    x = builder.build(40.0)
    assert x is not None
    f = dict(zip(RCFN_SCHEMA.names, x, strict=True))
    assert f["temp_c"] == 40.0
    assert f["onset_dx_m"] == pytest.approx(1.0e-3)
    assert f["dx_m"] == pytest.approx(1.02e-3)
    assert f["vdx_m_s"] == pytest.approx(2e-5)
    assert f["hold_time_s"] == pytest.approx(1.0)
    from_rest = RcfnFeatures()
    from_rest.start(0.0, onset, 6.0)
    assert from_rest.build(40.0) is None  # no loading seen: the ratio is unknown


def test_rcfn_closure_ratio_of_a_loading_that_crept_in_at_the_end() -> None:
    from relaxgrip.perception.features import RcfnFeatures

    # A stiff object: 4 s at 1 mm/s bending the marker 0.25 mm/s, then 2 s of creeping
    # (0.02 mm/s of motor, 5 µm/s of marker) before the onset: the last second alone
    # bends the marker under the contact threshold.
    builder = RcfnFeatures()
    t_s, motor_mm, dx_m = 0.0, 0.0, 1e-4
    for _ in range(41):
        builder.observe(t_s, np.array([dx_m, 0, 0, 0, 0, 0]), motor_mm)
        t_s, motor_mm, dx_m = t_s + 0.1, motor_mm + 0.1, dx_m + 0.25e-4
    for _ in range(20):
        builder.observe(t_s, np.array([dx_m, 0, 0, 0, 0, 0]), motor_mm)
        t_s, motor_mm, dx_m = t_s + 0.1, motor_mm + 0.002, dx_m + 0.5e-6
    builder.start(t_s, np.array([dx_m, 0, 0, 0, 0, 0]), motor_mm)
    # The span reaches back to the latest sample bent 20 µm or more before the onset
    # (motor over marker is 4 in the loading and in the creep alike); within the last
    # second alone the ratio would be unknown and the RCFN silent.
    assert builder.closure_ratio == pytest.approx(4.0, rel=0.05)
    assert builder.build(40.0) is not None


def test_a_frame_delivered_again_after_later_ones_is_not_processed() -> None:
    """An old RGB or infrared frame (another seq, an earlier time) changes nothing: the
    held infrared stays the newest, and the percept is the last one."""
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(), seed=0, clock=clock)
    perception = Perception(twin.config.rig)
    first = twin.observe()
    rows = run(perception, twin, clock, 3.0, Command())
    last_obs, last = rows[-1]
    assert first.ir is not None
    assert first.rgb is not None
    stale_ir = Frame(first.ir.t_s, 10_000, first.ir.image)
    stale_rgb = Frame(first.rgb.t_s, 10_000, first.rgb.image)
    again = perception.update(stale_rgb, stale_ir, last_obs.motor_position_mm)
    assert again is last
    assert perception.ir.latest is not None
    assert last.thermal is not None
    assert perception.ir.latest.t_s == last.thermal.t_s


def test_an_infrared_frame_beside_a_repeated_rgb_frame_reaches_the_percept() -> None:
    """The RGB camera hands over its last frame again while a new infrared frame comes:
    the percept keeps the marker and carries the new temperatures (the temperature loop
    reads them: they were held back until the next RGB frame, or for good on a stall)."""
    clock = VirtualClock()
    twin = GripperTwin(TwinConfig(), seed=0, clock=clock)
    perception = Perception(twin.config.rig)
    obs = twin.observe()
    assert obs.rgb is not None
    assert obs.ir is not None
    first = perception.update(obs.rgb, obs.ir, obs.motor_position_mm)
    assert first.thermal is not None
    hot = Frame(obs.ir.t_s + 1.0, obs.ir.seq + 1, np.asarray(obs.ir.image, np.float32) + 20.0)
    again = perception.update(obs.rgb, hot, obs.motor_position_mm)
    assert again.marker is first.marker
    assert again.t_s == first.t_s
    assert again.thermal is perception.ir.latest
    assert again.thermal is not None
    assert again.thermal.t_s == hot.t_s
    assert again.thermal.fingers[0].max_c == pytest.approx(first.thermal.fingers[0].max_c + 20.0,
                                                           abs=0.5)
    assert perception.update(obs.rgb, hot, obs.motor_position_mm) is again  # nothing new
