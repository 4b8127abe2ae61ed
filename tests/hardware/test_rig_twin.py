"""The twin of a rig file: ours is the twin's defaults, bit for bit; another is its own gripper."""

from __future__ import annotations

import json
import math
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

from relaxgrip.backend import Command
from relaxgrip.clock import VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.experiments.controlled_hold import run_hold
from relaxgrip.hardware.rig_file import load_rig, parse_rig
from relaxgrip.hardware.rig_twin import load_twin_config, twin_config_for_rig
from relaxgrip.physics.beam import local_stiffness_n_per_m
from relaxgrip.physics.thermal import duty_for_mean_temp
from relaxgrip.twin import GripperTwin, TwinConfig
from tests.clitools import assert_one_error_line, run_main
from tests.rigs import RIG_FILES, RIGS, twin_of


def test_our_rig_file_is_the_twins_default_config() -> None:
    ours, default = load_twin_config(RIG_FILES["ours"]), TwinConfig()
    different = [f.name for f in fields(TwinConfig) if getattr(ours, f.name) != getattr(
        default, f.name)]
    assert different == []
    assert ours == default
    assert load_twin_config(None) == default


def test_a_seeded_hold_on_our_rig_file_is_bit_identical_to_the_default() -> None:
    a = run_hold("relax", 5.0, 3.0, 40.0, seed=5)
    b = run_hold("relax", 5.0, 3.0, 40.0, seed=5, config=load_twin_config(RIG_FILES["ours"]))
    assert a.loop.series.keys() == b.loop.series.keys()
    for name, x in a.loop.series.items():
        y = b.loop.series[name]
        assert np.array_equal(np.asarray(x, np.float64).view(np.uint64),
                              np.asarray(y, np.float64).view(np.uint64)), name
    assert json.dumps(a.to_dict()) == json.dumps(b.to_dict())


def test_the_twin_of_the_second_rig_is_that_gripper() -> None:
    rig = load_rig(RIG_FILES["lab"])
    cfg = twin_config_for_rig(rig)
    assert cfg.rig == rig.geometry
    assert cfg.finger == rig.stiffness
    assert cfg.finger.length_m == cfg.heat.length_m == cfg.rig.finger.length_m == 0.125
    assert (cfg.heat, cfg.relax, cfg.motor) == (rig.heat, rig.relax, rig.motor)
    assert cfg.contact_position_m == rig.finger.contact_m
    assert cfg.force_ball == rig.force_ball
    assert cfg.object == rig.force_ball  # the hold's object is the rig's own ball
    assert cfg.force_sensor is not None
    assert (cfg.force_sensor.rate_hz, cfg.force_sensor.noise_n) == (80.0, 0.02)
    # The twin-only settings stay the base's, and a base without a force sensor keeps none.
    base = replace(TwinConfig(), ambient_c=22.0, force_sensor=None)
    bare = twin_config_for_rig(rig, base)
    assert (bare.ambient_c, bare.force_sensor, bare.scatter) == (22.0, None, base.scatter)
    # Contacts the paper made on its 110 mm finger fall at the same share of this one.
    assert cfg.paper_position_m(0.110) == pytest.approx(0.125)
    assert TwinConfig().paper_position_m(0.080) == 0.080


@pytest.mark.parametrize("rig", RIGS)
def test_the_heat_model_reaches_the_operating_temperatures(rig: str) -> None:
    """Full duty takes a finger past the hottest setpoint; the duty for 60 °C holds it there."""
    cfg = replace(twin_of(rig), initial_temp_c=None).without_sensors()
    assert duty_for_mean_temp(65.0, cfg.heat, cfg.ambient_c) < 1.0
    duty = duty_for_mean_temp(60.0, cfg.heat, cfg.ambient_c)
    clock = VirtualClock()
    twin = GripperTwin(replace(cfg, scatter=cfg.scatter.scaled(0.0)), seed=0, clock=clock)
    for _ in range(1800):  # 30 min: well past the finger's time constant
        clock.advance(1.0)
        twin.act(Command(0.0, (duty, duty)))
    mean_c = float(np.mean(twin.truth().finger_temps_c[0]))
    assert mean_c == pytest.approx(60.0, abs=0.5)


def test_a_twin_of_a_distorted_camera_is_refused_with_one_line() -> None:
    import tomllib

    data = tomllib.loads(RIG_FILES["ours"].read_text(encoding="utf-8"))
    data["rgb"]["dist"] = [0.05, -0.01, 0.0, 0.0]
    rig = parse_rig(data, "lens.toml")  # a real rig may have a lens' distortion
    with pytest.raises(InputError, match=r"^lens.toml: \[rgb\] dist: the twin renders an "
                                         r"undistorted pinhole camera") as info:
        twin_config_for_rig(rig)
    assert "\n" not in str(info.value)
    assert twin_config_for_rig(rig, TwinConfig().without_cameras()).rgb is None


def test_characterize_reports_each_rigs_k80_drop_and_area(monkeypatch, capsys) -> None:
    out: dict[str, dict[str, object]] = {}
    for rig in RIGS:
        code, text, err = run_main(["characterize", "--rig", RIG_FILES[rig], "--json"],
                                   monkeypatch, capsys)
        assert code == 0, err
        out[rig] = json.loads(text)
    ours, lab = out["ours"], out["lab"]
    drops = {rig: list(d["k80_drop_pct"].values())  # type: ignore[attr-defined]
             for rig, d in out.items()}
    assert all(35.0 <= x <= 45.0 for x in drops["ours"])
    assert all(abs(x - 36.6) < 0.5 for x in drops["lab"])  # its measured 2.05 -> 1.30 N/mm
    assert ours != lab
    # The lab's file gives k80 at 5 N: its characterization at 4 and 6 N brackets it.
    k80 = lab["k80_n_per_mm"]
    assert isinstance(k80, dict)
    assert k80["4"]["27"] < 2.05 < k80["6"]["27"]
    area = lab["area_8n_mm2"]
    assert isinstance(area, dict)
    assert area["60"] > area["27"] > 0.0
    finger = twin_of("lab").finger
    assert local_stiffness_n_per_m(5.0, 60.0, finger) / 1e3 == pytest.approx(1.30)
    assert math.isfinite(float(area["27"]))


@pytest.mark.parametrize(("command", "extra"), [
    (["hold", "--duration-s", "10"], []),
    (["task", "feather"], []),
    (["characterize"], []),
    (["dataset", "build", "--icfn-samples", "0", "--rcfn-sequences", "0"], ["--out"]),
    (["reproduce", "--quick", "--section", "characterization"], ["--out"]),
])
def test_every_twin_command_refuses_a_bad_rig_file_with_one_line(
        monkeypatch, capsys, tmp_path: Path, command: list[str], extra: list[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(RIG_FILES["lab"].read_text(encoding="utf-8")
                   .replace("length_mm = 125.0", "length_mm = 0.125"), encoding="utf-8")
    args = [*command, *(a for e in extra for a in (e, tmp_path / "out")), "--rig", bad]
    code, out, err = run_main(args, monkeypatch, capsys)
    assert_one_error_line(code, out, err, "[finger] length_mm is 0.125 mm, not a length a finger "
                                          "has (20 to 1000 mm): written in metres? 0.125 metres "
                                          "is 125 mm")
    assert not (tmp_path / "out").exists()
