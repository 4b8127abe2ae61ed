"""Fixed-aperture holds on the twin: the relaxation the controller has to fight.

The rig closes on an object until the true contact force reaches the start
force, stops the motor and holds the aperture while a thermostat keeps the
fingers at the set temperature; the force then decays by stress relaxation.
This is the twin's calibration experiment (paper: holding at 5 N, §V-C) and
its speed benchmark.  Experiments may read ground truth; estimators never do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from relaxgrip.backend import Command, Observation
from relaxgrip.clock import VirtualClock
from relaxgrip.physics.thermal import duty_for_mean_temp
from relaxgrip.twin import TWIN_VERSION, GripperTwin, TwinConfig
from relaxgrip.validate import check_positive, check_temp_c

FloatArray = NDArray[np.float64]

__all__ = ["HoldTrace", "TruthThermostat", "close_to_force", "run_fixed_aperture_hold"]


@dataclass
class TruthThermostat:
    """PI thermostat on the true mean finger temperature (a calibration rig's heater control).

    Parameters
    ----------
    setpoint_c : float
        Target mean finger temperature (°C).
    feedforward : float
        Steady duty for the setpoint.
    kp, ki : float
        Gains (duty per K, duty per K s).
    """

    setpoint_c: float
    feedforward: float
    kp: float = 0.08
    ki: float = 0.004
    _integral: list[float] = field(default_factory=lambda: [0.0, 0.0])

    def duty(self, obs: Observation, dt_s: float) -> tuple[float, float]:
        """Heater duties for both fingers from the true temperatures."""
        assert obs.truth is not None, "the truth thermostat needs the twin"
        out = []
        for j, temps in enumerate(obs.truth.finger_temps_c):
            err = self.setpoint_c - sum(temps) / len(temps)
            self._integral[j] = min(max(self._integral[j] + err * dt_s, -50.0), 50.0)
            u = self.feedforward + self.kp * err + self.ki * self._integral[j]
            out.append(min(max(u, 0.0), 1.0))
        return out[0], out[1]


def close_to_force(
    twin: GripperTwin,
    target_n: float,
    thermostat: TruthThermostat,
    rate_hz: float = 30.0,
    approach_mm_s: float = 20.0,
    contact_mm_s: float = 1.0,
    timeout_s: float = 60.0,
) -> float:
    """Close on the object until the true force reaches ``target_n``, then stop.

    Returns
    -------
    float
        The time (s) at which the force crossed ``target_n``.

    Raises
    ------
    RuntimeError
        If the force is not reached within ``timeout_s``.
    """
    clock = twin.clock
    assert isinstance(clock, VirtualClock), "close_to_force runs in virtual time"
    dt = 1.0 / rate_hz
    obj = twin.config.object
    assert obj is not None, "close_to_force needs an object"
    t_end = clock.now() + timeout_s
    obs = twin.observe()
    while clock.now() < t_end:
        assert obs.truth is not None
        gap_mm = (obs.truth.aperture_m - obj.width_m) * 1e3
        force = obs.truth.contact_force_n
        if force >= target_n:
            twin.act(Command(0.0, thermostat.duty(obs, dt)))
            return obs.t_s
        speed = approach_mm_s if gap_mm > 3.0 else contact_mm_s
        twin.act(Command(speed, thermostat.duty(obs, dt)))
        clock.advance(dt)
        obs = twin.observe()
    raise RuntimeError(f"force {target_n} N not reached within {timeout_s} s")


@dataclass(frozen=True)
class HoldTrace:
    """A fixed-aperture hold, sampled at the control rate from the start of the hold.

    Attributes
    ----------
    temp_c, target_n, seed : float, float, int
        Set temperature (°C), start force (N) and twin seed.
    t_s : ndarray
        Time since the hold started (s).
    force_n : ndarray
        True contact force (N).
    temp_mean_c : ndarray
        Mean finger temperature (°C).
    twin_version : str
        Version of the twin that produced it.
    onset_s : float
        Twin time at which the hold started, after the closing (s).
    """

    temp_c: float
    target_n: float
    seed: int
    t_s: FloatArray
    force_n: FloatArray
    temp_mean_c: FloatArray
    twin_version: str = TWIN_VERSION
    onset_s: float = math.nan

    def window(self, start_s: float, end_s: float) -> FloatArray:
        """Forces with ``start_s <= t <= end_s`` (N)."""
        mask = (self.t_s >= start_s - 1e-9) & (self.t_s <= end_s + 1e-9)
        return self.force_n[mask]

    def mean_abs_deviation_n(self, start_s: float, end_s: float) -> float:
        """Mean ``|F - target|`` over a window (N)."""
        return float(np.mean(np.abs(self.window(start_s, end_s) - self.target_n)))

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python summary (no arrays)."""
        return {
            "twin_version": self.twin_version,
            "temp_c": self.temp_c,
            "target_n": self.target_n,
            "seed": self.seed,
            "duration_s": float(self.t_s[-1]),
            "start_force_n": float(self.force_n[0]),
            "end_force_n": float(self.force_n[-1]),
        }


def run_fixed_aperture_hold(
    temp_c: float = 40.0,
    target_n: float = 5.0,
    duration_s: float = 280.0,
    seed: int = 0,
    config: TwinConfig | None = None,
    rate_hz: float = 30.0,
) -> HoldTrace:
    """Close to ``target_n`` at ``temp_c``, then hold the aperture for ``duration_s``.

    Parameters
    ----------
    temp_c : float
        Finger temperature held by the thermostat (°C).
    target_n : float
        Force at which the motor stops (N).
    duration_s : float
        Length of the hold (s).
    seed : int
        Twin seed (run-to-run scatter).
    config : TwinConfig, optional
        Twin configuration (default: the force ball, no cameras and no
        reference force: the hold reads ground truth only).
    rate_hz : float
        Control and sampling rate (Hz).

    Returns
    -------
    HoldTrace
        The force and temperature during the hold.
    """
    check_temp_c(temp_c, "hold temperature")
    check_positive(target_n, "target force")
    check_positive(duration_s, "hold duration")
    base = config if config is not None else TwinConfig().without_sensors()
    cfg = replace(base, initial_temp_c=temp_c)
    twin = GripperTwin(cfg, seed=seed)
    clock = twin.clock
    assert isinstance(clock, VirtualClock)
    thermostat = TruthThermostat(temp_c, duty_for_mean_temp(temp_c, cfg.heat, cfg.ambient_c))
    t0 = close_to_force(twin, target_n, thermostat, rate_hz)
    dt = 1.0 / rate_hz
    n = round(duration_s * rate_hz) + 1
    t = np.empty(n)
    force = np.empty(n)
    temp = np.empty(n)
    for k in range(n):
        obs = twin.observe()
        truth = obs.truth
        assert truth is not None
        t[k] = obs.t_s - t0
        force[k] = truth.contact_force_n
        temp[k] = sum(map(sum, truth.finger_temps_c)) / (2 * len(truth.finger_temps_c[0]))
        twin.act(Command(0.0, thermostat.duty(obs, dt)))
        clock.advance(dt)
    return HoldTrace(temp_c, target_n, seed, t, force, temp, onset_s=t0)
