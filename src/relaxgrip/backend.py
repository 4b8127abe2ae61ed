"""The one interface every gripper backend implements.

A backend (the digital twin, the serial gripper, the MCU emulator path)
produces :class:`Observation` objects and takes :class:`Command` objects.  The
control loop, the recorder and the dashboard only know this module.  Ground
truth travels in :attr:`Observation.truth`, which only the twin fills and
which only experiments and metrics may read, never an estimator or a
controller.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from relaxgrip.errors import InputError
from relaxgrip.validate import check_duty, check_finite

__all__ = [
    "BackendInfo",
    "Command",
    "ForceSamples",
    "Frame",
    "Gripper",
    "Observation",
    "Truth",
    "check_backend",
]


@dataclass(frozen=True)
class Frame:
    """One camera frame, timestamped on arrival.

    Attributes
    ----------
    t_s : float
        Capture time on the backend's clock (s).
    seq : int
        Frame counter of its stream.
    image : ndarray
        RGB: ``(H, W, 3)`` uint8; infrared: ``(H, W)`` float32 temperatures (°C).
    """

    t_s: float
    seq: int
    image: NDArray[np.generic]

    def layout(self) -> object:
        """What a check of the image's type, size and channels reads, without its pixels.

        The image itself; a frame drawn on demand (the twin's) returns an
        array of the image's shape and dtype that holds no pixels.
        """
        return self.image

    def region(self, y0: int, y1: int, x0: int, x1: int) -> NDArray[np.generic]:
        """The pixels ``[y0:y1, x0:x1]`` of the image, equal to slicing :attr:`image`.

        A frame drawn on demand (the twin's) draws only these if the whole
        image has not been drawn: a tracker that reads the marker's
        neighbourhood costs the twin that region, not a frame.
        """
        return self.image[y0:y1, x0:x1]


@dataclass(frozen=True)
class Command:
    """What the host asks of the gripper for the next control period.

    Attributes
    ----------
    motor_velocity_mm_s : float
        Closing velocity of the gripper motor (mm/s); negative opens.
    heater_duty : tuple of float
        PWM duty of each finger's heater film, in [0, 1].
    arm_velocity_mm_s : float
        Vertical velocity of the arm carrying the gripper (mm/s); positive lifts.
    approach_velocity_mm_s : float
        Velocity of the arm along the fingers (mm/s); positive moves the
        gripper towards the object ahead.
    """

    motor_velocity_mm_s: float = 0.0
    heater_duty: tuple[float, float] = (0.0, 0.0)
    arm_velocity_mm_s: float = 0.0
    approach_velocity_mm_s: float = 0.0

    def __post_init__(self) -> None:
        check_finite(self.motor_velocity_mm_s, "motor_velocity_mm_s")
        check_finite(self.arm_velocity_mm_s, "arm_velocity_mm_s")
        check_finite(self.approach_velocity_mm_s, "approach_velocity_mm_s")
        if len(self.heater_duty) != 2:
            raise InputError(f"heater_duty needs 2 values, got {len(self.heater_duty)}")
        duties = (check_duty(self.heater_duty[0]), check_duty(self.heater_duty[1]))
        # A copy: a list given here and changed after the check would reach the heaters.
        object.__setattr__(self, "heater_duty", duties)


@dataclass(frozen=True)
class Truth:
    """Ground truth of the twin (never read by estimators or controllers).

    Forces in N, lengths in m, temperatures in °C, angles in rad.
    """

    contact_force_n: float
    finger_deflection_m: tuple[float, float]
    marker_deflection_m: tuple[float, float]
    marker_slope_rad: tuple[float, float]
    contact_position_m: float
    finger_temps_c: tuple[tuple[float, ...], tuple[float, ...]]
    finger_effective_temp_c: tuple[float, float]
    aperture_m: float
    object_name: str | None
    object_ahead_m: float
    object_lifted: bool
    object_slipping: bool
    object_crushed: bool
    object_plastic_m: float


@dataclass(frozen=True)
class ForceSamples:
    """Readings of a reference force sensor (the force-measurement ball).

    This is ground truth: only experiments and metrics read it, never an
    estimator or a controller.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Sample times on the backend's clock (s).
    force_n : ndarray, shape (n,)
        Measured normal force (N).
    """

    t_s: NDArray[np.float64]
    force_n: NDArray[np.float64]


@dataclass(frozen=True)
class Observation:
    """What a backend reports at one instant.

    Attributes
    ----------
    t_s : float
        Backend time (s).
    motor_position_mm : float
        Encoder position of the closing motor (mm from fully open).
    arm_height_mm : float
        Height of the arm above its start (mm).
    arm_forward_mm : float
        Travel of the arm along the fingers since the start (mm).
    heater_duty : tuple of float
        Heater duty read back from the driver.
    rgb : Frame or None
        Latest RGB frame (30 Hz stream), if the backend has a camera.
    ir : Frame or None
        Latest infrared frame (1 Hz stream), if the backend has one.
    faults : frozenset of str
        Active fault flags.
    force_ref : ForceSamples or None
        Reference force readings since the previous observation, when a
        force sensor is in the grasp (ground truth: experiments only).
    truth : Truth or None
        Ground truth; only the twin fills it.
    """

    t_s: float
    motor_position_mm: float
    arm_height_mm: float
    heater_duty: tuple[float, float]
    arm_forward_mm: float = 0.0
    rgb: Frame | None = None
    ir: Frame | None = None
    faults: frozenset[str] = field(default_factory=frozenset)
    force_ref: ForceSamples | None = None
    truth: Truth | None = None


@dataclass(frozen=True)
class BackendInfo:
    """Identity of a backend, recorded with every result."""

    name: str
    version: str
    has_truth: bool


@runtime_checkable
class Gripper(Protocol):
    """A gripper backend: observe, then act, on an injected clock."""

    @property
    def info(self) -> BackendInfo:
        """Name and version of the backend."""
        ...

    def reset(self, seed: int | None = None) -> Observation:
        """Return the backend to its initial state and observe it."""
        ...

    def observe(self) -> Observation:
        """Report the state at the clock's current time."""
        ...

    def act(self, command: Command) -> None:
        """Apply ``command`` from the clock's current time on."""
        ...

    def close(self) -> None:
        """Stop the motor, switch the heaters off and release resources."""
        ...


def check_backend(backend: Gripper, advance: Callable[[float], None], seconds: float = 1.0) -> None:
    """Check that ``backend`` honours the :class:`Gripper` contract.

    Parameters
    ----------
    backend : Gripper
        The backend under test.
    advance : callable
        Moves the backend's clock forward by a number of seconds (a virtual
        clock's ``advance``, or a sleep for wall-clock backends).
    seconds : float
        How long to exercise it.

    Raises
    ------
    AssertionError
        Naming the first broken rule.
    """
    assert isinstance(backend, Gripper), "backend does not implement the Gripper protocol"
    info = backend.info
    assert info.name, "backend info needs a name"
    assert info.version, "backend info needs a version"
    obs = backend.reset(seed=0)
    assert isinstance(obs, Observation), "reset() must return an Observation"
    if not info.has_truth:
        assert obs.truth is None, "only backends with has_truth may fill Observation.truth"
    last_t = obs.t_s
    steps = max(2, round(seconds / 0.05))
    for k in range(steps):
        backend.act(Command(motor_velocity_mm_s=2.0 if k < steps // 2 else -2.0))
        advance(seconds / steps)
        obs = backend.observe()
        assert isinstance(obs, Observation), "observe() must return an Observation"
        assert obs.t_s >= last_t, "observation time went backwards"
        assert math.isfinite(obs.motor_position_mm), "motor position must be finite"
        assert all(0.0 <= d <= 1.0 for d in obs.heater_duty), "heater duty outside 0-1"
        last_t = obs.t_s
    assert last_t > 0.0 or seconds == 0.0, "time did not advance"
    backend.act(Command())
    backend.close()
