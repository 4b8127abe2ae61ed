"""The twin and the closed loop, pinned: seeded runs give the recorded outputs bit for bit.

Every optimisation of the twin's stepping, its renderers, perception and the
loop must leave what they compute unchanged (the twin's version promises the
same outputs for the same seed).  ``tests/data/pinned_runs.json`` holds the
SHA-256 of every output of a few short seeded runs (frames, observations,
truth, the loop's series) and a few of their values in full, recorded from
the code the optimisations started from.  A deliberate change of the twin's
behaviour bumps ``TWIN_VERSION`` and records the file again::

    PYTHONPATH=src python3 -m tests.twin.test_pinned --record

The hashes are of this machine's floating point (NumPy, OpenCV and numba
builds): the file records the stack it was made on, and a stack that rounds
differently is reported as such rather than as a changed twin.
"""

from __future__ import annotations

import hashlib
import json
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from relaxgrip.backend import Command, Observation
from relaxgrip.clock import VirtualClock
from relaxgrip.twin import TWIN_VERSION, GripperTwin, TwinConfig
from relaxgrip.twin.sensors import RgbSensorConfig

PINNED = Path(__file__).resolve().parents[1] / "data" / "pinned_runs.json"


class _Digest:
    """SHA-256 over a run's outputs, fed in order; a few values kept in full."""

    def __init__(self) -> None:
        self._h = hashlib.sha256()
        self.samples: dict[str, Any] = {}

    def add(self, value: Any) -> None:
        if value is None:
            self._h.update(b"none")
        elif isinstance(value, np.ndarray):
            self._h.update(str((value.dtype.str, value.shape)).encode())
            self._h.update(np.ascontiguousarray(value).tobytes())
        elif isinstance(value, float | int | bool | str):
            self._h.update(repr(value).encode())
        elif isinstance(value, tuple | list):
            for item in value:
                self.add(item)
        else:
            raise TypeError(f"cannot digest {type(value)}")

    def hexdigest(self) -> str:
        return self._h.hexdigest()


def _add_observation(d: _Digest, obs: Observation, frames: bool) -> None:
    d.add((obs.t_s, obs.motor_position_mm, obs.arm_height_mm, obs.heater_duty))
    if frames:
        d.add(None if obs.rgb is None else (obs.rgb.t_s, obs.rgb.seq,
                                            np.asarray(obs.rgb.image)))
        d.add(None if obs.ir is None else (obs.ir.t_s, obs.ir.seq, np.asarray(obs.ir.image)))
    d.add(None if obs.force_ref is None else (obs.force_ref.t_s, obs.force_ref.force_n))
    t = obs.truth
    assert t is not None
    d.add((t.contact_force_n, t.finger_deflection_m, t.marker_deflection_m, t.marker_slope_rad,
           t.contact_position_m, t.finger_temps_c, t.finger_effective_temp_c, t.aperture_m,
           t.object_ahead_m, t.object_lifted, t.object_slipping, t.object_crushed,
           t.object_plastic_m))


def _twin_run(config: TwinConfig, seed: int, ticks: int, frames: bool) -> dict[str, Any]:
    """Close on the ball at 20 mm/s with the heaters on, stop at 3 N, hold; observe at 30 Hz."""
    clock = VirtualClock()
    twin = GripperTwin(config, seed=seed, clock=clock)
    d = _Digest()
    holding = False
    obs = twin.observe()
    for k in range(1, ticks + 1):
        assert obs.truth is not None
        holding = holding or obs.truth.contact_force_n >= 3.0
        twin.act(Command(0.0 if holding else 20.0, (0.4, 0.35)))
        clock.advance(1.0 / 30.0)
        obs = twin.observe()
        _add_observation(d, obs, frames)
        if k == ticks - 5 and frames:
            assert obs.rgb is not None
            assert obs.ir is not None
            d.samples["rgb_late_sum"] = int(np.asarray(obs.rgb.image, dtype=np.int64).sum())
            d.samples["ir_late_sum"] = float(np.asarray(obs.ir.image, dtype=np.float64).sum())
    assert obs.truth is not None
    d.samples["force_n"] = obs.truth.contact_force_n
    d.samples["finger_deflection_m"] = list(obs.truth.finger_deflection_m)
    d.samples["motor_position_mm"] = obs.motor_position_mm
    return {"sha256": d.hexdigest(), "values": d.samples}


def _hold_run(seed: int) -> dict[str, Any]:
    """A short relaxation-aware hold at 5 N, 40 °C: the loop's every series."""
    from relaxgrip.experiments.controlled_hold import run_hold

    result = run_hold("relax", 5.0, 4.0, 40.0, seed=seed)
    d = _Digest()
    for name in sorted(result.loop.series):
        d.add(name)
        d.add(np.asarray(result.loop.series[name]))
    d.samples["steps"] = int(result.loop["t_s"].size)
    d.samples["estimate_n_last"] = float(result.estimate_n[-1])
    d.samples["truth_n_last"] = float(result.truth_n[-1])
    return {"sha256": d.hexdigest(), "values": d.samples}


RUNS: dict[str, Callable[[], dict[str, Any]]] = {
    "twin_sensors": lambda: _twin_run(TwinConfig(), 7, 330, frames=True),
    "twin_no_sensors": lambda: _twin_run(TwinConfig(initial_temp_c=40.0).without_sensors(), 11,
                                         3000, frames=False),
    # The renderer's other path: blur and flicker (the whole frame is drawn, then blurred).
    "twin_rgb_blur": lambda: _twin_run(
        replace(TwinConfig(), rgb=RgbSensorConfig(blur_sigma_px=0.8, lighting_flicker=0.02)),
        3, 40, frames=True),
    "closed_loop_hold": lambda: _hold_run(5),
}


def _stack() -> dict[str, str]:
    import cv2
    import numba

    return {"numpy": np.__version__, "opencv": cv2.__version__, "numba": numba.__version__,
            "python": sys.version.split()[0]}


def _pinned() -> dict[str, Any]:
    data: dict[str, Any] = json.loads(PINNED.read_text())
    return data


@pytest.mark.parametrize("name", sorted(RUNS))
def test_seeded_run_is_pinned(name: str) -> None:
    pinned = _pinned()
    assert pinned["twin_version"] == TWIN_VERSION, (
        "the twin's version changed: record tests/data/pinned_runs.json again "
        "(python3 -m tests.twin.test_pinned --record)")
    got = RUNS[name]()
    want = pinned["runs"][name]
    if got["sha256"] != want["sha256"] and _stack() != pinned["stack"]:
        pytest.skip(f"recorded on {pinned['stack']}, this is {_stack()}: the hash is of "
                    "another floating point")
    assert got["values"] == want["values"]
    assert got["sha256"] == want["sha256"]


def _record() -> None:
    out = {"twin_version": TWIN_VERSION, "stack": _stack(),
           "runs": {name: run() for name, run in sorted(RUNS.items())}}
    PINNED.parent.mkdir(parents=True, exist_ok=True)
    PINNED.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    print(f"wrote {PINNED}")


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        raise SystemExit("usage: python3 -m tests.twin.test_pinned --record")
    _record()
