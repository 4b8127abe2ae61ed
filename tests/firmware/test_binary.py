"""The compiled firmware (relaxgrip.elf) in simavr: its UART byte for byte, its pins by the cycle.

Every test here runs the unmodified ELF that ``make -C firmware`` builds for the
ATmega328P; they skip, saying so, only where avr-gcc or simavr is missing.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import pytest

from relaxgrip.hardware.firmware_sim import (
    CPU_HZ,
    PINS,
    FirmwareImage,
    SimAvr,
    SimLink,
    build_firmware,
    toolchain_missing,
    watchdog_reactions,
)
from relaxgrip.hardware.protocol import codec as c
from relaxgrip.hardware.protocol.mcu import McuConfig, McuCore

MISSING = toolchain_missing()
pytestmark = pytest.mark.skipif(
    bool(MISSING), reason=f"the firmware's toolchain is missing ({', '.join(MISSING)}): "
                          "apt-get install gcc-avr avr-libc simavr libsimavr-dev")

OFF = {"motor_en": 0, "motor_in1": 0, "motor_in2": 0, "heater0": 0, "heater1": 0}


@pytest.fixture(scope="module")
def image() -> FirmwareImage:
    return build_firmware()


@pytest.fixture
def link(image: FirmwareImage) -> Iterator[SimLink]:
    sim = SimAvr(image)
    sim.run_for(0.002)  # powered up
    yield SimLink(sim)
    sim.close()


def packets(replies: list[c.DecodeResult]) -> list[c.Message]:
    assert all(isinstance(r, c.Packet) for r in replies), replies
    return [r.message for r in replies if isinstance(r, c.Packet)]


def answer(link: SimLink, message: c.Message, **kw: int) -> c.Message:
    (reply,) = packets(link.send(message, **kw))
    return reply


def ready(link: SimLink) -> None:
    ack = answer(link, c.Hello(1))
    assert isinstance(ack, c.HelloAck)
    st = answer(link, c.SetEnable(True))
    assert isinstance(st, c.Status)
    assert st.enabled


def levels(link: SimLink) -> dict[str, int]:
    report = link.sim.take_pins()
    return dict(zip(PINS, report.level, strict=True))


# ---------------------------------------------------------------------------- handshake


def test_handshake_of_each_minor_and_the_power_up_state(link: SimLink) -> None:
    ack = answer(link, c.Hello(1))
    assert ack == c.HelloAck(0, 200, 20_000, "relaxgrip-fw 1.1", 1, int(c.Feature.LOAD_CELL),
                             10_000)
    st = answer(link, c.GetStatus())
    assert isinstance(st, c.Status)
    assert st.layout_minor == 1
    assert st.faults == {"RESET"}
    assert not st.enabled
    assert levels(link) == OFF
    # A host of minor 0 says the Hello without payload and gets the minor-0 layouts.
    assert answer(link, c.Hello(), seq=40) == c.HelloAck(40, 200, 20_000, "relaxgrip-fw 1.1")
    st = answer(link, c.GetStatus(), seq=41)
    assert isinstance(st, c.Status)
    assert st.layout_minor == 0


def test_wrong_version_is_answered_in_the_firmware_s_own_version(link: SimLink) -> None:
    (reply,) = link.send(c.Hello(1), seq=9, version=2)
    # The host decoder of version 2 sees a frame of version 1: the mismatch, both named.
    assert isinstance(reply, c.Packet)
    assert reply.version == c.PROTOCOL_VERSION
    assert reply.message == c.ErrorReply(9, c.ErrorCode.WRONG_VERSION, 0x01, 2)


def test_the_host_reports_a_version_mismatch_in_one_line(image: FirmwareImage) -> None:
    """McuClient of another version against the binary, over the simulated UART."""
    from relaxgrip.clock import VirtualClock
    from relaxgrip.hardware.protocol import McuClient, VersionMismatchError

    class SimTransport:
        def __init__(self, sim: SimAvr, clock: VirtualClock) -> None:
            self.sim, self.clock = sim, clock

        def write(self, data: bytes) -> None:
            self.sim.write(data)

        def read(self, timeout_s: float) -> bytes:
            self.sim.run_for(max(timeout_s, 0.0005))
            self.clock.sleep_until(self.sim.time_s)
            return self.sim.read()

        def close(self) -> None:
            pass

    with SimAvr(image) as sim:
        sim.run_for(0.002)
        clock = VirtualClock(sim.time_s)
        client = McuClient(SimTransport(sim, clock), clock, protocol_version=2)
        with pytest.raises(VersionMismatchError) as info:
            client.handshake()
    assert str(info.value) == ("MCU speaks protocol version 1, this host speaks version 2: "
                               "flash matching firmware or install a matching relaxgrip")


# ---------------------------------------------------------------------------- round trips


def test_command_status_round_trips_and_pins(link: SimLink) -> None:
    ready(link)
    answer(link, c.SetWatchdog(2000))
    st = answer(link, c.Command(5_000, (2_500, 7_000)))
    assert isinstance(st, c.Status)
    assert (st.velocity_um_s, st.heater_duty_permyriad, st.fault_flags) == (5_000, (2_500, 7_000),
                                                                             0)
    link.run_for(0.005)
    link.sim.take_pins()
    link.run_for(0.1)  # 20 periods of the heaters' 200 Hz PWM (the AVR ends a run a few
    report = link.sim.take_pins()  # cycles late: an instruction's; hence 2e-5)
    assert report.duty("heater0") == pytest.approx(0.25, abs=2e-5)
    assert report.duty("heater1") == pytest.approx(0.70, abs=2e-5)
    assert report.duty("motor_in1") == 1.0  # closing: IN1 high, IN2 low
    assert report.duty("motor_in2") == 0.0
    assert report.duty("motor_en") > 0.2  # the encoder never moves: the loop drives harder
    answer(link, c.SetEnable(True))  # the loop starts afresh from where the motor stands
    answer(link, c.SetWatchdog(2000))
    st = answer(link, c.Command(-3_000, (0, 10_000)))
    assert isinstance(st, c.Status)
    link.run_for(0.1)
    link.sim.take_pins()
    link.run_for(0.1)
    report = link.sim.take_pins()
    assert (report.duty("heater0"), report.duty("heater1")) == (0.0, 1.0)
    assert (report.duty("motor_in1"), report.duty("motor_in2")) == (0.0, 1.0)
    st = answer(link, c.SetMotorVelocity(1_000))  # the velocity only
    assert isinstance(st, c.Status)
    assert (st.velocity_um_s, st.heater_duty_permyriad) == (1_000, (0, 10_000))
    st = answer(link, c.SetHeaterDuty((3, 4)))  # the duties only
    assert isinstance(st, c.Status)
    assert (st.velocity_um_s, st.heater_duty_permyriad) == (1_000, (3, 4))


def test_the_setpoint_read_from_sram_is_the_status_s(link: SimLink) -> None:
    """The fault matrix reads the firmware's setpoint from its SRAM: the layout it assumes
    is the firmware's (checked against what Status reports, and disabled after a Hello)."""
    ready(link)
    for velocity, duty in ((5_000, (2_500, 7_000)), (-3_000, (0, 10_000)), (0, (1, 2))):
        st = answer(link, c.Command(velocity, duty))
        assert isinstance(st, c.Status)
        assert link.sim.mcu_setpoint() == (True, st.velocity_um_s, st.heater_duty_permyriad)
    answer(link, c.Hello(1))
    assert link.sim.mcu_setpoint() == (False, 0, (0, 0))


def test_encoder_position_follows_the_quadrature_edges(link: SimLink) -> None:
    ready(link)
    sim = link.sim
    sim.encoder_to(3_000, sim.cycle + CPU_HZ // 2)  # 15 mm closing in 0.5 s
    link.run_for(0.6)
    st = answer(link, c.GetStatus())
    assert isinstance(st, c.Status)
    assert st.encoder_position_um == 15_000
    sim.encoder_to(-41, sim.cycle + CPU_HZ // 2)
    link.run_for(0.6)
    st = answer(link, c.GetStatus())
    assert isinstance(st, c.Status)
    assert st.encoder_position_um == -205
    assert st.fault_flags & c.FaultFlag.ENCODER == 0


def test_the_velocity_loop_tracks_the_command_on_an_ideal_motor(link: SimLink) -> None:
    """The pins drive a motor of 25 mm/s at full duty (position = ∫ duty · speed); the
    encoder reports it back: 5 mm/s commanded is 5 mm/s within 1 % over a second."""
    ready(link)
    sim = link.sim
    step = CPU_HZ // 1000
    position_mm = 0.0
    link.send(c.Command(5_000, (0, 0)))
    sim.take_pins()
    start_mm, start_s = None, 0.0
    for k in range(1500):
        report = sim.take_pins()
        drive = report.duty("motor_in1") - report.duty("motor_in2")
        position_mm += report.duty("motor_en") * drive * 25.0 * 0.001
        sim.encoder_to(round(position_mm / 0.005), sim.cycle + step)
        sim.run_until(sim.cycle + step)
        if k % 30 == 29:
            link.send(c.Command(5_000, (0, 0)))
        if k == 500:
            start_mm, start_s = position_mm, sim.time_s
    assert start_mm is not None
    speed = (position_mm - start_mm) / (sim.time_s - start_s)
    assert speed == pytest.approx(5.0, rel=0.01)


def test_load_cell_conversions_reach_status(link: SimLink) -> None:
    ready(link)
    sim = link.sim
    values = [123_456, -7, (1 << 23) - 1, -(1 << 23)]
    for i, v in enumerate(values):
        sim.hx711_push(v, sim.cycle + (i + 1) * CPU_HZ // 10)
    seen = []
    for _ in range(len(values)):
        link.run_for(0.1)
        st = answer(link, c.GetStatus())
        assert isinstance(st, c.Status)
        seen.append((st.load_cell_counts, st.load_cell_samples))
        assert st.state_flags & c.StateFlag.LOAD_CELL
        assert st.load_cell_time_us is not None
        assert 0 <= st.mcu_time_us - st.load_cell_time_us < 100_000
    assert seen == [(v, i + 1) for i, v in enumerate(values)]
    assert sim.hx711_reads == 4
    link.run_for(0.6)
    st = answer(link, c.GetStatus())
    assert isinstance(st, c.Status)
    assert not st.state_flags & c.StateFlag.LOAD_CELL  # no conversion for 500 ms


def test_a_duty_above_the_limit_is_clamped(image: FirmwareImage) -> None:
    limited = build_firmware({"HEATER_DUTY_LIMIT": 6_000})
    assert limited.elf != image.elf
    with SimAvr(limited) as sim:
        sim.run_for(0.002)
        link = SimLink(sim)
        ack = answer(link, c.Hello(1))
        assert isinstance(ack, c.HelloAck)
        assert ack.heater_duty_limit_permyriad == 6_000
        answer(link, c.SetEnable(True))
        answer(link, c.SetWatchdog(2000))
        st = answer(link, c.Command(0, (9_000, 65_535)))
        assert isinstance(st, c.Status)
        assert st.heater_duty_permyriad == (6_000, 6_000)
        assert st.faults == {"DUTY_CLAMPED"}
        link.run_for(0.01)
        sim.take_pins()
        link.run_for(0.1)
        report = sim.take_pins()
        assert report.duty("heater0") == pytest.approx(0.6, abs=2e-5)
        assert report.duty("heater1") == pytest.approx(0.6, abs=2e-5)
        st = answer(link, c.Command(50_000, (6_000, 1)))
        assert isinstance(st, c.Status)
        assert st.velocity_um_s == 20_000
        assert st.faults == {"VELOCITY_CLAMPED"}


# ---------------------------------------------------------------------------- watchdog


def test_watchdog_stops_every_pin_within_200_ms_plus_a_period_100_times_of_100(
        link: SimLink) -> None:
    """The link goes silent after 2-10 Commands at 30 Hz, at random phases; the pins, as
    measured, are all low within 200 ms + 33 ms of the last Command's arrival, the
    unsolicited Status says WATCHDOG, and a later Command is refused until SetEnable
    (watchdog_reactions checks each and raises otherwise)."""
    answer(link, c.Hello(1))
    reactions_ms = np.array(watchdog_reactions(link, 100, np.random.default_rng(5))) * 1e3
    assert reactions_ms.size == 100
    assert reactions_ms.max() <= 200.0 + 1000 / 30
    assert reactions_ms.min() >= 200.0  # not before its period


# ---------------------------------------------------------------------------- bad input


def test_ten_thousand_random_bytes_then_a_handshake_works(link: SimLink) -> None:
    rng = np.random.default_rng(11)
    ready(link)
    noise = rng.integers(0, 256, 10_000, dtype=np.uint8).tobytes()
    replies = link.exchange(noise, settle_s=0.01)
    errors = [r.message for r in replies if isinstance(r, c.Packet)]
    assert errors
    assert all(isinstance(e, c.ErrorReply) or (isinstance(e, c.Status) and e.unsolicited)
               for e in errors)
    # The host's 0x00 before its Hello closes what the noise left unfinished: that gets its
    # error (unreadable, type 0), the Hello its answer.
    *before, ack = packets(link.send(c.Hello(1), seq=700))
    assert ack == c.HelloAck(700, 200, 20_000, "relaxgrip-fw 1.1", 1, 1, 10_000)
    assert all(isinstance(e, c.ErrorReply) and e.offending_type == 0 for e in before)
    assert len(before) <= 1
    st = answer(link, c.GetStatus(), seq=701)
    assert isinstance(st, c.Status)
    assert st.rx_error_count >= len([e for e in errors if isinstance(e, c.ErrorReply)])


@pytest.mark.parametrize(("data", "code"), [
    # A truncated frame: the host's leading 0x00 before the next frame closes it.
    (c.encode_frame(c.Command(1, (2, 3)), 5)[:7], c.ErrorCode.BAD_CRC),
    (bytes.fromhex("0511223300"), c.ErrorCode.BAD_COBS),
    (c.cobs_encode(b"\x01\x01\x00") + b"\x00", c.ErrorCode.TOO_SHORT),
    (b"\x01" * 300 + b"\x00", c.ErrorCode.OVERSIZE),
])
def test_unreadable_frames_get_their_error_and_the_next_frame_its_answer(
        link: SimLink, data: bytes, code: c.ErrorCode) -> None:
    ready(link)
    (reference,) = c.FrameDecoder().feed(data if data.endswith(b"\x00") else data + b"\x00")
    assert isinstance(reference, c.FrameError)
    assert reference.code is code
    replies = packets(link.exchange(data)) + packets(link.send(c.GetStatus()))
    assert replies[0] == c.ErrorReply(0, code)
    assert isinstance(replies[1], c.Status)
    assert replies[1].enabled
    assert len(replies) == 2


def test_every_rejection_of_the_spec_on_the_binary(link: SimLink) -> None:
    assert answer(link, c.Command(1, (0, 0)), seq=3) == c.ErrorReply(
        3, c.ErrorCode.NO_HANDSHAKE, 0x06, 0)
    ready(link)
    bad_crc = bytearray(c.cobs_decode(c.encode_frame(c.GetStatus(), 2)[:-1]))
    bad_crc[-1] ^= 0x40
    assert packets(link.exchange(b"\x00" + c.cobs_encode(bytes(bad_crc)) + b"\x00")) == [
        c.ErrorReply(0, c.ErrorCode.BAD_CRC)]

    def raw(msg_type: int, seq: int, payload: bytes) -> bytes:
        body = bytes([1, msg_type]) + seq.to_bytes(2, "little") + payload
        crc = c.crc16_ccitt_false(body).to_bytes(2, "little")
        return b"\x00" + c.cobs_encode(body + crc) + b"\x00"

    cases = [
        (raw(0x42, 2, b"\x01"), c.ErrorReply(2, c.ErrorCode.UNKNOWN_TYPE, 0x42, 0x42)),
        (raw(0x06, 2, bytes(7)), c.ErrorReply(2, c.ErrorCode.WRONG_LENGTH, 0x06, 7)),
        (raw(0x04, 2, b"\x02"), c.ErrorReply(2, c.ErrorCode.VALUE_OUT_OF_RANGE, 0x04, 2)),
        (raw(0x82, 2, bytes(25)), c.ErrorReply(2, c.ErrorCode.UNKNOWN_TYPE, 0x82, 0x82)),
    ]
    for data, expected in cases:
        assert packets(link.exchange(data)) == [expected]
    assert answer(link, c.SetWatchdog(5), seq=2) == c.ErrorReply(
        2, c.ErrorCode.VALUE_OUT_OF_RANGE, 0x05, 5)
    st = answer(link, c.Command(4_000, (100, 0)), seq=3)
    assert isinstance(st, c.Status)
    dup = answer(link, c.Command(9_000, (0, 0)), seq=3)  # a retransmission: not applied
    assert isinstance(dup, c.Status)
    assert dup.velocity_um_s == 4_000
    assert answer(link, c.Command(1, (0, 0)), seq=2) == c.ErrorReply(
        2, c.ErrorCode.STALE_SEQUENCE, 0x06, 3)
    st = answer(link, c.Command(1_000, (0, 0)), seq=7)  # 4, 5, 6 lost
    assert isinstance(st, c.Status)
    assert st.rx_gap_count == 3
    assert st.rx_error_count == 8


def test_firmware_and_python_mcu_answer_every_frame_alike(link: SimLink) -> None:
    """The same 400 host frames, valid and not, at the same times, to the binary and to
    McuCore (docs/protocol.md in Python): the same answers, field for field (but the
    clocks and the encoder, which only the firmware's hardware has)."""
    rng = np.random.default_rng(3)
    core = McuCore(McuConfig(firmware_id="relaxgrip-fw 1.1", load_cell=True),
                   start_s=0.0)
    decoder = c.FrameDecoder()

    def command() -> c.Message:
        return c.Command(int(rng.integers(-30_000, 30_000)),
                         (int(rng.integers(0, 12_000)), int(rng.integers(0, 12_000))))

    choices: list[Callable[[], c.Message]] = [
        lambda: c.Hello(1), lambda: c.Hello(), lambda: c.GetStatus(), lambda: c.GetStatus(),
        lambda: c.SetEnable(True), lambda: c.SetEnable(True), lambda: c.SetEnable(False),
        lambda: c.SetWatchdog(int(rng.choice([5, 20, 200, 500, 2000, 3000]))),
        command, command, command, command, command,
        lambda: c.SetMotorVelocity(int(rng.integers(-30_000, 30_000))),
        lambda: c.SetHeaterDuty((int(rng.integers(0, 12_000)), int(rng.integers(0, 12_000)))),
    ]
    seq = 0
    seen: list[c.Message] = []

    def comparable(m: c.Message) -> object:
        seen.append(m)
        if isinstance(m, c.Status):
            return (m.ack_seq, m.velocity_um_s, m.heater_duty_permyriad, m.fault_flags,
                    m.state_flags & ~int(c.StateFlag.LOAD_CELL), m.rx_error_count,
                    m.rx_gap_count, m.layout_minor)
        return m

    for _ in range(400):
        seq = (seq + int(rng.choice([1, 1, 1, 0, 3, -2]))) % 65536
        msg = choices[int(rng.integers(0, len(choices)))]()
        frame = c.encode_frame(msg, seq, leading_delimiter=True)
        if rng.random() < 0.1:
            frame = frame[:-3] + bytes([frame[-3] ^ 0x01]) + frame[-2:]
        gap = float(rng.choice([0.002, 0.01, 0.05, 0.1, 0.4]))
        at = link.sim.time_s + gap + len(frame) * 10 / 115_200  # the delimiter's arrival
        # Keep 5 ms from the watchdog's expiry: either MCU may be first at the edge.
        trip_s = (core._last_feed_us / 1e6 + core.watchdog_ms / 1000) if core.enabled else None
        if trip_s is not None and abs(at - trip_s) < 0.005:
            gap, at = gap + 0.01, at + 0.01
        got = [comparable(p) for p in packets(link.run_for(gap) + link.exchange(frame))]
        want = []
        for item in decoder.feed(frame):
            want += [comparable(m) for m in core.receive(item, at)]
        assert got == want, (msg, seq)
    # The sequence met every kind of answer: the comparison is not of empty lists.
    codes = {m.code for m in seen if isinstance(m, c.ErrorReply)}
    assert codes >= {c.ErrorCode.BAD_CRC, c.ErrorCode.NOT_ENABLED, c.ErrorCode.STALE_SEQUENCE,
                     c.ErrorCode.VALUE_OUT_OF_RANGE}
    assert any(isinstance(m, c.Status) and m.unsolicited for m in seen)
    for flag in ("DUTY_CLAMPED", "VELOCITY_CLAMPED"):
        assert any(isinstance(m, c.Status) and flag in m.faults for m in seen)
    assert len(seen) >= 2 * 400


# ---------------------------------------------------------------------------- budget


def test_flash_and_ram_within_budget(image: FirmwareImage, link: SimLink) -> None:
    """Flash <= 24 KB and RAM <= 1.5 KB (75 % of the ATmega328P's): static data from
    avr-size, the stack's deepest reach measured on SRAM painted before power-up, after a
    run through every path (frames of every kind, noise, the load cell, the encoder)."""
    assert image.elf.with_suffix(".hex").is_file()
    assert image.flash_bytes <= 24 * 1024
    rng = np.random.default_rng(2)
    ready(link)
    link.sim.hx711_push(-5, link.sim.cycle + 1000)
    link.sim.encoder_to(500, link.sim.cycle + CPU_HZ // 10)
    for k in range(60):
        link.send(c.Command(int(rng.integers(-30_000, 30_000)), (12_000, 3)))
        link.send(c.GetStatus())
        if k % 10 == 0:
            link.exchange(rng.integers(0, 256, 600, dtype=np.uint8).tobytes())
            link.exchange(b"\x01" * 300 + b"\x00")
            ready(link)
    stack = link.sim.stack_bytes()
    assert 64 < stack < 1024
    assert image.static_ram_bytes + stack <= 1536
