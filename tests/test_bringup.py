"""``relaxgrip bringup``: its plan sized for the rig, and a directory that is another rig's."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from relaxgrip.bringup import STATE_NAME, Bringup
from relaxgrip.experiments.bringup import MAX_CALIBRATION_HOLDS, plan_for_rig
from relaxgrip.hardware.rig_file import load_rig
from tests.clitools import run_main

RIGS = Path(__file__).resolve().parents[1] / "docs" / "rigs"


def test_the_plan_spans_the_rig_s_forces_temperatures_and_positions() -> None:
    rig = load_rig(RIGS / "lab-125mm.toml")
    plan = plan_for_rig(rig, takes=24, hold_s=60.0, seed=3)
    forces = sorted(t.force_n for t in plan.data)
    assert forces[0] >= 1.0
    assert forces[-1] <= min(8.0, 0.8 * rig.limits.max_target_n)
    assert len({t.temp_c for t in plan.data}) >= 3
    assert len({t.contact_mm for t in plan.data}) == 3
    assert all(rig.limits.min_setpoint_c <= t.temp_c <= rig.limits.max_setpoint_c
               for t in plan.data)
    assert len(plan.calibration) <= MAX_CALIBRATION_HOLDS
    assert plan_for_rig(rig, takes=24, hold_s=60.0, seed=3) == plan  # seeded


def test_a_directory_of_another_rig_is_refused_and_left_as_it_was(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bringup"
    Bringup(RIGS / "lab-125mm.toml", out, takes=4, hold_s=20.0, calibration_holds=4)
    before = (out / STATE_NAME).read_text(encoding="utf-8")
    code, _, err = run_main(["bringup", RIGS / "relaxgrip.toml", "--out", out, "--takes", "4"],
                            monkeypatch, capsys)
    assert code == 2
    assert err.count("error:") == 1
    assert "is the bring-up of rig 'lab gripper, 125 mm finger'" in err
    assert (out / STATE_NAME).read_text(encoding="utf-8") == before
    assert json.loads(before)["done"] == []
    code, _, err = run_main(["bringup", RIGS / "lab-125mm.toml", "--out", out, "--takes", "5"],
                            monkeypatch, capsys)
    assert code == 2
    assert "was started with other settings" in err
