"""The MCU's load cell as the host's force reference: Status -> ForceSamples, tare, checks."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from relaxgrip.backend import Command
from relaxgrip.clock import VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.hardware.emulator import open_emulated_gripper
from relaxgrip.hardware.force_ref import ForceReference, LinearCalibration, McuLoadCell
from relaxgrip.hardware.protocol import McuClient, McuConfig, McuCore, McuEndpoint, MemoryLink
from relaxgrip.hardware.protocol import codec as c


def _client(config: McuConfig) -> tuple[McuClient, McuEndpoint, VirtualClock]:
    clock = VirtualClock()
    link = MemoryLink(clock)
    mcu = McuEndpoint(link.device, clock, McuCore(config))
    link.host.set_service(mcu.poll)
    return McuClient(link.host, clock), mcu, clock


def test_conversions_reach_the_host_once_each_on_its_clock() -> None:
    client, mcu, clock = _client(McuConfig(load_cell=True))
    cell = McuLoadCell(client, LinearCalibration(1e-5, 1000.0))
    assert isinstance(cell, ForceReference)
    client.handshake()
    cell.start()
    client.set_enabled(True)
    mcu.core.load_cell_conversion(201_000, 0.0)
    clock.advance(0.05)
    client.request_status()
    client.command(0.0, (0.0, 0.0))  # the same conversion again: not a new reading
    got = cell.read(clock.now())
    assert got is not None
    np.testing.assert_allclose(got.force_n, [2.0])
    np.testing.assert_allclose(got.t_s, [0.0], atol=1e-9)  # stamped when the MCU read it
    assert cell.read(clock.now()) is None
    for k in (1, 2, 3):  # two conversions between Status frames: one is missed
        mcu.core.load_cell_conversion(1000 + 100_000 * k, 0.05 + 0.01 * k)
    clock.advance(0.05)
    client.command(0.0, (0.0, 0.0))
    got = cell.read(clock.now())
    assert got is not None
    np.testing.assert_allclose(got.force_n, [3.0])
    assert (cell.conversions, cell.conversions_missed) == (2, 2)
    cell.shift_zero(3.0)
    assert cell.calibration.force_n(301_000) == pytest.approx(0.0)
    cell.close()
    assert client.status_listeners == []


@pytest.mark.parametrize(("config", "minor", "words"), [
    (McuConfig(load_cell=False), 1, "was built without one: build it with LOAD_CELL=1"),
    (McuConfig(load_cell=True, protocol_minor=0), 1, "speaks protocol minor 0"),
    (McuConfig(load_cell=True), 0, "speaks protocol minor 0"),
])
def test_a_load_cell_the_mcu_does_not_report_is_one_clear_error(
        config: McuConfig, minor: int, words: str) -> None:
    client, _, _ = _client(config)
    client.protocol_minor = minor
    client.decoder = c.FrameDecoder(minor=minor)
    client.handshake()
    with pytest.raises(InputError, match=words) as info:
        McuLoadCell(client, LinearCalibration(1e-5)).start()
    assert "\n" not in str(info.value)


def test_bad_calibrations_are_refused() -> None:
    with pytest.raises(InputError, match="scale_n_per_count must be a finite non-zero"):
        LinearCalibration(0.0)
    with pytest.raises(InputError, match="offset_counts must be finite"):
        LinearCalibration(1e-5, float("nan"))


def test_the_emulator_s_force_ref_is_its_load_cell_reading_the_ball() -> None:
    """Recordings carry the load cell's readings, not the twin's truth feed: they follow
    the contact force within the HX711's noise and its 100 ms averaging."""
    clock = VirtualClock()
    gripper, _ = open_emulated_gripper(seed=2, clock=clock, grace_s=1.0)
    try:
        gripper.reset()
        assert gripper.info.version.startswith("protocol 1.1;")
        times, refs, truths = [], [], []
        for _ in range(150):  # 5 s: close onto the ball, then hold still
            obs = gripper.observe()
            assert obs.truth is not None
            truths.append((obs.t_s, obs.truth.contact_force_n))
            if obs.force_ref is not None:
                times += list(obs.force_ref.t_s)
                refs += list(obs.force_ref.force_n)
            v = 6.0 if obs.truth.contact_force_n < 3.0 else 0.0
            gripper.act(Command(motor_velocity_mm_s=v))
            clock.advance(1 / 30)
        t_true, f_true = np.array(truths).T
        t_ref, f_ref = np.array(times), np.array(refs)
        assert len(t_ref) == pytest.approx(50, abs=2)  # 10 SPS over 5 s
        assert np.all(np.diff(t_ref) > 0.09)
        still = t_ref > t_true[np.argmax(f_true > 2.9)] + 0.5
        assert still.sum() > 20
        np.testing.assert_allclose(f_ref[still], np.interp(t_ref[still], t_true, f_true),
                                   atol=0.01)
        assert np.abs(f_ref[t_ref < 0.5]).max() < 0.005  # calibrated zero, open fingers
    finally:
        gripper.close()


def test_tare_zeroes_a_wrong_offset_with_nothing_on_the_cell() -> None:
    clock = VirtualClock()
    gripper, emu = open_emulated_gripper(seed=5, clock=clock, grace_s=1.0)
    try:
        gripper.reset()
        cell = gripper.force_ref
        assert isinstance(cell, McuLoadCell)
        cell.calibration = dataclasses.replace(cell.calibration,
                                               offset_counts=cell.calibration.offset_counts
                                               - 50_000)
        taken = gripper.tare_force_ref(duration_s=0.6)
        assert taken == pytest.approx(50_000 * cell.calibration.scale_n_per_count, abs=0.002)
        after = []
        for _ in range(20):
            gripper.act(Command())
            clock.advance(1 / 30)
            obs = gripper.observe()
            if obs.force_ref is not None:
                after += list(obs.force_ref.force_n)
        assert len(after) >= 5
        assert np.abs(after).max() < 0.002
        assert emu.endpoint.core.enabled  # the tare's zero Commands kept the watchdog fed
        with pytest.raises(InputError, match=r"tare duration_s must be 0\.1\.\.10 s"):
            gripper.tare_force_ref(duration_s=20.0)
    finally:
        gripper.close()


def test_a_recording_on_the_emulator_carries_the_load_cell_as_force_ref(tmp_path) -> None:
    """/relaxgrip/force_ref holds the MCU's load-cell conversions (10 per second, on the
    host's clock), not the twin's truth feed."""
    from relaxgrip.experiments.controlled_hold import run_hold
    from relaxgrip.recording import McapRecorder
    from relaxgrip.recording.reader import iter_messages

    path = tmp_path / "hold.mcap"
    with McapRecorder(path) as recorder:
        run_hold("relax", 5.0, 2.0, 40.0, seed=4, backend="emulator", recorder=recorder)
    t = [v for topic, _, msg in iter_messages(path) if topic == "/relaxgrip/force_ref"
         for v in msg["t_s"]]
    f = [v for topic, _, msg in iter_messages(path) if topic == "/relaxgrip/force_ref"
         for v in msg["force_n"]]
    assert len(t) > 100
    np.testing.assert_allclose(np.diff(t), 0.1, atol=1e-6)
    assert max(f) > 4.0  # the ball held near the 5 N target
