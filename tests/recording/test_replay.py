"""Offline replay matches what the loop recorded (exactly with PNG frames, closely with JPEG)."""

from __future__ import annotations

import copy
import importlib
import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.clock import VirtualClock
from relaxgrip.control import GraspController, GraspPlan, make_estimator, run_loop
from relaxgrip.experiments.controlled_hold import HoldResult, run_hold
from relaxgrip.learning.observer import ObserverModel, default_observer_dir, load_default_observer
from relaxgrip.learning.store import ModelBundle
from relaxgrip.recording import McapRecorder, iter_messages, replay
from relaxgrip.recording.replay import replay_periods
from relaxgrip.twin import GripperTwin, TwinConfig
from tests.clitools import assert_one_error_line, run_main

#: JPEG moves the marker corners by a fraction of a pixel: the replayed estimate differs from
#: the recorded one by up to this (measured on a relax hold: max 0.076 N, mean 0.017 N).
JPEG_MAX_DIFF_N = 0.15


def test_png_replay_is_exact(tmp_path: Path, models: ModelBundle) -> None:
    """Lossless frames: perception and estimation replay bit for bit, marker re-zeroing included."""
    cfg = replace(TwinConfig(), initial_temp_c=40.0)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=3, clock=clock)
    ctl = GraspController(cfg.rig, make_estimator("icfn", models.icfn, models.rcfn),
                          heat=cfg.heat)
    path = tmp_path / "png.mcap"
    with McapRecorder(path, rgb_format="png") as rec:
        run_loop(twin, ctl, clock, GraspPlan(target_n=5.0, temp_c=40.0), 4.3, recorder=rec)
    kinds = [m["kind"] for t, _, m in iter_messages(path) if t == "/relaxgrip/events"]
    assert "marker_rezero" in kinds
    m = replay(path, models).metrics()
    assert m["estimate_compared"] > 20
    assert m["estimate_max_abs_diff_n"] == 0.0
    assert m["icfn_max_abs_diff_n"] == 0.0
    assert m["estimate_valid_agreement"] == 1.0
    assert m["marker_status_agreement"] == 1.0


def test_png_replay_of_a_relax_hold_reads_where_the_ball_was_seen(
        png_relax_hold: tuple[Path, HoldResult], uncalibrated: ModelBundle) -> None:
    """The hold onset's event tells replay where the object sat: the chain replays exactly."""
    path, result = png_relax_hold
    onsets = [m["detail"] for t, _, m in iter_messages(path)
              if t == "/relaxgrip/events" and m["kind"] == "hold_onset"]
    assert len(onsets) == 1
    assert "object at" in onsets[0]
    assert np.isfinite(result.loop["chain_n"]).sum() > 60  # the chain read for the last 3 s
    m = replay(path, uncalibrated).metrics()
    assert m["estimate_compared"] > 200
    assert m["estimate_max_abs_diff_n"] == 0.0


def test_jpeg_replay_of_a_relax_hold_matches_closely(relax_hold: tuple[Path, HoldResult],
                                                     models: ModelBundle) -> None:
    path, result = relax_hold
    r = replay(path, models)
    m = r.metrics()
    assert m["periods"] == result.loop["t_s"].size
    np.testing.assert_array_equal(r.recorded_n, result.loop["estimate_n"])
    # The hold (onset, RCFN, Eq. 10) is replayed: the estimate is valid in the same periods.
    assert m["estimate_valid_agreement"] == 1.0
    assert m["marker_status_agreement"] == 1.0
    assert m["estimate_compared"] > 600
    assert m["estimate_max_abs_diff_n"] < JPEG_MAX_DIFF_N
    assert m["estimate_mean_abs_diff_n"] < 0.03
    # Replaying with another estimator is not the recording: the check can fail.
    assert not np.allclose(r.recorded_n, result.loop["icfn_n"], equal_nan=True)


def test_replay_cli_json_and_plot(relax_hold: tuple[Path, HoldResult], tmp_path: Path,
                                  monkeypatch: pytest.MonkeyPatch,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = relax_hold
    figure = tmp_path / "replay.png"
    code, out, err = run_main(["replay", path, "--json", "--plot", figure], monkeypatch, capsys)
    assert code == 0, err
    data = json.loads(out)
    assert data["estimator"] == "relax"
    assert data["estimate_max_abs_diff_n"] < JPEG_MAX_DIFF_N
    assert figure.stat().st_size > 1000
    inode = figure.stat().st_ino
    code, out, err = run_main(["replay", path, "--plot", figure], monkeypatch, capsys)
    assert code == 0, err
    assert figure.stat().st_ino != inode  # replaced whole, never rewritten in place
    (tmp_path / "dir.png").mkdir()
    code, out, err = run_main(["replay", path, "--plot", tmp_path / "dir.png"], monkeypatch,
                              capsys)
    assert code == 2
    assert "is a directory" in err


def test_replay_tells_the_estimator_of_contact_onset_and_release(
        tmp_path: Path, models: ModelBundle, monkeypatch: pytest.MonkeyPatch) -> None:
    """What the controller told the estimator live, the replay tells it at the same times."""
    replay_module = importlib.import_module("relaxgrip.recording.replay")
    calls: dict[str, list[tuple[str, float]]] = {"live": [], "replay": []}

    def spying(kind: str, name: str) -> object:
        est = make_estimator(kind, models.icfn, models.rcfn, unrelaxed=models.unrelaxed)
        for method in ("contact", "start_hold", "end_hold"):
            real = getattr(est, method)

            def spy(t_s: float, *args: float, _real=real, _method=method) -> object:
                calls[name].append((_method, round(t_s, 6)))
                return _real(t_s, *args)
            setattr(est, method, spy)
        return est

    cfg = replace(TwinConfig(), initial_temp_c=40.0)
    clock = VirtualClock()
    ctl = GraspController(cfg.rig, spying("relax", "live"), heat=cfg.heat)  # type: ignore[arg-type]
    path = tmp_path / "release.mcap"
    with McapRecorder(path) as rec:
        run_loop(GripperTwin(cfg, seed=1, clock=clock), ctl, clock,
                 GraspPlan(target_n=3.0, temp_c=40.0, hold_s=1.0), 30.0, recorder=rec)
    assert [c for c, _ in calls["live"]] == ["contact", "start_hold", "end_hold"]
    monkeypatch.setattr(replay_module, "bundle_estimator",
                        lambda kind, bundle, observer=None: spying(kind, "replay"))
    r = replay(path, models)
    assert calls["replay"] == calls["live"]
    assert r.metrics()["estimate_valid_agreement"] == 1.0


def _dashboard_like(tmp_path: Path) -> tuple[Path, Path]:
    """A dashboard session stepped in virtual time: one PNG recording from before the
    grasp (operator's Start and Release between periods), one started during the hold."""
    pytest.importorskip("fastapi")
    from relaxgrip.dashboard.session import open_session

    clock = VirtualClock()
    session = open_session("twin", clock=clock, seed=0, record_dir=tmp_path)
    session._check_running = lambda: None  # type: ignore[method-assign]  # stepped here

    def run(seconds: float) -> None:
        for _ in range(round(seconds * 30)):
            clock.sleep_until(clock.now() + 1 / 30)
            session._period()

    def record(path: Path) -> McapRecorder:
        rec = McapRecorder(path, rgb_format="png")
        rec.start(session.backend.info, session.controller, session._now())
        return rec

    whole, late = tmp_path / "whole.mcap", tmp_path / "late.mcap"
    run(0.2)
    session._recorder = record(whole)
    session.close_grasp()
    while not session.controller.estimate.hold_s >= 2.0:
        run(1 / 30)
    both = (session._recorder, record(late))

    class Tee:
        def step(self, *args: object) -> None:
            for rec in both:
                rec.step(*args)  # type: ignore[arg-type]

        def close(self) -> None:
            for rec in both:
                rec.close()

    session._recorder = Tee()  # type: ignore[assignment]
    run(2.0)
    session.release()  # between periods: the estimator's hold ends before the next one
    run(1.0)
    session.close()
    return whole, late


def test_a_dashboard_recording_replays_exactly_and_one_begun_mid_grasp_is_refused(
        tmp_path: Path, models: ModelBundle, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    whole, late = _dashboard_like(tmp_path)
    m = replay(whole, models).metrics()
    assert m["estimate_compared"] > 100
    assert m["estimate_max_abs_diff_n"] == 0.0
    assert m["icfn_max_abs_diff_n"] == 0.0
    code, _, err = run_main(["replay", late], monkeypatch, capsys)
    assert code == 2
    assert "began during a grasp (phase hold)" in err
    code, _, err = run_main(["dataset", "from-recordings", late, "--out", tmp_path / "d"],
                            monkeypatch, capsys)
    assert code == 2
    assert "began during a grasp" in err
    assert not (tmp_path / "d").exists()
    # The late recording holds no event from before it began.
    times = [m["t_s"] for t, _, m in iter_messages(late) if t == "/relaxgrip/events"]
    first = next(m["t_s"] for t, _, m in iter_messages(late) if t == "/relaxgrip/observation")
    assert min(times) >= first - 1 / 30


def test_replay_shows_a_calibration_other_than_the_recordings(
        relax_hold: tuple[Path, HoldResult], models: ModelBundle) -> None:
    """The estimate's calibration is recorded; replayed against a directory calibrated
    otherwise, the difference is named, not only seen in the estimate."""
    from relaxgrip.learning.hold_bias import HoldBias

    path, _ = relax_hold
    same = replay(path, models).metrics()
    assert same["calibration_valid_agreement"] == 1.0
    other = (HoldBias(np.array([5.0]), np.array([40.0]), np.array([1.0]), np.full((1, 1, 1), 0.2))
             if models.hold_bias is None else None)
    changed = replay(path, replace(models, hold_bias=other)).metrics()
    assert changed["calibration_valid_agreement"] < 1.0


def test_an_observer_recording_replays_with_the_observer_it_ran_with(
        tmp_path: Path, models: ModelBundle, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The observer replays with the parameters it is given (an observer of another band
    replays another band); ``--observer`` names the ones the recording ran with (here the
    shipped ones, copied)."""
    path = tmp_path / "observer.mcap"
    observer = load_default_observer()
    with McapRecorder(path) as rec:
        run_hold("observer", 5.0, 3.0, 40.0, 2, models, recorder=rec, observer=observer)
    other = copy.deepcopy(observer)
    other.band_scale = 2.0 * observer.band_scale

    def widths(model: ObserverModel) -> np.ndarray:
        rows = [e.band_hi_n - e.band_lo_n
                for _, _, e in replay_periods(path, models, observer=model)]
        return np.array(rows)[np.isfinite(rows)]

    narrow, wide = widths(observer), widths(other)
    assert narrow.size > 50
    # Twice the relative part, the same floor: each width 2 (floor + 2 r) = 2 W - 2 floor.
    np.testing.assert_allclose(wide, 2.0 * narrow - 2.0 * observer.band_floor_n, rtol=1e-9)
    assert observer.band_floor_n > 0  # the shipped band has one: the floor is in the test
    directory = tmp_path / "observer-dir"
    shutil.copytree(default_observer_dir(), directory)
    code, out, err = run_main(["replay", path, "--observer", directory, "--json"], monkeypatch,
                              capsys)
    assert code == 0, err
    assert json.loads(out)["estimate_max_abs_diff_n"] < JPEG_MAX_DIFF_N
    code, out, err = run_main(["replay", path, "--observer", tmp_path / "none"], monkeypatch,
                              capsys)
    assert_one_error_line(code, out, err, "none")
