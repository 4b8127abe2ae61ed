"""A recorder killed with SIGKILL mid-run leaves every flushed chunk readable."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from relaxgrip.errors import InputError
from relaxgrip.recording import iter_periods, recover
from relaxgrip.recording.reader import iter_messages

FLUSH_S = 0.5
KILL_AT_S = 5.0

_CHILD = textwrap.dedent("""
    import sys
    from dataclasses import replace
    from pathlib import Path

    from relaxgrip.clock import VirtualClock
    from relaxgrip.control import GraspController, GraspPlan, make_estimator, run_loop
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.recording import McapRecorder
    from relaxgrip.twin import GripperTwin, TwinConfig

    class Announcing(McapRecorder):
        def step(self, obs, controller, command):
            super().step(obs, controller, command)
            print(obs.t_s, flush=True)  # this period is in the recorder's hands

    models = load_default_models()
    cfg = replace(TwinConfig(), initial_temp_c=40.0)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    ctl = GraspController(cfg.rig, make_estimator("fixed", models.icfn, models.rcfn),
                          heat=cfg.heat)
    rec = Announcing(Path(sys.argv[1]), flush_every_s=float(sys.argv[2]))
    run_loop(twin, ctl, clock, GraspPlan(target_n=5.0, temp_c=40.0, hold_s=200.0), 400.0,
             recorder=rec)
    rec.close()
    print("finished", flush=True)
""")


def test_sigkill_leaves_the_flushed_part_readable(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    child = subprocess.Popen([sys.executable, "-c", _CHILD, str(path), str(FLUSH_S)],
                             stdout=subprocess.PIPE, text=True)
    assert child.stdout is not None
    last_t = -1.0
    for line in child.stdout:
        assert line.strip() != "finished", "the run ended before it was killed"
        last_t = float(line)
        if last_t >= KILL_AT_S:
            os.kill(child.pid, signal.SIGKILL)
            break
    child.wait(timeout=30)
    assert child.returncode == -signal.SIGKILL
    assert last_t >= KILL_AT_S
    # Strict reading names the problem and the way out.
    with pytest.raises(InputError, match=r"truncated.*relaxgrip recover"):
        next(iter_periods(path))
    # Tolerant reading gives every period up to the last flush before the kill.
    periods = list(iter_periods(path, tolerant=True))
    times = [p.t_s for p in periods]
    assert times == sorted(times)
    assert times[0] == 0.0
    assert times[-1] >= last_t - FLUSH_S - 1e-9
    assert all(p.rgb is not None for p in periods[1:])
    # recover writes a complete file that mcap's indexed reader opens.
    out = tmp_path / "recovered.mcap"
    report = recover(path, out)
    assert not report.complete
    n_tolerant = sum(1 for _ in iter_messages(path, tolerant=True))
    assert report.messages == n_tolerant
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert summary.statistics is not None
    assert summary.statistics.message_count == n_tolerant
    assert [p.t_s for p in iter_periods(out)] == times


def _recording_hold(path: Path, ignore_hangup: bool = False) -> subprocess.Popen[bytes]:
    """``relaxgrip hold --json --record path`` in a child, once its recording has grown past
    1 MB.

    The child gets the stop signals a terminal gives (SIGHUP ignored with
    ``ignore_hangup``, as ``nohup`` starts it), whatever this test run was
    started with: under ``nohup`` it inherits SIGHUP ignored, from ``&`` SIGINT.
    """
    def dispositions() -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_DFL)
        signal.signal(signal.SIGHUP, signal.SIG_IGN if ignore_hangup else signal.SIG_DFL)

    child = subprocess.Popen(
        [sys.executable, "-m", "relaxgrip", "hold", "--duration-s", "120", "--json",
         "--record", str(path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=dispositions)
    deadline = time.monotonic() + 120.0
    while not (path.exists() and path.stat().st_size > 1_000_000):
        assert child.poll() is None, "the hold ended before it was signalled"
        assert time.monotonic() < deadline, "the recording did not start"
        time.sleep(0.05)
    return child


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP],
                         ids=lambda s: s.name)
def test_kill_and_a_closed_terminal_stop_a_hold_as_ctrl_c_does(tmp_path: Path,
                                                                stop: signal.Signals) -> None:
    """The command's clean-up runs: the recording is closed, complete, with its summary, and
    the hold so far is printed (``"interrupted": true``)."""
    import json

    path = tmp_path / "stopped.mcap"
    child = _recording_hold(path)
    child.send_signal(stop)
    out, err = child.communicate(timeout=60)
    assert child.returncode == 130, err  # as Ctrl-C: interrupted, no traceback
    assert b"Traceback" not in err
    (line,) = out.decode().splitlines()  # one JSON object
    partial = json.loads(line)
    assert partial["interrupted"] is True
    assert partial["duration_s"] == 120.0
    assert 0.0 <= partial["held_s"] < 120.0  # stopped early in the grasp, as a rule
    assert isinstance(partial["events"], list)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert summary.statistics is not None
    assert summary.statistics.message_count == sum(1 for _ in iter_messages(path)) > 100


def test_a_hold_started_under_nohup_keeps_running_through_a_hangup(tmp_path: Path) -> None:
    path = tmp_path / "nohup.mcap"
    child = _recording_hold(path, ignore_hangup=True)
    child.send_signal(signal.SIGHUP)
    size = path.stat().st_size
    deadline = time.monotonic() + 60.0
    while path.stat().st_size < size + 1_000_000:  # still recording
        assert child.poll() is None, "a hangup stopped a hold that ignores it"
        assert time.monotonic() < deadline
        time.sleep(0.05)
    child.send_signal(signal.SIGTERM)
    child.communicate(timeout=60)
    assert child.returncode == 130


def test_sealing_a_file_cut_anywhere_keeps_what_recover_keeps(
        relax_hold: tuple[Path, object], tmp_path: Path) -> None:
    """A recording cut at any byte (a full disk) and sealed in place reads as a complete
    file, with every message a tolerant reading of the cut file finds, and no more."""
    from relaxgrip.recording.recorder import seal_recording

    whole = relax_hold[0].read_bytes()
    all_messages = sum(1 for _ in iter_messages(relax_hold[0]))
    cuts = [len(whole) * k // 23 + k for k in range(1, 23)] + [len(whole)]
    kept_counts = []
    for cut in cuts:
        path = tmp_path / f"cut{cut}.mcap"
        path.write_bytes(whole[:cut])
        expected = sum(1 for _ in iter_messages(path, tolerant=True))
        end_s = seal_recording(path)
        got = [t for _, t, _ in iter_messages(path)]  # no tolerance: a complete file
        assert len(got) == expected, cut
        assert end_s == (max(got) / 1e9 if got else None)
        assert path.stat().st_size <= cut + 50  # footer, data end and magic
        kept_counts.append(len(got))
    assert kept_counts == sorted(kept_counts)
    assert kept_counts[0] > 0
    assert kept_counts[-1] == all_messages  # a complete file loses only its summary


@pytest.mark.parametrize("cut", [0, 5, 8, 20])
def test_sealing_refuses_a_file_without_a_complete_header(
        relax_hold: tuple[Path, object], tmp_path: Path, cut: int) -> None:
    from relaxgrip.recording.recorder import seal_recording

    path = tmp_path / "stub.mcap"
    path.write_bytes(relax_hold[0].read_bytes()[:cut])
    with pytest.raises(OSError, match="MCAP header"):
        seal_recording(path)
    assert path.stat().st_size == cut  # left as it was


def test_a_signal_while_a_chunk_is_written_stops_the_run_after_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGTERM as the writer compresses a chunk: the interrupt had cut it between taking
    the chunk's messages and writing them, so the file lost them while its summary counted
    them (a hold recorded 246 messages and held 174)."""
    import zstandard

    from relaxgrip.clock import VirtualClock
    from relaxgrip.control import GraspController, GraspPlan, make_estimator, run_loop
    from relaxgrip.interrupts import interrupt
    from relaxgrip.learning.training import load_default_models
    from relaxgrip.recording import McapRecorder
    from relaxgrip.twin import GripperTwin, TwinConfig

    compress = zstandard.compress  # what mcap's writer calls, looked up at each chunk
    chunks = {"n": 0}

    def signalled(data: bytes) -> bytes:
        chunks["n"] += 1
        out: bytes = compress(data)
        if chunks["n"] == 3:
            os.kill(os.getpid(), signal.SIGTERM)  # handled as this call returns
        return out

    monkeypatch.setattr(zstandard, "compress", signalled)
    previous = signal.signal(signal.SIGTERM, interrupt)
    path = tmp_path / "signalled.mcap"
    models = load_default_models()
    cfg = TwinConfig()
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    ctl = GraspController(cfg.rig, make_estimator("fixed", models.icfn, models.rcfn))
    try:
        with pytest.raises(KeyboardInterrupt), McapRecorder(path, flush_every_s=0.2) as rec:
            run_loop(twin, ctl, clock, GraspPlan(target_n=5.0), 30.0, recorder=rec)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert chunks["n"] >= 3
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert summary.statistics is not None
    assert summary.statistics.message_count == sum(1 for _ in iter_messages(path)) > 10
