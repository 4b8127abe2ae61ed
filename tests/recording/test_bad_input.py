"""Bad recordings give one error line and exit code 2."""

from __future__ import annotations

import base64
import errno
import io
import json
import os
import shutil
import struct
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from relaxgrip.clock import VirtualClock
from relaxgrip.control import GraspController, GraspPlan, make_estimator, run_loop
from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import HoldResult
from relaxgrip.learning.store import ModelBundle
from relaxgrip.learning.training import default_models_dir
from relaxgrip.recording import McapRecorder
from tests.clitools import assert_one_error_line, run_main
from tests.recording.conftest import copy_recording


def _without(src: Path, dst: Path, topics: set[str]) -> None:
    """Copy a recording leaving out some topics."""
    copy_recording(src, dst, lambda topic, data, _: None if topic in topics else data)


@pytest.mark.parametrize("command", ["replay", "from-recordings"])
def test_missing_foreign_truncated(command: str, relax_hold: tuple[Path, HoldResult],
                                   tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    good, _ = relax_hold
    foreign = tmp_path / "notes.mcap"
    foreign.write_text("not a recording\n" * 10)
    truncated = tmp_path / "cut.mcap"
    data = good.read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    prefix = ["replay"] if command == "replay" else ["dataset", "from-recordings"]
    suffix: list[str | Path] = [] if command == "replay" else ["--out", tmp_path / "data"]
    for path, expected in ((tmp_path / "nope.mcap", "no such recording"),
                           (foreign, "not an MCAP file"),
                           (truncated, "truncated")):
        code, out, err = run_main([*prefix, path, *suffix], monkeypatch, capsys)
        assert_one_error_line(code, out, err, expected)
    assert not (tmp_path / "data").exists()


def test_recording_without_frames(tmp_path: Path, models: ModelBundle,
                                  monkeypatch: pytest.MonkeyPatch,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    from relaxgrip.twin import GripperTwin, TwinConfig

    cfg = replace(TwinConfig(), rgb=None, ir=None)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    ctl = GraspController(cfg.rig, make_estimator("icfn", models.icfn, models.rcfn))
    path = tmp_path / "blind.mcap"
    with McapRecorder(path) as rec:
        run_loop(twin, ctl, clock, GraspPlan(target_n=5.0), 1.0, recorder=rec)
    code, out, err = run_main(["replay", path], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "no RGB frames")
    code, out, err = run_main(["dataset", "from-recordings", path, "--out", tmp_path / "d"],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, "no RGB frames")


class _FillingFile(io.FileIO):
    """A file on a disk that is full once ``room`` bytes are in it: a write past that
    writes what fits, then fails, as the system's ``write`` does."""

    def __init__(self, path: Path, room: int) -> None:
        super().__init__(path, "w")
        self.room = room

    def write(self, data: Any) -> int:
        fits = max(0, self.room - self.tell())
        if len(data) > fits:
            super().write(bytes(data)[:fits])
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)


def filling_disk(monkeypatch: pytest.MonkeyPatch, room: int) -> None:
    """The recorder's new files fill up at ``room`` bytes; other opens are real."""
    import builtins

    import relaxgrip.recording.recorder as recorder_module

    def fake_open(path: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        if mode == "wb":
            return io.BufferedWriter(_FillingFile(path, room))
        return builtins.open(path, mode, *args, **kwargs)

    monkeypatch.setattr(recorder_module, "open", fake_open, raising=False)


def test_a_full_disk_seals_the_recording_names_it_and_the_heaters_go_off(
        tmp_path: Path, models: ModelBundle, monkeypatch: pytest.MonkeyPatch) -> None:
    from relaxgrip.recording.reader import iter_messages, read_session
    from relaxgrip.twin import GripperTwin, TwinConfig

    path = tmp_path / "grasp.mcap"
    filling_disk(monkeypatch, 2_000_000)
    cfg = TwinConfig()
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    ctl = GraspController(cfg.rig, make_estimator("relax", models.icfn, models.rcfn))
    with pytest.raises(OSError, match="No space left") as caught, McapRecorder(path) as rec:
        run_loop(twin, ctl, clock, GraspPlan(target_n=5.0, temp_c=45.0), 30.0, recorder=rec)
    assert caught.value.errno == errno.ENOSPC
    assert caught.value.filename == str(path)  # the one line relaxgrip prints names it
    assert rec.messages > 100  # it filled up mid-run, not at the start
    assert twin.observe().heater_duty == (0.0, 0.0)  # the loop switched the heaters off
    # Sealed: a complete file, read without tolerance, up to the time the error states.
    assert path.stat().st_size <= 2_000_000
    times = [t for _, t, _ in iter_messages(path)]
    assert len(times) > 100
    assert f"sealed at its last complete chunk ({max(times) / 1e9:.2f} s of loop time)" \
        in str(caught.value.strerror)
    assert read_session(path)["estimator"] == "relax"
    rec.close()  # closing again does nothing


def test_a_disk_full_from_the_start_leaves_no_file_or_an_empty_sealed_one(
        tmp_path: Path, models: ModelBundle, monkeypatch: pytest.MonkeyPatch) -> None:
    from relaxgrip.recording.reader import iter_messages
    from relaxgrip.twin import GripperTwin, TwinConfig

    path = tmp_path / "grasp.mcap"
    filling_disk(monkeypatch, 30)  # not even the MCAP header fits
    with pytest.raises(OSError, match="No space left") as caught:
        McapRecorder(path)
    assert caught.value.filename == str(path)
    assert not path.exists()
    filling_disk(monkeypatch, 1000)  # the header fits, the first chunk does not
    cfg = TwinConfig()
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=0, clock=clock)
    ctl = GraspController(cfg.rig, make_estimator("fixed", models.icfn, models.rcfn))
    with pytest.raises(OSError, match="sealed before its first chunk was complete: it holds "
                                      "no messages"), McapRecorder(path) as rec:
        run_loop(twin, ctl, clock, GraspPlan(target_n=2.0), 5.0, recorder=rec)
    assert list(iter_messages(path)) == []  # a complete, empty recording


def test_a_summary_that_does_not_fit_leaves_every_message_sealed(
        tmp_path: Path, models: ModelBundle, monkeypatch: pytest.MonkeyPatch) -> None:
    """The disk fills while close() writes the summary: the data is all there, sealed."""
    from relaxgrip.recording.reader import iter_messages
    from relaxgrip.twin import GripperTwin, TwinConfig

    def record(path: Path) -> McapRecorder:
        cfg = TwinConfig()
        clock = VirtualClock()
        twin = GripperTwin(cfg, seed=0, clock=clock)
        ctl = GraspController(cfg.rig, make_estimator("fixed", models.icfn, models.rcfn))
        rec = McapRecorder(path)
        run_loop(twin, ctl, clock, GraspPlan(target_n=2.0), 3.0, recorder=rec)
        return rec

    whole = tmp_path / "whole.mcap"
    record(whole).close()
    data = whole.read_bytes()
    size = len(data)
    # The footer (29 bytes, then the closing magic) starts with where the summary does.
    (summary_start,) = struct.unpack("<Q", data[size - 37 + 9: size - 37 + 17])
    assert 0 < summary_start < size - 37
    filling_disk(monkeypatch, (summary_start + size) // 2)
    path = tmp_path / "cut.mcap"
    rec = record(path)  # every message went out in chunks; the summary is still to come
    with pytest.raises(OSError, match="No space left on device; the recording stops, sealed"):
        rec.close()
    assert path.stat().st_size < size
    assert list(iter_messages(path)) == list(iter_messages(whole))


def test_a_full_disk_on_the_command_line_is_one_line_and_the_file_reads(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "hold.mcap"
    filling_disk(monkeypatch, 1_500_000)
    code, out, err = run_main(["hold", "--duration-s", "20", "--record", path],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, f"{path}: No space left on device; the recording "
                                          "stops, sealed at its last complete chunk (")
    code, out, err = run_main(["replay", path, "--json"], monkeypatch, capsys)
    assert code == 0, err
    assert json.loads(out)["periods"] > 10


def test_recording_without_infrared_frames(relax_hold: tuple[Path, HoldResult], tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    good, _ = relax_hold
    blind = tmp_path / "no-ir.mcap"
    _without(good, blind, {"/ir"})
    code, out, err = run_main(["replay", blind], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "no infrared frames")


def test_recording_without_ground_truth(relax_hold: tuple[Path, HoldResult], tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    good, _ = relax_hold
    blind = tmp_path / "no-truth.mcap"
    _without(good, blind, {"/relaxgrip/truth", "/relaxgrip/force_ref"})
    code, out, err = run_main(["dataset", "from-recordings", blind, "--out", tmp_path / "d"],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, "no force ground truth")


def test_calibrating_on_a_recording_without_a_force_reference(
        relax_hold: tuple[Path, HoldResult], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    good, _ = relax_hold
    blind = tmp_path / "no-truth.mcap"
    _without(good, blind, {"/relaxgrip/truth", "/relaxgrip/force_ref"})
    directory = tmp_path / "models"
    shutil.copytree(default_models_dir(), directory)
    before = (directory / "manifest.json").read_bytes()
    code, out, err = run_main(["calibrate-hold", directory, "--recordings", good,
                               "--recordings", blind], monkeypatch, capsys)
    assert_one_error_line(code, out, err, f"{blind}: no force reference")
    assert (directory / "manifest.json").read_bytes() == before


def test_hold_record_refuses_compare(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_main(["hold", "--compare", "--record", tmp_path / "r.mcap"],
                              monkeypatch, capsys)
    assert_one_error_line(code, out, err, "--record records one run")
    assert not (tmp_path / "r.mcap").exists()


def test_recover_cli(relax_hold: tuple[Path, HoldResult], tmp_path: Path,
                     monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    good, _ = relax_hold
    cut = tmp_path / "cut.mcap"
    data = good.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    out_path = tmp_path / "fixed.mcap"
    code, out, err = run_main(["recover", cut, out_path], monkeypatch, capsys)
    assert code == 0, err
    assert "was truncated" in out
    code, out, err = run_main(["replay", out_path, "--json"], monkeypatch, capsys)
    assert code == 0, err
    code, out, err = run_main(["recover", tmp_path / "none.mcap", out_path], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "no such recording")


def _summary(path: Path):
    with open(path, "rb") as f:
        return make_reader(f).get_summary()


def test_recover_a_damaged_chunk_costs_its_own_messages(
        relax_hold: tuple[Path, HoldResult], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A complete file with one chunk damaged: that chunk is skipped, the rest kept,
    the loss stated; no channel is written twice from the summary."""
    good, _ = relax_hold
    whole = _summary(good)
    assert whole is not None
    assert whole.statistics is not None
    copy = tmp_path / "copy.mcap"
    code, out, err = run_main(["recover", good, copy], monkeypatch, capsys)
    assert code == 0, err
    assert f"was complete: {whole.statistics.message_count} messages on " \
           f"{len(whole.channels)} channels" in out
    copied = _summary(copy)
    assert copied is not None
    assert len(copied.channels) == len(whole.channels)
    assert len(copied.schemas) == len(whole.schemas)

    chunks = sorted(whole.chunk_indexes, key=lambda c: c.chunk_start_offset)
    middle = chunks[len(chunks) // 2]
    data = bytearray(good.read_bytes())
    data[middle.chunk_start_offset + middle.chunk_length - 100] ^= 0xFF  # in its records
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    out_path = tmp_path / "recovered.mcap"
    code, out, err = run_main(["recover", damaged, out_path, "--json"], monkeypatch, capsys)
    assert code == 0, err
    report = json.loads(out)
    assert report["damaged_chunks"] == 1
    assert report["expected_messages"] == whole.statistics.message_count
    assert 0 < report["lost_messages"] < whole.statistics.message_count // 4
    assert report["messages"] + report["lost_messages"] == whole.statistics.message_count
    recovered = _summary(out_path)
    assert recovered is not None
    assert recovered.statistics is not None
    assert recovered.statistics.message_count == report["messages"]
    assert recovered.statistics.message_end_time == whole.statistics.message_end_time


def test_recover_refuses_outputs_it_cannot_write(
        relax_hold: tuple[Path, HoldResult], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    good, _ = relax_hold
    code, out, err = run_main(["recover", good, tmp_path], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "is a directory; name the MCAP file to write")
    code, out, err = run_main(["recover", good, tmp_path / "no" / "x.mcap"], monkeypatch, capsys)
    assert_one_error_line(code, out, err, "cannot write (No such file or directory)")
    assert list(tmp_path.iterdir()) == []  # no temporary left behind
    fifo = tmp_path / "ff"
    os.mkfifo(fifo)  # formerly replaced by a regular file, exit code 0
    code, out, err = run_main(["recover", good, fifo], monkeypatch, capsys)
    assert_one_error_line(code, out, err, f"{fifo} is a FIFO, not a regular file: "
                                          "choose another output")
    assert fifo.is_fifo()
    assert list(tmp_path.iterdir()) == [fifo]


def _rewritten(src: Path, dst: Path, change) -> None:
    """Copy a recording with ``change(topic, message)`` applied to its first message per topic."""
    changed: set[str] = set()

    def first(topic: str, data: bytes, _: int) -> bytes:
        if topic in changed:
            return data
        new = change(topic, json.loads(data))
        if new is None:
            return data
        changed.add(topic)
        return json.dumps(new).encode()

    copy_recording(src, dst, first)


def _drop(key: str):
    return lambda m: {k: v for k, v in m.items() if k != key}


@pytest.mark.parametrize(("topic", "change", "words"), [
    ("/relaxgrip/session", lambda m: {**m, "format_version": "two"},
     "format_version is not an integer"),
    ("/relaxgrip/session", lambda m: {**m, "rig": "x"}, "the session's rig is not an object"),
    ("/relaxgrip/observation", _drop("motor_position_mm"),
     "a message lacks the field 'motor_position_mm'"),
    ("/relaxgrip/observation", lambda m: {**m, "rgb_seq": None, "t_s": "soon"},
     "a message has a malformed field"),
    ("/rgb", lambda m: {**m, "data": "abc"}, "a message has a malformed field"),
    ("/relaxgrip/estimate", lambda m: 3.5, "a message on /relaxgrip/estimate is not a JSON "
                                           "object"),
])
@pytest.mark.parametrize("command", ["replay", "from-recordings"])
def test_a_malformed_message_is_one_line(command: str, topic: str, change, words: str,
                                         relax_hold: tuple[Path, HoldResult], tmp_path: Path,
                                         monkeypatch: pytest.MonkeyPatch,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.mcap"
    _rewritten(relax_hold[0], bad, lambda t, m: change(m) if t == topic else None)
    args: list[str | Path] = (["replay", bad] if command == "replay" else
                              ["dataset", "from-recordings", bad, "--out", tmp_path / "d"])
    code, out, err = run_main(args, monkeypatch, capsys)
    assert_one_error_line(code, out, err, words)
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize(("topic", "change", "words"), [
    ("/rgb", lambda m: {**m, "data": base64.b64encode(b"no jpeg here").decode()},
     "an RGB frame (jpeg) does not decode"),
    ("/relaxgrip/observation", lambda m: {**m, "motor_position_mm": float("nan")},
     "motor_position_mm must be a finite number"),
])
def test_a_bad_frame_or_value_names_its_recording(topic: str, change, words: str,
                                                  relax_hold: tuple[Path, HoldResult],
                                                  tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.mcap"
    _rewritten(relax_hold[0], bad, lambda t, m: change(m) if t == topic else None)
    code, out, err = run_main(["replay", bad], monkeypatch, capsys)
    assert_one_error_line(code, out, err, f"{bad}: {words}")


def test_a_recording_to_a_fifo_is_refused_not_blocked_on(tmp_path: Path) -> None:
    """``hold --record`` opened a FIFO for writing: without a reader it blocked for ever (the
    hold never started, no error), with one the recording went into the pipe."""
    fifo = tmp_path / "grasp.mcap"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # so that the test cannot block
    try:
        with pytest.raises(InputError, match=f"{fifo} is a FIFO, not a regular file"):
            McapRecorder(fifo)
    finally:
        os.close(reader)
    assert fifo.is_fifo()
