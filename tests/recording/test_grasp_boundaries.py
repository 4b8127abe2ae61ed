"""A recording across the operator's requests: a grasp begun, stopped, begun again."""

from __future__ import annotations

from pathlib import Path

import pytest

from relaxgrip.clock import VirtualClock
from relaxgrip.control import GraspController, GraspPlan, make_estimator
from relaxgrip.control.phases import GraspPhase
from relaxgrip.errors import InputError
from relaxgrip.learning.store import ModelBundle
from relaxgrip.recording import McapRecorder, iter_messages, read_session, replay
from relaxgrip.recording.reader import read_replayable_session
from relaxgrip.twin import GripperTwin, TwinConfig

#: No temperature: the controller never zeroes the marker again during a grasp.
PLAN = GraspPlan(target_n=3.0)


class _Bench:
    """The twin and a controller stepped period by period in virtual time, as the
    dashboard steps them: an operator's request lands between two periods."""

    def __init__(self, models: ModelBundle) -> None:
        cfg = TwinConfig()
        self.clock = VirtualClock()
        self.twin = GripperTwin(cfg, seed=0, clock=self.clock)
        self.controller = GraspController(cfg.rig,
                                          make_estimator("icfn", models.icfn, models.rcfn),
                                          heat=cfg.heat)
        self.recorder: McapRecorder | None = None

    def record(self, path: Path) -> McapRecorder:
        """Begin recording to ``path`` (lossless frames) now, between two periods."""
        self.recorder = self.begun(path)
        return self.recorder

    def begun(self, path: Path) -> McapRecorder:
        """A recorder begun now, not stepped (its session message only)."""
        recorder = McapRecorder(path, rgb_format="png")
        recorder.start(self.twin.info, self.controller, self.clock.now())
        return recorder

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds * 30)):
            self.clock.sleep_until(self.clock.now() + 1 / 30)
            obs = self.twin.observe()
            command = self.controller.step(obs)
            self.twin.act(command)
            if self.recorder is not None:
                self.recorder.step(obs, self.controller, command)


def _events(path: Path) -> list[dict[str, object]]:
    return [m for topic, _, m in iter_messages(path) if topic == "/relaxgrip/events"]


def test_a_recording_begun_between_grasps_replays_exactly(tmp_path: Path,
                                                          models: ModelBundle) -> None:
    """The next grasp's start drops the last grasp's marker zero; the replay repeats that
    from the grasp's ``open``, so no rezero is written for it (one was, and the replay
    zeroed the marker a frame late)."""
    bench = _Bench(models)
    bench.controller.start(PLAN, bench.clock.now())
    bench.run(1.0)
    assert bench.controller.perception.tracker.zero_pose is not None
    bench.controller.stop(bench.clock.now())
    bench.run(0.2)
    path = tmp_path / "second.mcap"
    with bench.record(path):
        bench.controller.start(PLAN, bench.clock.now())
        bench.run(1.5)
    assert read_session(path)["grasp_in_progress"] is False
    assert "marker_rezero" not in [e["kind"] for e in _events(path)]
    m = replay(path, models).metrics()
    assert m["icfn_compared"] > 10
    assert m["icfn_max_abs_diff_n"] == 0.0
    assert m["icfn_valid_agreement"] == 1.0
    assert m["marker_status_agreement"] == 1.0


def test_a_recording_begun_once_the_marker_zero_took_a_frame_is_in_progress(
        tmp_path: Path, models: ModelBundle) -> None:
    """The frames the zero pose averages are not in a recording begun after the first of
    them: it cannot be replayed (it was said to be, and replayed on another zero)."""
    bench = _Bench(models)
    bench.controller.start(PLAN, bench.clock.now())
    early, late = tmp_path / "early.mcap", tmp_path / "late.mcap"
    bench.begun(early).close()  # before the grasp's first period
    bench.run(3 / 30)
    tracker = bench.controller.perception.tracker
    assert bench.controller.phase is GraspPhase.OPEN
    assert tracker.zero_pose is None
    assert 0 < tracker.zero_samples < tracker.zero_frames
    bench.begun(late).close()
    assert read_session(early)["grasp_in_progress"] is False
    assert read_session(late)["grasp_in_progress"] is True
    with pytest.raises(InputError, match=r"began during a grasp \(phase open\)"):
        read_replayable_session(late)


def test_a_stop_and_a_start_between_two_periods_are_both_recorded(
        tmp_path: Path, models: ModelBundle) -> None:
    """Stop then Start before the next period (two viewers, a quick operator): the stopped
    grasp's last entries are written before the new grasp's."""
    bench = _Bench(models)
    bench.controller.start(PLAN, bench.clock.now())
    path = tmp_path / "restart.mcap"
    with bench.record(path):
        bench.run(0.3)
        t = bench.clock.now()
        bench.controller.stop(t)
        bench.controller.start(PLAN, t)
        bench.run(0.2)
    events = [(e["kind"], e["detail"], e["t_s"]) for e in _events(path)]
    assert events[1:4] == [("phase", "stopped", t), ("stop", "operator", t),
                           ("phase", "open", t)]
    assert events[0][:2] == ("phase", "open")
