"""McuClient <-> McuEndpoint over the in-memory link, in virtual time."""

from __future__ import annotations

import pytest

from relaxgrip.clock import VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol import (
    AppliedOutputs,
    LinkCorruptedError,
    LinkTimeoutError,
    McuClient,
    McuConfig,
    McuCore,
    McuEndpoint,
    McuFaultError,
    McuRejectedError,
    MemoryLink,
    VersionMismatchError,
)
from relaxgrip.hardware.protocol import codec as c


class Rig:
    """Host client and emulated MCU on one virtual clock, MCU served while the host waits."""

    def __init__(self, mcu_version: int = c.PROTOCOL_VERSION, host_version: int = 1,
                 mcu_minor: int = c.PROTOCOL_MINOR, host_minor: int = c.PROTOCOL_MINOR) -> None:
        self.clock = VirtualClock()
        self.link = MemoryLink(self.clock)
        core = McuCore(McuConfig(protocol_version=mcu_version, protocol_minor=mcu_minor,
                                 load_cell=True))
        self.mcu = McuEndpoint(self.link.device, self.clock, core)
        self.link.host.set_service(self.mcu.poll)
        self.client = McuClient(self.link.host, self.clock, protocol_version=host_version,
                                protocol_minor=host_minor)

    def start(self) -> None:
        self.client.handshake()
        self.client.set_enabled(True)

    def idle(self, seconds: float) -> None:
        """Let time pass with the MCU running and the host silent."""
        steps = round(seconds / 0.001)
        for _ in range(steps):
            self.clock.advance(0.001)
            self.mcu.poll()


def test_handshake_reports_mcu_identity() -> None:
    rig = Rig()
    ack = rig.client.handshake()
    assert ack == c.HelloAck(0, 200, 20_000, "relaxgrip-emu 1", 1, int(c.Feature.LOAD_CELL),
                             10_000)
    assert rig.client.hello_ack == ack
    assert rig.client.session_minor == 1
    assert rig.client.link_age_s == 0.0
    rig.client.set_enabled(True)
    assert rig.client.command(1.0, (0.0, 0.0)).layout_minor == 1


@pytest.mark.parametrize(("mcu_minor", "host_minor"), [(0, 1), (1, 0), (0, 0)])
def test_an_older_minor_on_either_side_runs_a_minor_0_session(mcu_minor: int,
                                                              host_minor: int) -> None:
    """docs/protocol.md §12: the session speaks the older minor; a minor-0 MCU answers the
    minor-1 Hello WRONG_LENGTH and the host says the minor-0 one."""
    rig = Rig(mcu_minor=mcu_minor, host_minor=host_minor)
    ack = rig.client.handshake()
    assert ack == c.HelloAck(1 if host_minor else 0, 200, 20_000, "relaxgrip-emu 1")
    assert rig.client.session_minor == 0
    rig.client.set_enabled(True)
    st = rig.client.command(2.0, (0.5, 0.0))
    assert st.layout_minor == 0
    assert (st.velocity_mm_s, st.heater_duty) == (2.0, (0.5, 0.0))
    assert rig.mcu.core.rx_error_count == (1 if (mcu_minor, host_minor) == (0, 1) else 0)


def test_control_loop_at_30_hz() -> None:
    rig = Rig()
    rig.start()
    for _ in range(90):  # 3 s of 33 ms ticks
        rig.clock.advance(0.033)
        st = rig.client.command(4.0, (0.25, 1.0))
        assert st.enabled
        assert st.fault_flags == 0
    assert st.velocity_mm_s == 4.0
    assert st.heater_duty == (0.25, 1.0)
    # The ideal motor moved 4 mm/s for 89 ticks of 33 ms (the first command started it).
    assert st.position_mm == pytest.approx(4.0 * 0.033 * 89, abs=0.01)
    assert st.mcu_time_us == round(rig.clock.now() * 1e6)
    stats = rig.client.stats
    assert (stats.frames_sent, stats.frames_received, stats.decode_errors) == (92, 92, 0)
    assert stats.mcu_frames_lost == 0
    assert st.rx_error_count == 0
    assert st.rx_gap_count == 0


def test_clamped_velocity_is_reported() -> None:
    rig = Rig()
    rig.start()
    st = rig.client.command(50.0, (0.0, 0.0))
    assert st.velocity_mm_s == 20.0
    assert "VELOCITY_CLAMPED" in st.faults
    with pytest.raises(InputError, match=r"heater_duty\[0\] 1.2 is outside 0-1"):
        rig.client.command(1.0, (1.2, 0.0))


@pytest.mark.parametrize(("mcu", "host"), [(2, 1), (1, 2)])
def test_version_mismatch_names_both_versions(mcu: int, host: int) -> None:
    rig = Rig(mcu_version=mcu, host_version=host)
    with pytest.raises(VersionMismatchError) as info:
        rig.client.handshake()
    msg = str(info.value)
    assert f"MCU speaks protocol version {mcu}" in msg
    assert f"this host speaks version {host}" in msg
    assert (info.value.mcu_version, info.value.host_version) == (mcu, host)
    assert rig.clock.now() < 0.1


def test_watchdog_trips_after_200_ms_of_silence_not_before() -> None:
    rig = Rig()
    rig.start()
    rig.client.command(5.0, (0.5, 0.5))
    rig.idle(0.199)
    assert rig.client.poll() == []
    before = rig.mcu.core.outputs
    assert before.velocity_um_s == 5_000
    rig.idle(0.001)
    (st,) = rig.client.poll()
    assert st.unsolicited
    assert st.faults == {"WATCHDOG"}
    assert not st.enabled
    assert rig.mcu.core.outputs == AppliedOutputs()  # motor stopped, heaters off
    with pytest.raises(McuFaultError, match="stopped by fault WATCHDOG"):
        rig.client.command(5.0, (0.5, 0.5))
    rig.client.set_enabled(True)
    assert rig.client.command(5.0, (0.5, 0.5)).enabled


def test_longer_watchdog_period() -> None:
    rig = Rig()
    rig.start()
    rig.client.set_watchdog(0.5)
    rig.client.command(1.0, (0.0, 0.0))
    rig.idle(0.45)
    assert rig.client.command(1.0, (0.0, 0.0)).enabled
    with pytest.raises(InputError, match=r"watchdog period 5\.0 s is outside 0\.02\.\.2\.0 s"):
        rig.client.set_watchdog(5.0)


def test_dead_link_noticed_within_100_ms() -> None:
    rig = Rig()
    rig.start()
    rig.client.command(1.0, (0.0, 0.0))
    rig.link.cut()
    t0 = rig.clock.now()
    with pytest.raises(
        LinkTimeoutError, match="no reply from the MCU to Command seq 3 within 100 ms"
    ):
        rig.client.command(1.0, (0.0, 0.0))
    assert rig.clock.now() - t0 <= 0.1 + 1e-9
    assert rig.client.link_age_s == pytest.approx(0.1)
    rig.link.restore()
    # The MCU's watchdog stopped the motor meanwhile? Not yet (100 ms < 200 ms).
    assert rig.client.command(1.0, (0.0, 0.0)).enabled


def test_corrupted_reply_is_reported() -> None:
    rig = Rig()
    rig.start()

    def flip(data: bytes) -> bytes:
        b = bytearray(data)
        b[len(b) // 2] ^= 0x10
        return bytes(b)

    rig.link.device.tamper = flip
    with pytest.raises(LinkCorruptedError, match=r"1 corrupted frame.*BAD_") as info:
        rig.client.request_status()
    assert "\n" not in str(info.value)
    assert rig.client.stats.decode_errors == 1
    rig.link.device.tamper = None
    assert rig.client.request_status().enabled


def test_corrupted_command_is_reported_by_the_mcu() -> None:
    rig = Rig()
    rig.start()
    rig.link.host.tamper = lambda data: data[:-3] + bytes([data[-3] ^ 0xFF]) + data[-2:]
    with pytest.raises(LinkCorruptedError, match=r"the MCU could not read 1 frame\(s\) \(BAD_"):
        rig.client.command(1.0, (0.0, 0.0))
    rig.link.host.tamper = None
    st = rig.client.command(1.0, (0.0, 0.0))
    assert st.rx_error_count == 1
    assert st.rx_gap_count == 1


def test_truncated_reply_is_reported() -> None:
    rig = Rig()
    rig.start()
    rig.client.set_watchdog(2.0)  # the failed exchanges below take 100 ms each
    rig.link.device.tamper = lambda data: data[: len(data) // 2]
    with pytest.raises(LinkCorruptedError, match="bytes of a truncated frame pending"):
        rig.client.request_status()
    rig.link.device.tamper = None
    with pytest.raises(LinkCorruptedError, match="1 corrupted frame"):
        rig.client.request_status()  # the tail merges with the next reply: both lost
    assert rig.client.request_status().enabled  # then back in step


def test_mcu_reset_is_noticed() -> None:
    rig = Rig()
    rig.start()
    rig.mcu.core = McuCore(start_s=rig.clock.now())  # power cycle
    with pytest.raises(McuRejectedError, match="MCU rejected Command seq 2: NO_HANDSHAKE"):
        rig.client.command(1.0, (0.0, 0.0))
    rig.client.handshake()
    st = rig.client.request_status()
    assert "RESET" in st.faults


def test_sequence_wraps() -> None:
    clock = VirtualClock()
    link = MemoryLink(clock)
    mcu = McuEndpoint(link.device, clock)
    link.host.set_service(mcu.poll)
    client = McuClient(link.host, clock, first_seq=65_534)
    client.handshake()
    client.set_enabled(True)
    for _ in range(5):
        st = client.command(1.0, (0.0, 0.0))
    assert st.ack_seq == 4
    assert st.rx_gap_count == 0
    assert st.rx_error_count == 0


def test_client_parameters_are_checked() -> None:
    link = MemoryLink(VirtualClock())
    with pytest.raises(InputError, match="reply_timeout_s must be in"):
        McuClient(link.host, link.clock, reply_timeout_s=0.0)
    with pytest.raises(InputError, match="first_seq 70000 is outside"):
        McuClient(link.host, link.clock, first_seq=70_000)


def test_a_fault_status_after_the_answer_in_the_same_read_reaches_poll() -> None:
    """The MCU answers, then a heater trips: both frames arrive in one read."""
    rig = Rig()
    rig.start()
    trip = [True]

    def answer_then_trip() -> None:
        sent = rig.mcu.frames_sent
        rig.mcu.poll()
        if rig.mcu.frames_sent > sent and trip:
            trip.clear()
            rig.mcu._send(rig.mcu.core.raise_fault(c.FaultFlag.OVERTEMP, rig.clock.now()))

    rig.link.host.set_service(answer_then_trip)
    assert rig.client.command(1.0, (0.5, 0.5)).enabled
    assert not trip
    polled = rig.client.poll(0.0)
    assert [(s.unsolicited, "OVERTEMP" in s.faults, s.enabled) for s in polled] == [
        (True, True, False)]
    assert rig.client.stats.unsolicited == 1


def test_an_mcu_reboot_is_not_counted_as_lost_frames() -> None:
    rig = Rig()
    rig.start()
    for _ in range(5):
        rig.client.command(1.0, (0.0, 0.0))
    rig.mcu = McuEndpoint(rig.link.device, rig.clock)  # power cycle: its seq restarts at 0
    rig.link.host.set_service(rig.mcu.poll)
    rig.client.handshake()
    rig.client.set_enabled(True)
    assert rig.client.stats.mcu_frames_lost == 0
    rig.link.cut()  # and a real loss is still counted
    rig.mcu._send([rig.mcu.core.status(0)])
    rig.link.restore()
    rig.client.command(1.0, (0.0, 0.0))
    assert rig.client.stats.mcu_frames_lost == 1


def test_replayed_mcu_frames_are_dropped_and_a_line_of_replays_is_a_fault() -> None:
    """A frame whose sequence number repeats or goes back (a line replaying old frames) is
    not taken: an old Status's encoder reading must not pass for the latest."""
    rig = Rig()
    rig.start()
    sent: list[bytes] = []
    write = rig.link.device.write

    def recording(data: bytes) -> None:
        sent.append(data)
        write(data)

    rig.link.device.write = recording  # type: ignore[method-assign]
    rig.client.command(2.0, (0.1, 0.1))
    old = sent[-1]  # the MCU's answer to that command
    rig.clock.advance(0.033)
    rig.client.command(3.0, (0.1, 0.1))
    assert rig.client.last_status is not None
    newest = rig.client.last_status
    write(old)  # replayed, and again
    write(old)
    assert rig.client.poll() == []
    assert rig.client.last_status == newest
    assert rig.client.stats.stale_frames == 2
    assert rig.client.stats.mcu_frames_lost == 0
    # A line that only replays: no answer is taken, and the error says why.
    rig.link.device.write = lambda data: write(old)  # type: ignore[method-assign]
    with pytest.raises(LinkCorruptedError, match="repeated or old sequence number dropped"):
        rig.client.request_status()
