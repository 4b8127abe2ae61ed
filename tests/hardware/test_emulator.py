"""The MCU emulator: the twin behind a real pty, in lockstep virtual time and in wall-clock time."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.backend import Command, check_backend
from relaxgrip.clock import VirtualClock, WallClock
from relaxgrip.experiments.controlled_hold import run_hold
from relaxgrip.hardware.emulator import McuEmulator, open_emulated_gripper
from relaxgrip.hardware.gripper import SerialGripper
from relaxgrip.hardware.protocol.codec import FaultFlag
from relaxgrip.hardware.rig_file import load_rig
from relaxgrip.perception.rig_check import check_rig
from relaxgrip.twin import GripperTwin, TwinConfig
from tests.rigs import RIGS, twin_of

DOCS = Path(__file__).resolve().parents[2] / "docs"


@pytest.fixture(params=RIGS)
def emulated(request: pytest.FixtureRequest
             ) -> Iterator[tuple[SerialGripper, McuEmulator, VirtualClock]]:
    """The twin of each example rig behind the emulator."""
    clock = VirtualClock()
    gripper, emu = open_emulated_gripper(twin_of(request.param), seed=3, clock=clock,
                                         grace_s=1.0)
    yield gripper, emu, clock
    gripper.close()
    emu.stop()


def test_serial_gripper_on_the_emulator_passes_check_backend(
        emulated: tuple[SerialGripper, McuEmulator, VirtualClock]) -> None:
    gripper, emu, clock = emulated
    check_backend(gripper, clock.advance, seconds=1.0)
    assert gripper.info.name == "emulator"
    assert gripper.info.has_truth
    assert emu.error is None
    assert emu.endpoint.core.outputs.velocity_um_s == 0  # close() stopped and disabled it
    assert not emu.endpoint.core.enabled


def test_lockstep_sees_exactly_what_the_twin_sees(
        emulated: tuple[SerialGripper, McuEmulator, VirtualClock]) -> None:
    gripper, emu, clock = emulated
    twin_clock = VirtualClock()
    twin = GripperTwin(emu.config, seed=3, clock=twin_clock)
    obs_e, obs_t = gripper.reset(), twin.observe()
    for k in range(45):  # 1.5 s at 30 Hz: 45 RGB frames and two IR frames
        cmd = Command(motor_velocity_mm_s=8.0 if k < 30 else -4.0, heater_duty=(0.25, 0.5))
        gripper.act(cmd)
        twin.act(cmd)
        clock.advance(1 / 30)
        twin_clock.advance(1 / 30)
        obs_e, obs_t = gripper.observe(), twin.observe()
        assert obs_e.t_s == obs_t.t_s
        assert obs_e.motor_position_mm == pytest.approx(obs_t.motor_position_mm, abs=1e-9)
        assert obs_e.heater_duty == obs_t.heater_duty
        assert obs_e.rgb is not None
        assert obs_t.rgb is not None
        assert (obs_e.rgb.seq, obs_e.rgb.t_s) == (obs_t.rgb.seq, obs_t.rgb.t_s)
        assert np.array_equal(obs_e.rgb.image, obs_t.rgb.image)
        assert obs_e.ir is not None
        assert obs_t.ir is not None
        assert np.array_equal(obs_e.ir.image, obs_t.ir.image)
        assert obs_e.truth == obs_t.truth
    assert obs_e.ir is not None
    assert obs_e.ir.seq == 1


def test_mcu_watchdog_stops_twin_when_the_host_goes_quiet(
        emulated: tuple[SerialGripper, McuEmulator, VirtualClock]) -> None:
    gripper, emu, clock = emulated
    gripper.reset()
    gripper.act(Command(motor_velocity_mm_s=5.0, heater_duty=(1.0, 1.0)))
    assert emu.endpoint.core.outputs.heater_duty_permyriad == (10000, 10000)
    clock.advance(0.19)
    gripper.observe()  # a GetStatus does not feed the watchdog
    assert emu.endpoint.core.enabled
    clock.advance(0.02)
    status = gripper.client.request_status()  # the watchdog tripped first: unsolicited status
    assert status.fault_flags & FaultFlag.WATCHDOG
    assert emu.endpoint.core.outputs.heater_duty_permyriad == (0, 0)
    assert emu.twin.observe().heater_duty == (0.0, 0.0)


def test_short_hold_over_the_pty_matches_the_twin() -> None:
    twin = run_hold("relax", 5.0, 12.0, 40.0, seed=1, backend="twin")
    start = time.perf_counter()
    emu = run_hold("relax", 5.0, 12.0, 40.0, seed=1, backend="emulator")
    wall_s = time.perf_counter() - start
    assert emu.loop.backend.name == "emulator"
    a, b = twin.metrics(), emu.metrics()
    # Over the wire the encoder reads in 0.01 mm steps, which moves the RCFN's closure
    # ratio: at the end of this 12 s hold it gave K 0.280 N against the twin's 0.347 N
    # and the MAEs 0.107 / 0.085 N (seed 1, shipped models of 2026-11-25).
    assert abs(a["mae_n"] - b["mae_n"]) < 0.03
    assert abs(a["mean_signed_error_n"] - b["mean_signed_error_n"]) < 0.03
    # The loop decelerates into the target, so an estimate a hundredth of a newton apart
    # (the encoder's quantisation over the wire) moves the onset by a few frames.
    on_twin, on_emu = twin.loop.hold_onset_s(), emu.loop.hold_onset_s()
    assert on_twin is not None
    assert on_emu is not None
    assert abs(on_twin - on_emu) < 0.5
    f_twin = float(np.interp(on_twin, twin.loop["t_s"], twin.loop["truth_force_n"]))
    f_emu = float(np.interp(on_emu, emu.loop["t_s"], emu.loop["truth_force_n"]))
    assert abs(f_twin - f_emu) < 0.05
    n = min(twin.truth_n.size, emu.truth_n.size)
    assert float(np.max(np.abs(twin.truth_n[:n] - emu.truth_n[:n]))) < 0.1
    t_end = float(emu.loop["t_s"][-1])
    assert wall_s < t_end  # virtual time: faster than the hold itself


def test_wall_clock_emulator_serves_check_rig_over_its_socket(tmp_path: Path) -> None:
    rig = load_rig(DOCS / "rig-emulator.toml")
    emu = McuEmulator(TwinConfig(), seed=0, clock=WallClock())
    try:
        sock = str(tmp_path / "frames.sock")
        emu.listen(sock)
        emu.start()
        assert rig.emulator is not None
        spec = dataclasses.replace(
            rig, serial=dataclasses.replace(rig.serial, port=emu.port),
            emulator=dataclasses.replace(rig.emulator, socket=sock))
        found = check_rig(spec)
        # A rig file that names another marker than the finger carries: the loop would
        # never track it, so the check must not find it either.
        other = (spec.marker.marker_id + 7) % 50
        wrong = check_rig(dataclasses.replace(
            spec, marker=dataclasses.replace(spec.marker, marker_id=other)))
    finally:
        emu.stop()
    assert found.firmware_id == "relaxgrip-emu 1"
    assert found.rgb_shape == (480, 640, 3)
    assert found.ir_shape == (192, 256)
    assert found.marker_found
    assert found.marker_ids_seen == [spec.marker.marker_id]
    assert found.marker_offset_mm < 1.0
    assert not wrong.marker_found
    assert wrong.marker_id == other
    assert wrong.marker_ids_seen == [spec.marker.marker_id]
    assert np.isnan(wrong.marker_distance_mm)
    assert 20.0 < found.ir_temp_c[1] < 35.0
    assert not emu.endpoint.core.enabled  # the check never enables the outputs


def test_wall_clock_watchdog_trips_on_time_when_the_frame_host_stops_reading(
        tmp_path: Path) -> None:
    """A host that stops reading the frame channel (suspended, hung) loses frames,
    as from a real camera, but never delays the MCU: its watchdog trips after 200 ms."""
    import socket

    from relaxgrip.hardware.protocol.client import McuClient
    from relaxgrip.hardware.protocol.transport import SerialTransport

    clock = WallClock()
    emu = McuEmulator(TwinConfig(), seed=0, clock=clock)
    host = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    client = None
    try:
        sock = str(tmp_path / "frames.sock")
        emu.listen(sock)
        emu.start()
        host.connect(sock)  # and never reads
        client = McuClient(SerialTransport(emu.port), clock)
        client.handshake()
        client.set_enabled(True)
        for _ in range(20):  # 0.7 s of commands: more frames than the socket holds
            client.command(1.0, (1.0, 1.0))
            time.sleep(1 / 30)
        quiet_from = time.monotonic()
        while emu.endpoint.core.enabled and time.monotonic() - quiet_from < 3.0:
            time.sleep(0.005)
        quiet_s = time.monotonic() - quiet_from
    finally:
        if client is not None:
            client.close()
        emu.stop()
        host.close()
    assert emu.endpoint.core.fault_flags & FaultFlag.WATCHDOG
    assert quiet_s < 0.5
    assert emu.publisher.messages_dropped > 0


def test_stopping_twice_closes_no_descriptor_it_does_not_own(tmp_path: Path) -> None:
    """The fixtures close the gripper (which stops the emulator) and stop it again: the
    second stop must not close a descriptor the system has since given to someone else."""
    import os

    emu = McuEmulator(TwinConfig(), seed=0, clock=VirtualClock())
    slave = emu._pty.slave
    emu.start()
    emu.stop()
    fd = os.open(tmp_path / "log.txt", os.O_WRONLY | os.O_CREAT)
    os.dup2(fd, slave)  # the number the pty's slave had, now someone else's file
    os.close(fd)
    try:
        emu.stop()
        os.write(slave, b"still open\n")
    finally:
        os.close(slave)
    assert (tmp_path / "log.txt").read_text(encoding="utf-8") == "still open\n"


def test_wall_clock_watchdog_trips_when_the_host_stops_reading_the_port() -> None:
    """A host that sends but never reads fills the pty: the emulator drops its answers, as
    a UART overflows, instead of waiting for ever, and its watchdog stops the outputs."""
    from relaxgrip.hardware.protocol.client import McuClient
    from relaxgrip.hardware.protocol.codec import GetStatus, encode_frame
    from relaxgrip.hardware.protocol.transport import SerialTransport

    clock = WallClock()
    emu = McuEmulator(TwinConfig(), seed=0, clock=clock).start()
    port = SerialTransport(emu.port)
    try:
        client = McuClient(port, clock)
        client.handshake()
        client.set_enabled(True)
        client.command(1.0, (1.0, 1.0))
        # From now on only GetStatus (which does not feed the watchdog), answers never read.
        for batch in range(30):
            try:
                port.write(b"".join(encode_frame(GetStatus(), 3 + 100 * batch + k,
                                                 leading_delimiter=True) for k in range(100)))
            except Exception:  # an MCU that stopped reading: the port's write timed out
                break
        core = emu.endpoint.core
        deadline = time.monotonic() + 3.0
        while core.enabled and time.monotonic() < deadline:
            time.sleep(0.01)
        assert core.fault_flags & FaultFlag.WATCHDOG
        assert core.outputs.velocity_um_s == 0
        assert core.outputs.heater_duty_permyriad == (0, 0)
        assert emu.transport.tx_overflows > 0
        assert emu.error is None
    finally:
        port.close()
        emu.stop()


def test_a_second_emulator_is_refused_however_it_names_the_socket(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/emulator.md: the socket belongs to one emulator, whether the second names it
    by a relative path or through a linked folder; its socket is never replaced."""
    import os

    from relaxgrip.errors import InputError

    folder = tmp_path / "d"
    folder.mkdir()
    alias = tmp_path / "alias"
    alias.symlink_to(folder)
    monkeypatch.chdir(folder)
    first = McuEmulator(TwinConfig(), seed=0, clock=WallClock())
    second = McuEmulator(TwinConfig(), seed=0, clock=WallClock())
    try:
        first.listen("f.sock")
        inode = os.stat(folder / "f.sock").st_ino
        for spelling in (folder / "f.sock", alias / "f.sock"):
            with pytest.raises(InputError, match="another emulator is serving it") as info:
                second.listen(str(spelling))
            assert "\n" not in str(info.value)
        assert os.stat(folder / "f.sock").st_ino == inode
        monkeypatch.chdir(tmp_path)  # stopping elsewhere still removes its files
    finally:
        second.stop()
        first.stop()
    assert list(folder.iterdir()) == []
    third = McuEmulator(TwinConfig(), seed=0, clock=WallClock())
    try:
        third.listen(str(alias / "f.sock"))  # free once the first stopped
    finally:
        third.stop()
    assert list(folder.iterdir()) == []
