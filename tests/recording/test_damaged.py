"""A damaged recording: recover keeps what the damage spared, and the reader never shows a
frame under another frame's number and time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import NonSeekingReader, make_reader

from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import HoldResult
from relaxgrip.recording import iter_messages, iter_periods, read_session, recover
from relaxgrip.recording.reader import read_replayable_session
from tests.recording.conftest import chunk_indexes, copy_recording, damage_first_chunk


def test_recover_keeps_the_rest_of_a_file_whose_first_chunk_is_damaged(
        relax_hold: tuple[Path, HoldResult], tmp_path: Path) -> None:
    """The schemas and channels were only in the first chunk: a complete file's summary
    lists them again, and the recorder now writes them ahead of the first chunk as well, so
    a killed file (no summary) keeps them too."""
    good = relax_hold[0]
    total = sum(1 for _ in iter_messages(good))
    old_style = tmp_path / "old-style.mcap"
    copy_recording(good, old_style, lambda topic, data, t: data)
    for src, cut in ((old_style, False), (good, False), (good, True)):
        damaged = tmp_path / "damaged.mcap"
        damage_first_chunk(src, damaged, killed=cut)
        out = tmp_path / "recovered.mcap"
        report = recover(damaged, out)
        assert report.damaged_chunks == 1, src
        assert report.complete is not cut
        if not cut:
            assert report.lost_messages is not None
            assert 0 < report.lost_messages < total // 4
        topics = {topic for topic, _, _ in iter_messages(out)}
        assert "/relaxgrip/observation" in topics
        assert report.messages > total // 2
    # The recorder's layout reads with mcap's linear reader as with its indexed one.
    with open(good, "rb") as f:
        linear = sum(1 for _ in NonSeekingReader(f).iter_messages())
    assert linear == total


def test_a_frame_lost_with_its_period_is_not_shown_under_a_later_frame_s_stamp(
        relax_hold: tuple[Path, HoldResult], tmp_path: Path) -> None:
    """Periods lost with a damaged chunk: the RGB frame written last before them is not the
    frame of the first observation after them, which names another."""
    good = relax_hold[0]
    original = {p.rgb.seq: p.rgb for p in iter_periods(good) if p.rgb is not None}
    times = [t for topic, t, _ in iter_messages(good) if topic == "/relaxgrip/observation"]
    lost_from, lost_to = times[60], times[64]  # periods 60-63 lost, then 64's frame

    def keep(topic: str, t: int) -> bool:
        if topic == "/rgb":  # the first lost period's frame survives, the next one's not
            return not lost_from < t <= lost_to
        return not lost_from <= t < lost_to

    gap = tmp_path / "gap.mcap"
    copy_recording(good, gap, lambda topic, data, t: data if keep(topic, t) else None)
    stamps = {m["timestamp"]["sec"] * 10**9 + m["timestamp"]["nsec"]
              for topic, _, m in iter_messages(gap) if topic == "/rgb"}
    periods = list(iter_periods(gap))
    assert len(periods) == len(times) - 4
    for p in periods:
        if p.rgb is None:
            continue
        assert round(p.rgb.t_s * 1e9) in stamps, p.t_s  # a frame the file holds
        assert p.rgb.t_s == original[p.rgb.seq].t_s
        np.testing.assert_array_equal(p.rgb.image, original[p.rgb.seq].image)


def test_recover_restores_the_session_a_damaged_first_chunk_took(
        relax_hold: tuple[Path, HoldResult], tmp_path: Path) -> None:
    """The session message is in the first chunk: damaged, the recovered file had no
    session, and nothing read it (replay: "not a relaxgrip recording").  The recorder
    writes a copy outside the chunks, which recover puts back first, saying where the
    recording resumes: replay and datasets, which need the marker's zero from the lost
    start, refuse it in one line."""
    good = relax_hold[0]
    session = read_session(good)
    for cut in (False, True):
        damaged = tmp_path / "damaged.mcap"
        damage_first_chunk(good, damaged, killed=cut)
        out = tmp_path / "recovered.mcap"
        report = recover(damaged, out)
        restored = read_session(out)
        assert report.lost_start_s == restored["lost_start_s"]
        resumes_s = restored.pop("lost_start_s") - session["t0_s"]
        assert restored == session
        assert 0.0 < resumes_s < 5.0
        # Its marker's zero went with the first chunk: not replayed on the frames after.
        with pytest.raises(InputError, match=r"recovered without its start \(a damaged first "
                                             rf"chunk; it resumes at {resumes_s:.2f} s\)"):
            read_replayable_session(out)
        first = next(iter_messages(out))
        assert first[0] == "/relaxgrip/session"
        assert sum(1 for topic, _, _ in iter_messages(out) if topic == first[0]) == 1
        assert sum(1 for _ in iter_periods(out)) > 0
        again = tmp_path / "again.mcap"  # its copy goes along
        damage_first_chunk(out, again)
        recover(again, tmp_path / "again-recovered.mcap")
        again_restored = read_session(tmp_path / "again-recovered.mcap")
        assert "lost_start_s" in again_restored
        assert {k: v for k, v in again_restored.items() if k != "lost_start_s"} == session
    # Recovered whole, the session is read once, not twice.
    whole = tmp_path / "whole.mcap"
    assert recover(good, whole).lost_start_s is None
    assert sum(1 for topic, _, _ in iter_messages(whole) if topic == "/relaxgrip/session") == 1


def _damage_session_copy(src: Path, dst: Path, utf8: bool = False,
                         first_chunk_too: bool = False) -> None:
    """``src`` with a byte of the session's copy (its metadata record) damaged: not UTF-8
    then, or (``utf8``) a control character, not JSON; ``first_chunk_too``: a byte of the
    first chunk's records as well."""
    if first_chunk_too:
        damage_first_chunk(src, dst)
        src = dst
    with open(src, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    (index,) = summary.metadata_indexes
    data = bytearray(src.read_bytes())
    at = index.offset + index.length - 20  # in the session's JSON
    data[at] = 0x01 if utf8 else data[at] ^ 0xFF
    dst.write_bytes(bytes(data))


def test_a_damaged_session_copy_costs_nothing_but_itself(
        relax_hold: tuple[Path, HoldResult], tmp_path: Path) -> None:
    """The copy is outside the chunks, without a CRC: a byte of it damaged stopped the scan
    there, and every intact chunk after it was lost to reading and to recover ("no complete
    message to recover"); damaged with the first chunk, recover raised a JSONDecodeError."""
    good = relax_hold[0]
    total = sum(1 for _ in iter_messages(good))
    damaged = tmp_path / "damaged.mcap"
    _damage_session_copy(good, damaged)
    assert sum(1 for _ in iter_messages(damaged)) == total
    assert read_session(damaged) == read_session(good)
    report = recover(damaged, tmp_path / "recovered.mcap")
    assert (report.messages, report.lost_messages, report.stopped_early) == (total, 0, False)
    _damage_session_copy(good, damaged, utf8=True, first_chunk_too=True)
    report = recover(damaged, tmp_path / "recovered.mcap")
    assert report.damaged_chunks == 1
    assert report.lost_start_s is None  # no session to restore
    assert report.messages > total // 2
    with pytest.raises(InputError, match="not a relaxgrip recording"):
        read_session(tmp_path / "recovered.mcap")


def test_recover_reads_on_past_a_broken_chunk_header_by_the_chunk_index(
        relax_hold: tuple[Path, HoldResult], tmp_path: Path) -> None:
    """A complete file whose middle chunk has a damaged length field: reading in order stops
    there, and every chunk after it was lost though the summary's chunk index lists them.
    Now only that chunk is."""
    good = relax_hold[0]
    total = sum(1 for _ in iter_messages(good))
    chunks = chunk_indexes(good)
    assert len(chunks) >= 4
    middle = chunks[len(chunks) // 2]
    data = bytearray(good.read_bytes())
    at = middle.chunk_start_offset + 1  # after the opcode: the record's length
    data[at:at + 8] = (2**40).to_bytes(8, "little")
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    out = tmp_path / "recovered.mcap"
    report = recover(damaged, out)
    assert (report.damaged_chunks, report.stopped_early) == (1, False)
    assert report.expected_messages == total
    lost = report.lost_messages
    assert lost is not None
    assert 0 < lost < total // len(chunks) * 3
    assert sum(1 for _ in iter_messages(out)) == report.messages
    assert read_session(out) == read_session(good)
