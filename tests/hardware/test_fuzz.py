"""The host's decoder fuzzed: 100,000 damaged, cut, spliced and random inputs, seeded.

No exception escapes the decoder, none but a version mismatch (typed) escapes the
client's reading of what the MCU sent, and no damaged frame is taken for a packet
nobody sent.
"""

from __future__ import annotations

import random
from collections.abc import Callable

from relaxgrip.clock import VirtualClock
from relaxgrip.hardware.protocol import McuClient, MemoryLink, VersionMismatchError
from relaxgrip.hardware.protocol import codec as c

#: Inputs fed to the decoder, and of them fed through the client as MCU bytes.
N_DECODER = 100_000
N_CLIENT = 10_000


def _corpus(rng: random.Random) -> list[c.Packet]:
    """Valid packets of every message type, with values across their wire ranges."""
    def i32() -> int:
        return rng.randint(-(1 << 31), (1 << 31) - 1)

    def u16() -> int:
        return rng.randint(0, 0xFFFF)

    makers: list[Callable[[], c.Message]] = [
        c.Hello, c.GetStatus,
        lambda: c.SetMotorVelocity(i32()),
        lambda: c.SetHeaterDuty((u16(), u16())),
        lambda: c.SetEnable(rng.random() < 0.5),
        lambda: c.SetWatchdog(u16()),
        lambda: c.Command(i32(), (u16(), u16())),
        lambda: c.HelloAck(u16(), u16(), i32(), "relaxgrip-emu 1"),
        lambda: c.Status(u16(), rng.randint(0, 0xFFFF_FFFF), i32(), i32(), (u16(), u16()),
                         u16(), rng.randint(0, 0xFF), u16(), u16()),
        lambda: c.ErrorReply(u16(), rng.randint(0, 0xFF), rng.randint(0, 0xFF), u16()),
    ]
    return [c.Packet(rng.randint(0, 0xFFFF), make()) for make in makers for _ in range(20)]


def _mutate(rng: random.Random, frames: list[bytes]) -> tuple[bytes, bool]:
    """A damaged input and whether the damage is one a CRC-16 always detects (a burst of at
    most 16 bits in one frame, or a frame cut short)."""
    frame = bytearray(rng.choice(frames))
    kind = rng.randrange(8)
    if kind == 0:  # one bit
        bit = rng.randrange(len(frame) * 8)
        frame[bit // 8] ^= 1 << (bit % 8)
        return bytes(frame), True
    if kind == 1:  # a burst within two bytes
        pos = rng.randrange(len(frame) - 1)
        frame[pos] ^= rng.randint(1, 255)
        frame[pos + 1] ^= rng.randint(0, 255)
        return bytes(frame), True
    if kind == 2:  # cut short
        return bytes(frame[: rng.randrange(len(frame))]) + b"\x00", True
    if kind == 3:  # bytes inserted
        pos = rng.randrange(len(frame))
        return bytes(frame[:pos] + rng.randbytes(rng.randint(1, 8)) + frame[pos:]), False
    if kind == 4:  # two frames spliced
        other = rng.choice(frames)
        return bytes(frame[: rng.randrange(len(frame))] + other[rng.randrange(len(other)):]), \
            False
    if kind == 5:  # random bytes, delimiters among them
        return rng.randbytes(rng.randint(1, 120)), False
    if kind == 6:  # many bytes changed
        for _ in range(rng.randint(3, 10)):
            frame[rng.randrange(len(frame))] = rng.randrange(256)
        return bytes(frame), False
    return bytes(frame) * rng.randint(2, 4), True  # repeated whole: each copy valid


def test_100k_fuzzed_inputs_never_raise_and_no_damaged_frame_passes(capsys) -> None:
    rng = random.Random(65)
    packets = _corpus(rng)
    frames = [c.encode_frame(p.message, p.seq) for p in packets]
    sent = set(packets)
    escaped: list[str] = []
    fabricated = detectable_passed = 0
    for _ in range(N_DECODER):
        data, detectable = _mutate(rng, frames)
        decoder = c.FrameDecoder()
        try:
            out = decoder.feed(data) + decoder.feed(b"\x00")
        except Exception as exc:
            escaped.append(f"{type(exc).__name__}: {exc} on {data.hex()}")
            continue
        for item in out:
            assert isinstance(item, c.Packet | c.FrameError)
            if isinstance(item, c.FrameError):
                assert "\n" not in item.reason
            elif item not in sent:
                fabricated += 1
                detectable_passed += detectable
    with capsys.disabled():
        print(f"\ndecoder fuzzing: {N_DECODER:,} inputs, {len(escaped)} escaped exceptions, "
              f"{fabricated} damaged frames accepted")
    assert escaped == []
    assert detectable_passed == 0  # the CRC's guarantee
    assert fabricated == 0  # and none of the others, on this seed's inputs either


def test_the_client_reads_fuzzed_mcu_bytes_without_an_untyped_exception() -> None:
    rng = random.Random(66)
    packets = [p for p in _corpus(rng) if isinstance(p.message, c.Status | c.HelloAck
                                                     | c.ErrorReply)]
    frames = [c.encode_frame(p.message, p.seq) for p in packets]
    clock = VirtualClock()
    link = MemoryLink(clock)
    client = McuClient(link.host, clock)
    mismatches = 0
    for _ in range(N_CLIENT):
        data, _ = _mutate(rng, frames)
        link.device.write(data + b"\x00")
        try:
            client.poll(0.0)
        except VersionMismatchError:  # a damaged version byte whose CRC passed: typed, named
            mismatches += 1
    assert client.stats.decode_errors > N_CLIENT // 2
    assert mismatches < N_CLIENT // 100
