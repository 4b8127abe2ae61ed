"""SerialGripper faults: each is noticed within 100 ms of virtual time, outputs are stopped,
and a one-line error names what happened."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from relaxgrip.backend import Command
from relaxgrip.clock import VirtualClock
from relaxgrip.hardware.emulator import open_emulated_gripper
from relaxgrip.hardware.frame_channel import KIND_RGB
from relaxgrip.hardware.gripper import GripperFaultError, fault_names
from relaxgrip.hardware.protocol import McuConfig
from relaxgrip.hardware.protocol.codec import FaultFlag

DT = 1 / 30


class Bench:
    """An emulated gripper running a hot, moving command at 30 Hz."""

    def __init__(self, mcu: McuConfig | None = None) -> None:
        self.clock = VirtualClock()
        self.gripper, self.emu = open_emulated_gripper(seed=0, clock=self.clock, mcu=mcu,
                                                       grace_s=0.5)

    def run(self, ticks: int) -> None:
        for _ in range(ticks):
            self.gripper.observe()
            self.gripper.act(Command(motor_velocity_mm_s=3.0, heater_duty=(0.6, 0.6)))
            self.clock.advance(DT)

    def fault_after(self) -> tuple[str, float]:
        """Keep ticking until the gripper fails; (message, detection delay since now)."""
        t_fault = self.clock.now()
        with pytest.raises(GripperFaultError) as info:
            self.run(100)
        assert self.gripper.fault_time_s is not None
        return str(info.value), self.gripper.fault_time_s - t_fault

    def outputs_off_within_watchdog(self) -> None:
        """Whatever the host could send, the MCU has stopped the outputs 200 ms later."""
        self.clock.advance(0.25)
        core = self.emu.endpoint.core
        core.tick(self.clock.now())
        assert core.outputs.velocity_um_s == 0
        assert core.outputs.heater_duty_permyriad == (0, 0)

    def close(self) -> None:
        self.gripper.close()
        self.emu.stop()


@pytest.fixture
def bench() -> Iterator[Bench]:
    b = Bench()
    b.gripper.reset()
    b.run(5)
    yield b
    b.close()


def _one_line(message: str) -> None:
    assert "\n" not in message
    assert message.startswith("gripper stopped: ")


def test_corrupted_bytes(bench: Bench) -> None:
    def flip(data: bytes) -> bytes:
        return data[:3] + bytes([data[3] ^ 0x55]) + data[4:] if len(data) > 4 else data

    bench.emu.tamper_tx = flip
    message, delay_s = bench.fault_after()
    _one_line(message)
    assert "corrupted frame(s) received" in message
    assert delay_s <= 0.1 + 1e-9
    # The MCU still reads the host: the zero command reached it.
    assert bench.emu.endpoint.core.outputs.heater_duty_permyriad == (0, 0)
    assert bench.emu.endpoint.core.outputs.velocity_um_s == 0
    # The run loop's final all-stop after a fault does not raise; anything else does.
    bench.gripper.act(Command())
    with pytest.raises(GripperFaultError, match="stopped earlier"):
        bench.gripper.act(Command(motor_velocity_mm_s=1.0))


def test_truncated_frame(bench: Bench) -> None:
    bench.emu.tamper_tx = lambda data: data[: len(data) // 2]
    message, delay_s = bench.fault_after()
    _one_line(message)
    assert "bytes of a truncated frame pending" in message
    assert delay_s <= 0.1 + 1e-9
    bench.outputs_off_within_watchdog()


def test_a_cable_cut_with_the_mcu_powered_trips_its_watchdog(bench: Bench) -> None:
    """The MCU runs on behind a cut cable: its watchdog, not a stopped emulator, switches the
    last command (3 mm/s, duty 0.6) off, 200 ms after the last command it got."""
    plant = bench.emu.plant
    last_command_s = bench.clock.now() - DT  # the bench's last act, one period ago
    bench.emu.disconnect()
    message, delay_s = bench.fault_after()
    _one_line(message)
    assert "MCU link fault" in message
    assert "MCU watchdog stops the motor and heaters within 200 ms" in message
    assert delay_s <= 0.1 + 1e-9
    # The host gave up; the MCU has not: step its clock in 1 ms and let it poll each time.
    t_end = last_command_s + 0.3
    while bench.clock.now() < t_end:
        bench.clock.advance(0.001)
        assert plant.wait_applied(bench.clock.now()), "the emulated MCU stopped running"
    assert bench.emu.error is None
    assert bench.emu.endpoint.core.fault_flags & FaultFlag.WATCHDOG
    off_s, off = plant.output_log[-1]
    assert off.velocity_um_s == 0
    assert off.heater_duty_permyriad == (0, 0)
    before = [o for t, o in plant.output_log if t < off_s]
    assert before[-1].velocity_um_s == 3000  # what it drove until the watchdog tripped
    assert 0.2 - 1e-9 <= off_s - last_command_s <= 0.2 + 0.002 + 1e-9


def test_stalled_camera(bench: Bench) -> None:
    bench.emu.publisher.muted.add(KIND_RGB)
    last_frame_s = bench.clock.now() - DT  # the last frame published before the mute
    message, _ = bench.fault_after()
    _one_line(message)
    assert "RGB camera stalled: no new frame for" in message
    assert "zero command acknowledged" in message
    assert bench.gripper.fault_time_s is not None
    over_limit_s = bench.gripper.fault_time_s - last_frame_s - 0.2
    assert 0.0 < over_limit_s <= 0.1  # noticed within 100 ms of passing the 200 ms limit
    assert bench.emu.endpoint.core.outputs.heater_duty_permyriad == (0, 0)


def test_wrong_protocol_version() -> None:
    b = Bench(McuConfig(protocol_version=2))
    try:
        t0 = b.clock.now()
        with pytest.raises(GripperFaultError) as info:
            b.gripper.reset()
        message = str(info.value)
        _one_line(message)
        assert "wrong protocol version: MCU speaks protocol version 2, this host speaks " \
               "version 1" in message
        assert b.gripper.fault_time_s is not None
        assert b.gripper.fault_time_s - t0 <= 0.1
        assert not b.emu.endpoint.core.enabled  # never enabled: nothing was ever on
    finally:
        b.close()


def test_mcu_fault_is_reported_and_host_limits_apply(bench: Bench) -> None:
    bench.gripper.act(Command(motor_velocity_mm_s=500.0, heater_duty=(0.6, 0.6)))
    assert bench.emu.endpoint.core.outputs.velocity_um_s == 20_000  # clamped by the host
    bench.emu.endpoint.core.raise_fault(FaultFlag.MOTOR_DRIVER, bench.clock.now())
    bench.clock.advance(DT)
    with pytest.raises(GripperFaultError,
                       match=r"the MCU stopped its outputs itself \(MOTOR_DRIVER\)"):
        bench.gripper.observe()
    with pytest.raises(GripperFaultError, match="stopped earlier"):
        bench.gripper.act(Command(motor_velocity_mm_s=1.0))
    assert fault_names(int(FaultFlag.RESET) | (1 << 9)) == {"RESET", "BIT9"}


def test_a_reset_that_fails_on_the_thermal_camera_releases_the_rgb_one() -> None:
    """Cameras open once (a streaming V4L2 device refuses a second opener): a reset that
    fails on the second camera closes the first, so that the retry can open both."""
    import time
    from pathlib import Path
    from typing import Any

    import numpy as np

    from relaxgrip.hardware.cameras import OpenCvRgbSource, UvcThermalSource
    from relaxgrip.hardware.gripper import SerialGripper
    from relaxgrip.hardware.protocol import McuClient, McuEndpoint, MemoryLink
    from relaxgrip.hardware.rig_file import load_rig

    rig = load_rig(Path(__file__).resolve().parents[2] / "docs" / "rigs" / "relaxgrip.toml")
    busy: set[int | str] = set()
    plugged = {rig.rgb.device}
    caps: list[Any] = []

    class ExclusiveCapture:
        def __init__(self, device: int | str) -> None:
            self.device = device
            self.opened = device in plugged and device not in busy
            if self.opened:
                busy.add(device)
            caps.append(self)

        def isOpened(self) -> bool:
            return self.opened

        def set(self, prop: int, value: float) -> bool:
            return True

        def read(self) -> tuple[bool, np.ndarray[Any, Any]]:
            time.sleep(0.002)
            if self.device == rig.rgb.device:
                return True, np.zeros((480, 640, 3), np.uint8)
            return True, np.full((192, 256), 30_000, np.uint16)

        def release(self) -> None:
            if self.opened:
                busy.discard(self.device)
                self.opened = False

    clock = VirtualClock()
    link = MemoryLink(clock)
    mcu = McuEndpoint(link.device, clock)
    link.host.set_service(mcu.poll)
    rgb = OpenCvRgbSource(rig.rgb, clock, capture_factory=ExclusiveCapture)
    ir = UvcThermalSource(rig.ir, clock, capture_factory=ExclusiveCapture)
    gripper = SerialGripper(McuClient(link.host, clock), rgb, ir, limits=rig.limits)
    try:
        with pytest.raises(GripperFaultError, match="cannot open thermal camera"):
            gripper.reset()
        assert busy == set()  # the RGB camera was closed, its reader stopped
        assert rgb._thread is None
        plugged.add(rig.ir.device)  # the thermal camera is plugged in; the lab retries
        gripper.reset()
        assert busy == {rig.rgb.device, rig.ir.device}
        assert [c.device for c in caps] == [rig.rgb.device, rig.ir.device] * 2
    finally:
        gripper.close()
    assert busy == set()


@pytest.mark.parametrize("boot_wait_s", [0.0, 2.5])
def test_reset_says_hello_again_while_the_mcu_boots(boot_wait_s: float) -> None:
    """Opening a USB-serial port resets an Arduino-class MCU (DTR): its bootloader is
    silent for a second or two, and one Hello within 100 ms went unanswered."""
    clock = VirtualClock()
    gripper, emu = open_emulated_gripper(seed=0, clock=clock, grace_s=0.02)
    gripper.boot_wait_s = boot_wait_s
    emu.tamper_tx = lambda data: data if clock.now() >= 1.0 else b""  # booting until 1 s
    try:
        if boot_wait_s == 0.0:
            with pytest.raises(GripperFaultError, match="no reply from the MCU to Hello"):
                gripper.reset()
        else:
            gripper.reset()
            assert 1.0 <= clock.now() < 1.3
            assert gripper.client.hello_ack is not None
    finally:
        gripper.close()
        emu.stop()


def test_an_mcu_that_never_boots_is_named_after_the_wait() -> None:
    clock = VirtualClock()
    gripper, emu = open_emulated_gripper(seed=0, clock=clock, grace_s=0.02)
    gripper.boot_wait_s = 0.5
    emu.tamper_tx = lambda data: b""
    try:
        with pytest.raises(GripperFaultError) as info:
            gripper.reset()
        _one_line(str(info.value))
        assert "(Hello said for 0.5 s: the MCU did not boot)" in str(info.value)
    finally:
        gripper.close()
        emu.stop()


def test_an_mcu_whose_velocity_limit_is_above_the_rig_s_is_never_enabled() -> None:
    b = Bench(McuConfig(max_velocity_um_s=50_000))
    try:
        with pytest.raises(GripperFaultError) as info:
            b.gripper.reset()
        message = str(info.value)
        _one_line(message)
        assert ("the MCU's velocity limit 50 mm/s is above the rig's [limits] "
                "max_motor_speed_mm_s 20 mm/s") in message
        assert not b.emu.endpoint.core.enabled
    finally:
        b.close()
