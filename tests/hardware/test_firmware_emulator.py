"""The emulator with the compiled firmware in simavr as its MCU (``--mcu firmware``)."""

from __future__ import annotations

import json
from collections.abc import Iterator

import numpy as np
import pytest

from relaxgrip.backend import Command
from relaxgrip.clock import VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import check_mcu, run_hold
from relaxgrip.hardware.emulator import McuEmulator, open_emulated_gripper
from relaxgrip.hardware.firmware_emulator import MotorDrive
from relaxgrip.hardware.firmware_sim import toolchain_missing
from relaxgrip.hardware.gripper import SerialGripper
from tests.clitools import run_main

MISSING = toolchain_missing()
needs_toolchain = pytest.mark.skipif(
    bool(MISSING), reason=f"the firmware's toolchain is missing ({', '.join(MISSING)}): "
                          "apt-get install gcc-avr avr-libc simavr libsimavr-dev")


@pytest.fixture
def emulated() -> Iterator[tuple[SerialGripper, McuEmulator, VirtualClock]]:
    clock = VirtualClock()
    gripper, emu = open_emulated_gripper(seed=3, clock=clock, grace_s=2.0, firmware=True)
    yield gripper, emu, clock
    gripper.close()
    emu.stop()


@needs_toolchain
def test_the_firmware_drives_the_twin_and_reads_its_encoder_and_load_cell(
        emulated: tuple[SerialGripper, McuEmulator, VirtualClock]) -> None:
    gripper, emu, clock = emulated
    assert emu.firmware is not None
    with pytest.raises(InputError, match="runs the compiled firmware"):
        _ = emu.endpoint
    obs = gripper.reset()
    assert gripper.info.version.startswith("protocol 1.1; firmware relaxgrip-fw 1.1")
    positions: list[tuple[float, float]] = []
    refs: list[float] = []
    ref_times: list[float] = []
    for _ in range(60):  # 2 s closing at 4 mm/s, heaters at 0.3
        gripper.act(Command(motor_velocity_mm_s=4.0, heater_duty=(0.3, 0.3)))
        clock.advance(1 / 30)
        obs = gripper.observe()
        positions.append((obs.t_s, obs.motor_position_mm))
        if obs.force_ref is not None:
            refs += list(obs.force_ref.force_n)
            ref_times += list(obs.force_ref.t_s)
    t, x = np.array(positions).T
    late = t > 1.0
    assert np.polyfit(t[late], x[late], 1)[0] == pytest.approx(4.0, rel=0.02)
    # The encoder the host reads is the twin's motor, within a count and the link's latency.
    assert obs.motor_position_mm == pytest.approx(emu.twin.motor_position_mm, abs=0.1)
    assert obs.heater_duty == (0.3, 0.3)  # read back from the PWM
    # The HX711 at 10 SPS (each exchange takes the link's few milliseconds of time too).
    assert len(refs) == pytest.approx(obs.t_s * 10, abs=2)
    np.testing.assert_allclose(np.diff(ref_times), 0.1, atol=0.003)
    assert np.abs(refs).max() < 0.005  # the ball not reached yet: nothing on the cell


@needs_toolchain
def test_the_firmware_watchdog_stops_the_twin_when_the_host_goes_quiet(
        emulated: tuple[SerialGripper, McuEmulator, VirtualClock]) -> None:
    gripper, emu, clock = emulated
    gripper.reset()
    gripper.act(Command(motor_velocity_mm_s=5.0, heater_duty=(1.0, 1.0)))
    clock.advance(0.1)
    gripper.observe()  # a GetStatus does not feed the watchdog
    moved = emu.twin.motor_position_mm
    assert moved > 0.1
    clock.advance(0.2)
    status = gripper.client.request_status()
    assert status.fault_flags & 1  # WATCHDOG
    assert not status.enabled
    still = emu.twin.motor_position_mm
    clock.advance(0.5)
    gripper.client.request_status()
    assert emu.twin.motor_position_mm == pytest.approx(still, abs=0.05)
    assert emu.twin.observe().heater_duty == (0.0, 0.0)


@needs_toolchain
def test_a_twin_taken_over_mid_grasp_has_its_travel_counted_by_the_firmware() -> None:
    """The firmware counts the encoder from power-up: a twin whose motor is 60 mm closed
    has that travel turned in during the boot, and the host reads where the motor is; the
    emulator's output log is the firmware's own (its setpoint, its heater pins)."""
    from relaxgrip.twin import GripperTwin

    clock = VirtualClock(5.0)
    twin = GripperTwin(seed=4, clock=VirtualClock(0.0))
    twin.reset()
    for _ in range(150):  # 15 s at 4 mm/s
        twin.act(Command(motor_velocity_mm_s=4.0))
        twin.clock.advance(0.1)  # type: ignore[attr-defined]
        twin.observe()
    clock = VirtualClock(twin.clock.now())
    gripper, emu = open_emulated_gripper(clock=clock, grace_s=2.0, firmware=True, twin=twin)
    try:
        gripper.reset()
        obs = gripper.observe()
        assert obs.motor_position_mm > 50.0
        # Within a few counts: the motor coasts on its lag while the link answers.
        assert obs.motor_position_mm == pytest.approx(twin.motor_position_mm, abs=0.05)
        gripper.act(Command(motor_velocity_mm_s=2.0, heater_duty=(0.5, 0.0)))
        clock.advance(0.1)
        gripper.observe()
        assert emu.wait_applied(clock.now())
        _, moving, duty = emu.outputs()[-1]
        assert moving == 2.0
        assert duty[1] == 0.0
        assert emu.fault_flags == 0
    finally:
        gripper.close()
        emu.stop()


@needs_toolchain
def test_a_short_hold_through_the_firmware_matches_the_twin() -> None:
    """The emulator's criterion: the MAE within max(0.02 N, 50 %) of the twin's, same seed."""
    twin = run_hold("relax", 5.0, 12.0, 40.0, seed=1, backend="twin")
    fw = run_hold("relax", 5.0, 12.0, 40.0, seed=1, backend="emulator", mcu="firmware")
    assert fw.loop.backend.name == "emulator"
    a, b = twin.metrics()["mae_n"], fw.metrics()["mae_n"]
    assert abs(a - b) <= max(0.02, 0.5 * a)
    on_twin, on_fw = twin.loop.hold_onset_s(), fw.loop.hold_onset_s()
    assert on_twin is not None
    assert on_fw is not None
    assert abs(on_twin - on_fw) < 0.5


def test_mcu_choices_are_checked() -> None:
    assert check_mcu("python", "twin") == "python"
    with pytest.raises(InputError, match="--mcu must be python or firmware, got 'avr'"):
        check_mcu("avr", "emulator")
    with pytest.raises(InputError, match="use it with --backend emulator"):
        check_mcu("firmware", "twin")
    with pytest.raises(InputError, match="full_speed_mm_s must be > 0"):
        MotorDrive(0.0)


@pytest.mark.parametrize(("args", "message"), [
    (["--mcu", "firmware"], "--mcu firmware runs the firmware behind the emulator"),
    (["--mcu", "avr", "--backend", "emulator"], "--mcu must be python or firmware"),
    (["--mcu", "firmware", "--backend", "emulator", "--seeds", "1,2"], "give --seed"),
])
def test_bad_mcu_flags_are_one_line_errors(monkeypatch, capsys, args, message) -> None:
    code, out, err = run_main(["hold", *args], monkeypatch, capsys)
    assert code == 2
    assert message in err
    assert err.count("\n") == 1
    assert out == ""


@needs_toolchain
def test_hold_on_the_firmware_from_the_command_line(monkeypatch, capsys) -> None:
    code, out, err = run_main(["hold", "--backend", "emulator", "--mcu", "firmware",
                               "--duration-s", "2", "--seed", "2", "--json"], monkeypatch, capsys)
    assert code == 0, err
    result = json.loads(out)
    assert result["duration_s"] == 2.0
    assert np.isfinite(result["mae_n"])


def test_without_the_toolchain_the_firmware_is_one_clear_error(monkeypatch) -> None:
    import shutil

    from relaxgrip.hardware import firmware_sim

    monkeypatch.setattr(shutil, "which", lambda tool: None)
    with pytest.raises(firmware_sim.FirmwareToolchainError) as info:
        McuEmulator(seed=0, clock=VirtualClock(), firmware=True)
    msg = str(info.value)
    assert msg.startswith("the simulated firmware needs avr-gcc, avr-objcopy")
    assert "apt-get install gcc-avr avr-libc simavr libsimavr-dev" in msg
    assert "\n" not in msg


@needs_toolchain
def test_the_wall_clock_emulator_serves_check_rig_through_the_firmware(tmp_path) -> None:
    import dataclasses
    from pathlib import Path

    from relaxgrip.clock import WallClock
    from relaxgrip.hardware.rig_file import load_rig
    from relaxgrip.perception.rig_check import check_rig
    from relaxgrip.twin import TwinConfig

    rig = load_rig(Path(__file__).resolve().parents[2] / "docs" / "rig-emulator.toml")
    emu = McuEmulator(TwinConfig(), seed=0, clock=WallClock(), firmware=True)
    try:
        sock = str(tmp_path / "frames.sock")
        emu.listen(sock)
        emu.start()
        assert rig.emulator is not None
        spec = dataclasses.replace(
            rig, serial=dataclasses.replace(rig.serial, port=emu.port),
            emulator=dataclasses.replace(rig.emulator, socket=sock))
        found = check_rig(spec)
    finally:
        emu.stop()
    assert emu.error is None
    assert found.firmware_id == "relaxgrip-fw 1.1"
    assert found.marker_found


def test_the_emulator_command_refuses_an_unknown_mcu(monkeypatch, capsys) -> None:
    code, out, err = run_main(["emulator", "--mcu", "avr", "--duration-s", "1"], monkeypatch,
                              capsys)
    assert code == 2
    assert err == "error: --mcu must be python or firmware, got 'avr'\n"
    assert out == ""
