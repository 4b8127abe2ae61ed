"""The MCU state machine, pure: handshake, sequence rules, watchdog, clamps, faults."""

from __future__ import annotations

import pytest

from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol import codec as c
from relaxgrip.hardware.protocol.mcu import AppliedOutputs, IdealMotorPlant, McuConfig, McuCore


def ready(now_s: float = 0.0) -> McuCore:
    core = McuCore(start_s=now_s)
    core.receive(c.Packet(0, c.Hello()), now_s)
    (reply,) = core.receive(c.Packet(1, c.SetEnable(True)), now_s)
    assert isinstance(reply, c.Status)
    assert reply.enabled
    assert reply.fault_flags == 0
    return core


def test_power_up_state_and_hello() -> None:
    core = McuCore()
    assert core.fault_flags == c.FaultFlag.RESET
    assert core.outputs == AppliedOutputs()
    (ack,) = core.receive(c.Packet(500, c.Hello()), 0.0)
    assert ack == c.HelloAck(500, 200, 20_000, "relaxgrip-emu 1")
    (st,) = core.receive(c.Packet(501, c.GetStatus()), 0.001)
    assert isinstance(st, c.Status)
    assert st.faults == {"RESET"}
    assert not st.enabled
    assert st.mcu_time_us == 1000


def test_commands_before_hello_are_refused() -> None:
    core = McuCore()
    (err,) = core.receive(c.Packet(3, c.Command(1, (0, 0))), 0.0)
    assert err == c.ErrorReply(3, c.ErrorCode.NO_HANDSHAKE, 0x06, 0)
    assert core.rx_error_count == 1


def test_command_applies_and_clamps() -> None:
    core = ready()
    (st,) = core.receive(c.Packet(2, c.Command(50_000, (12_000, 4_000))), 0.01)
    assert isinstance(st, c.Status)
    assert core.outputs == AppliedOutputs(20_000, (10_000, 4_000))
    assert (st.velocity_um_s, st.heater_duty_permyriad) == (20_000, (10_000, 4_000))
    assert st.faults == {"VELOCITY_CLAMPED", "DUTY_CLAMPED"}
    (st,) = core.receive(c.Packet(3, c.Command(-20_000, (0, 10_000))), 0.02)
    assert isinstance(st, c.Status)
    assert st.fault_flags == 0
    assert core.outputs == AppliedOutputs(-20_000, (0, 10_000))
    core.receive(c.Packet(4, c.SetMotorVelocity(-30_000)), 0.03)
    assert core.outputs == AppliedOutputs(-20_000, (0, 10_000))
    assert core.fault_flags == c.FaultFlag.VELOCITY_CLAMPED
    core.receive(c.Packet(5, c.SetHeaterDuty((7, 8))), 0.04)
    assert core.outputs == AppliedOutputs(-20_000, (7, 8))


def test_commands_while_disabled_are_refused_with_faults() -> None:
    core = McuCore()
    core.receive(c.Packet(0, c.Hello()), 0.0)
    (err,) = core.receive(c.Packet(1, c.SetHeaterDuty((1, 1))), 0.0)
    assert err == c.ErrorReply(1, c.ErrorCode.NOT_ENABLED, 0x03, int(c.FaultFlag.RESET))
    assert core.outputs == AppliedOutputs()


@pytest.mark.parametrize("period_ms", [200, 20, 2000])
def test_watchdog_trips_at_its_period_and_not_before(period_ms: int) -> None:
    core = ready(0.9)
    if period_ms != 200:
        core.receive(c.Packet(2, c.SetWatchdog(period_ms)), 0.99)
    core.receive(c.Packet(3, c.Command(5_000, (5_000, 5_000))), 1.0)
    just_before = 1.0 + period_ms / 1000 - 1e-6
    assert core.tick(just_before) == []
    assert core.outputs == AppliedOutputs(5_000, (5_000, 5_000))
    (st,) = core.tick(1.0 + period_ms / 1000)
    assert isinstance(st, c.Status)
    assert st.unsolicited
    assert not st.enabled
    assert st.faults == {"WATCHDOG"}
    assert (st.velocity_um_s, st.heater_duty_permyriad, st.ack_seq) == (0, (0, 0), 3)
    assert core.outputs == AppliedOutputs()
    assert core.tick(5.0) == []  # trips once


def test_watchdog_fed_by_commands_not_by_status_requests() -> None:
    core = ready()
    for k in range(30):  # 30 ticks of 33 ms: ~1 s, never tripped
        core.receive(c.Packet(2 + k, c.Command(1_000, (0, 0))), 0.033 * (k + 1))
    assert core.enabled
    t = 0.033 * 30
    core.receive(c.Packet(40, c.GetStatus()), t + 0.1)
    replies = core.receive(c.Packet(41, c.GetStatus()), t + 0.2)
    assert [type(r) for r in replies] == [c.Status, c.Status]
    assert isinstance(replies[0], c.Status)
    assert replies[0].unsolicited
    assert core.fault_flags & c.FaultFlag.WATCHDOG


def test_late_command_after_expiry_is_refused() -> None:
    core = ready()
    replies = core.receive(c.Packet(2, c.Command(1, (0, 0))), 0.25)
    assert isinstance(replies[0], c.Status)
    assert replies[0].unsolicited
    assert replies[1] == c.ErrorReply(2, c.ErrorCode.NOT_ENABLED, 0x06, 1)
    (st,) = core.receive(c.Packet(3, c.SetEnable(True)), 0.26)
    assert isinstance(st, c.Status)
    assert st.enabled
    assert st.fault_flags == 0


def test_watchdog_not_armed_while_disabled() -> None:
    core = McuCore()
    core.receive(c.Packet(0, c.Hello()), 0.0)
    assert core.tick(10.0) == []
    assert not core.fault_flags & c.FaultFlag.WATCHDOG


@pytest.mark.parametrize("period_ms", [0, 19, 2001, 65535])
def test_watchdog_period_out_of_range(period_ms: int) -> None:
    core = ready()
    (err,) = core.receive(c.Packet(2, c.SetWatchdog(period_ms)), 0.0)
    assert err == c.ErrorReply(2, c.ErrorCode.VALUE_OUT_OF_RANGE, 0x05, period_ms)
    assert core.watchdog_ms == 200


def test_sequence_duplicate_gap_stale_and_wrap() -> None:
    core = McuCore()
    core.receive(c.Packet(65_534, c.Hello()), 0.0)
    core.receive(c.Packet(65_535, c.SetEnable(True)), 0.0)
    core.receive(c.Packet(0, c.Command(1_000, (0, 0))), 0.01)  # wrap 65535 -> 0
    assert core.rx_gap_count == 0
    (st,) = core.receive(c.Packet(0, c.Command(9_000, (0, 0))), 0.02)  # duplicate
    assert isinstance(st, c.Status)
    assert st.ack_seq == 0
    assert core.outputs.velocity_um_s == 1_000  # not applied twice
    core.receive(c.Packet(4, c.Command(2_000, (0, 0))), 0.03)  # 1, 2, 3 lost
    assert core.rx_gap_count == 3
    assert core.outputs.velocity_um_s == 2_000
    (err,) = core.receive(c.Packet(2, c.Command(3_000, (0, 0))), 0.04)  # from the past
    assert err == c.ErrorReply(2, c.ErrorCode.STALE_SEQUENCE, 0x06, 4)
    assert core.outputs.velocity_um_s == 2_000


def test_frame_errors_become_error_replies() -> None:
    core = ready()
    bad = c.FrameError(c.ErrorCode.BAD_CRC, "CRC mismatch", b"\x01")
    (err,) = core.receive(bad, 0.0)
    assert err == c.ErrorReply(0, c.ErrorCode.BAD_CRC, 0, 0)
    wrong = c.FrameError(c.ErrorCode.WRONG_VERSION, "v2", b"", 2, 0x01, 9, 2)
    (err,) = core.receive(wrong, 0.0)
    assert err == c.ErrorReply(9, c.ErrorCode.WRONG_VERSION, 0x01, 2)
    (err,) = core.receive(c.Packet(3, c.Status(0, 0, 0, 0, (0, 0), 0, 0)), 0.0)
    assert err == c.ErrorReply(3, c.ErrorCode.UNKNOWN_TYPE, 0x82, 0x82)
    assert core.rx_error_count == 3
    assert core.enabled  # errors do not change the outputs


def test_hardware_fault_stops_outputs_until_enable() -> None:
    core = ready()
    core.receive(c.Packet(2, c.Command(1_000, (10_000, 10_000))), 0.0)
    (st,) = core.raise_fault(c.FaultFlag.OVERTEMP, 0.01)
    assert isinstance(st, c.Status)
    assert st.faults == {"OVERTEMP"}
    assert not st.enabled
    assert core.outputs == AppliedOutputs()
    core.receive(c.Packet(3, c.SetEnable(True)), 0.02)
    assert core.enabled
    assert core.outputs == AppliedOutputs()


def test_disable_and_hello_switch_outputs_off() -> None:
    core = ready()
    core.receive(c.Packet(2, c.Command(1_000, (5, 5))), 0.0)
    core.receive(c.Packet(3, c.SetEnable(False)), 0.0)
    assert core.outputs == AppliedOutputs()
    assert not core.enabled
    core.receive(c.Packet(4, c.SetEnable(True)), 0.0)
    core.receive(c.Packet(5, c.Command(1_000, (5, 5))), 0.0)
    core.receive(c.Packet(6, c.SetWatchdog(500)), 0.0)
    core.receive(c.Packet(100, c.Hello()), 0.0)
    assert core.outputs == AppliedOutputs()
    assert not core.enabled
    assert core.watchdog_ms == 200


def test_time_wraps_at_32_bits() -> None:
    core = McuCore(start_s=10.0)
    core.receive(c.Packet(0, c.Hello()), 10.0)
    (st,) = core.receive(c.Packet(1, c.GetStatus()), 10.0 + 2**32 / 1e6 + 0.5)
    assert isinstance(st, c.Status)
    assert st.mcu_time_us == 500_000


def test_config_validation() -> None:
    with pytest.raises(InputError, match=r"max_velocity_um_s must be > 0"):
        McuConfig(max_velocity_um_s=0)
    with pytest.raises(InputError, match=r"watchdog_default_ms 5 is outside 20\.\.2000"):
        McuConfig(watchdog_default_ms=5)
    with pytest.raises(InputError, match=r"protocol_minor 2 is outside 0\.\.1"):
        McuConfig(protocol_minor=2)
    with pytest.raises(InputError, match=r"heater_duty_limit_permyriad 10001 is outside"):
        McuConfig(heater_duty_limit_permyriad=10_001)


def test_minor_1_session_reports_the_load_cell_and_clamps_to_the_duty_limit() -> None:
    core = McuCore(McuConfig(load_cell=True, heater_duty_limit_permyriad=6_000))
    (ack,) = core.receive(c.Packet(0, c.Hello(1)), 0.0)
    assert ack == c.HelloAck(0, 200, 20_000, "relaxgrip-emu 1", 1, 1, 6_000)
    (st,) = core.receive(c.Packet(1, c.SetEnable(True)), 0.0)
    assert isinstance(st, c.Status)
    assert (st.load_cell_counts, st.load_cell_time_us, st.load_cell_samples) == (0, 0, 0)
    assert not st.state_flags & c.StateFlag.LOAD_CELL
    core.load_cell_conversion(1 << 24, 0.1)  # saturates at the 24-bit maximum
    (st,) = core.receive(c.Packet(2, c.Command(0, (7_000, 6_000))), 0.15)
    assert isinstance(st, c.Status)
    assert (st.load_cell_counts, st.load_cell_time_us, st.load_cell_samples) == (
        (1 << 23) - 1, 100_000, 1)
    assert st.state_flags & c.StateFlag.LOAD_CELL
    assert st.heater_duty_permyriad == (6_000, 6_000)
    assert st.faults == {"DUTY_CLAMPED"}
    core.receive(c.Packet(3, c.Command(0, (6_000, 0))), 0.3)
    core.receive(c.Packet(4, c.Command(0, (6_000, 0))), 0.45)
    (st,) = core.receive(c.Packet(5, c.Command(0, (6_000, 0))), 0.6)
    assert isinstance(st, c.Status)
    assert st.fault_flags == 0
    assert not st.state_flags & c.StateFlag.LOAD_CELL  # no conversion for 500 ms


def test_a_minor_0_mcu_refuses_the_minor_1_hello_by_its_length() -> None:
    from relaxgrip.clock import VirtualClock
    from relaxgrip.hardware.protocol.mcu import McuEndpoint
    from relaxgrip.hardware.protocol.transport import MemoryLink

    clock = VirtualClock()
    link = MemoryLink(clock)
    mcu = McuEndpoint(link.device, clock, McuCore(McuConfig(protocol_minor=0)))
    link.host.write(c.encode_frame(c.Hello(1), 7))
    mcu.poll()
    (reply,) = c.FrameDecoder().feed(link.host.read(0.0))
    assert isinstance(reply, c.Packet)
    assert reply.message == c.ErrorReply(7, c.ErrorCode.WRONG_LENGTH, 0x01, 1)


def test_ideal_plant_integrates_velocity() -> None:
    plant = IdealMotorPlant()
    plant.apply(AppliedOutputs(2_000, (0, 0)), 0.0)
    assert plant.encoder_position_um(0.5) == 1_000
    plant.apply(AppliedOutputs(-4_000, (0, 0)), 1.0)
    assert plant.encoder_position_um(1.25) == 1_000
