"""Streaming decoder: split frames, many per chunk, garbage, corruption; nothing escapes."""

from __future__ import annotations

import itertools
import random

from hypothesis import given, settings
from hypothesis import strategies as st

from relaxgrip.hardware.protocol import codec as c

from .strategies import packets


def wire(pkts: list[c.Packet]) -> bytes:
    return b"".join(c.encode_frame(p.message, p.seq) for p in pkts)


def feed_chunks(data: bytes, cuts: list[int]) -> list[c.DecodeResult]:
    dec = c.FrameDecoder()
    out: list[c.DecodeResult] = []
    bounds = sorted({0, len(data), *(k % (len(data) + 1) for k in cuts)})
    for a, b in itertools.pairwise(bounds):
        out += dec.feed(data[a:b])
    return out


@given(st.lists(packets, max_size=8))
def test_byte_by_byte(pkts: list[c.Packet]) -> None:
    dec = c.FrameDecoder()
    out: list[c.DecodeResult] = []
    for byte in wire(pkts):
        out += dec.feed(bytes([byte]))
    assert out == pkts
    assert dec.pending_bytes == 0


@given(st.lists(packets, max_size=8), st.lists(st.integers(0, 10_000), max_size=20))
def test_random_chunks(pkts: list[c.Packet], cuts: list[int]) -> None:
    assert feed_chunks(wire(pkts), cuts) == pkts


def test_all_frames_in_one_chunk_with_empty_frames() -> None:
    pkts = [c.Packet(k, c.SetMotorVelocity(k * 1000)) for k in range(50)]
    data = b"\x00\x00" + b"\x00".join(c.encode_frame(p.message, p.seq) for p in pkts)
    assert c.FrameDecoder().feed(data) == pkts


@settings(max_examples=300)
@given(st.binary(max_size=600), st.lists(st.integers(0, 1000), max_size=10))
def test_garbage_never_raises_and_errors_are_typed(garbage: bytes, cuts: list[int]) -> None:
    out = feed_chunks(garbage, cuts)
    assert all(isinstance(r, c.Packet | c.FrameError) for r in out)
    for r in out:
        if isinstance(r, c.FrameError):
            assert r.reason
            assert "\n" not in r.reason
            assert len(r.raw) <= c.MAX_ENCODED_FRAME_BYTES


@settings(max_examples=200)
@given(st.binary(max_size=400), packets, st.lists(st.integers(0, 2000), max_size=6))
def test_valid_frame_after_garbage_is_found(garbage: bytes, pkt: c.Packet, cuts: list[int]) -> None:
    # The garbage ends at a delimiter (as after a sender's leading 0x00).
    data = garbage + b"\x00" + c.encode_frame(pkt.message, pkt.seq)
    out = feed_chunks(data, cuts)
    assert out[-1] == pkt


@settings(max_examples=200)
@given(st.lists(packets, min_size=3, max_size=6), st.data())
def test_corrupted_byte_costs_at_most_its_frames(pkts: list[c.Packet], data: st.DataObject) -> None:
    stream = bytearray(wire(pkts))
    pos = data.draw(st.integers(0, len(stream) - 1))
    stream[pos] = data.draw(st.integers(0, 255).filter(lambda b: b != stream[pos]))
    out = c.FrameDecoder().feed(bytes(stream))
    good = [r for r in out if isinstance(r, c.Packet)]
    # A flipped byte damages its own frame, or (if it became/was a delimiter)
    # two frames; never does it fabricate a packet nobody sent.
    assert all(p in pkts for p in good)
    assert len(good) >= len(pkts) - 2
    assert len(good) < len(pkts) or bytes(stream).count(0) != len(pkts)


def test_oversize_run_is_reported_once_then_resyncs() -> None:
    dec = c.FrameDecoder()
    out = dec.feed(b"\x01" * 200)
    out += dec.feed(b"\x01" * 200)
    assert [r.code for r in out if isinstance(r, c.FrameError)] == [c.ErrorCode.OVERSIZE]
    out = dec.feed(b"\x00" + c.encode_frame(c.Hello(), 3))
    assert out == [c.Packet(3, c.Hello())]


def test_truncated_frame_is_pending_then_reported() -> None:
    frame = c.encode_frame(c.Command(1, (2, 3)), 9)
    dec = c.FrameDecoder()
    assert dec.feed(frame[:7]) == []
    assert dec.pending_bytes == 7
    (err,) = dec.feed(b"\x00")
    assert isinstance(err, c.FrameError)
    assert err.code in (c.ErrorCode.BAD_COBS, c.ErrorCode.BAD_CRC, c.ErrorCode.TOO_SHORT)
    # A truncated frame glued to the next one costs both, never the one after.
    nxt = c.encode_frame(c.Hello(), 10)
    last = c.encode_frame(c.GetStatus(), 11)
    out = dec.feed(frame[:7] + nxt + last)
    assert isinstance(out[0], c.FrameError)
    assert out[1:] == [c.Packet(11, c.GetStatus())]


def test_seeded_random_soak() -> None:
    rng = random.Random(7)
    dec = c.FrameDecoder()
    sent = [
        c.Packet(k % 65536, c.Command(rng.randint(-20_000, 20_000), (k, k))) for k in range(300)
    ]
    stream = bytearray()
    for p in sent:
        stream += b"\x00" + c.encode_frame(p.message, p.seq)
        if rng.random() < 0.1:
            stream += bytes(rng.randrange(256) for _ in range(rng.randint(1, 30)))
    got: list[c.DecodeResult] = []
    i = 0
    while i < len(stream):
        n = rng.randint(1, 64)
        got += dec.feed(bytes(stream[i : i + n]))
        i += n
    good = [r for r in got if isinstance(r, c.Packet)]
    assert all(p in sent for p in good)
    # Every frame starts with a delimiter, so a burst of garbage never costs a frame.
    assert len(good) == 300
    assert sum(isinstance(r, c.FrameError) for r in got) > 0
