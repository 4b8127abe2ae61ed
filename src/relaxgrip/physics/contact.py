"""Finger–object contact: series compliance, friction, weight, adhesion.

The fingers and the object form a chain of springs in series between the
two finger bases: the closing interpenetration ``delta`` (object width minus
aperture) is shared by the finger deflections and the object's compression,
and the same force acts through all of them.  Each finger enters through its
incremental relation over the current step, ``F = K_j X_j + c_j`` (see
:func:`relaxgrip.physics.viscoelastic.branch_update`), which keeps the
viscoelastic update exact and the contact solve closed-form.

Lifting holds when friction (reduced by the tilt of the bent finger's
contact face) plus any adhesion carries the object's weight.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

GRAVITY_M_PER_S2 = 9.80665

__all__ = [
    "GRAVITY_M_PER_S2",
    "AdhesionParams",
    "SeriesContact",
    "adhesion_pulloff_n",
    "friction_capacity_n",
    "series_contact",
]


class SeriesContact(NamedTuple):
    """Solution of one contact step.

    Attributes
    ----------
    force_n : float
        Contact force through the chain (N), ``>= 0``.
    finger_deflection_m : tuple of float
        Deflection of each finger at its contact point (m).
    object_compression_m : float
        Elastic compression of the object (m).
    plastic_m : float
        Permanent (plastic) compression added in this step (m), ``>= 0``.
    """

    force_n: float
    finger_deflection_m: tuple[float, ...]
    object_compression_m: float
    plastic_m: float


def series_contact(
    delta_m: float,
    finger_stiffness_n_per_m: Sequence[float],
    finger_offset_n: Sequence[float],
    object_stiffness_n_per_m: float,
    object_yield_n: float = math.inf,
) -> SeriesContact:
    """Solve the finger–object–finger chain for one step.

    Runs on plain floats: it sits in the twin's inner loop with one or two
    fingers, where NumPy's per-call overhead would dominate.

    Parameters
    ----------
    delta_m : float
        Interpenetration to be shared (m): object width (less any permanent
        set) minus the aperture.  ``<= 0`` means the chain is open.
    finger_stiffness_n_per_m : sequence of float
        Incremental stiffness ``K_j`` of each finger over the step (N/m), > 0.
    finger_offset_n : sequence of float
        Offset ``c_j`` of each finger's step relation ``F = K_j X_j + c_j`` (N).
    object_stiffness_n_per_m : float
        Object stiffness (N/m), > 0.
    object_yield_n : float
        Force above which the object deforms plastically (N).

    Returns
    -------
    SeriesContact
        Force, deflections and compression; with no contact the force is 0
        and each finger sits where its own relation gives zero force.
    """
    if min(finger_stiffness_n_per_m) <= 0 or object_stiffness_n_per_m <= 0:
        raise ValueError("stiffnesses must be > 0")
    if len(finger_stiffness_n_per_m) != len(finger_offset_n):
        raise ValueError("one offset per finger stiffness")
    finger_compliance = 0.0
    preload = 0.0
    for k, c in zip(finger_stiffness_n_per_m, finger_offset_n):  # noqa: B905 (lengths checked)
        finger_compliance += 1.0 / k
        preload += c / k
    force = (delta_m + preload) / (finger_compliance + 1.0 / object_stiffness_n_per_m)
    if force <= 0.0:
        force = 0.0
    elif force > object_yield_n:
        force = object_yield_n
    x_fingers = tuple(
        (force - c) / k
        for k, c in zip(finger_stiffness_n_per_m, finger_offset_n)  # noqa: B905 (lengths checked)
    )
    if force == 0.0:
        return SeriesContact(0.0, x_fingers, 0.0, 0.0)
    elastic = force / object_stiffness_n_per_m
    plastic = max(0.0, delta_m - sum(x_fingers) - elastic) if force == object_yield_n else 0.0
    return SeriesContact(force, x_fingers, elastic, plastic)


def friction_capacity_n(
    normal_force_n: ArrayLike, friction_coeff: float, face_tilt_rad: ArrayLike = 0.0,
    n_contacts: int = 2,
) -> FloatArray:
    """Vertical load that friction can carry in a pinch (N).

    A bent finger tilts its contact face so that the gap widens towards the
    fingertip; the normal force then pushes the object out with ``N sin(theta)``
    while friction holds with at most ``mu N cos(theta)``.

    Parameters
    ----------
    normal_force_n : array_like
        Normal force at each contact (N).
    friction_coeff : float
        Coulomb friction coefficient ``mu``.
    face_tilt_rad : array_like
        Tilt ``theta`` of the contact face (rad), the finger's slope there.
    n_contacts : int
        Number of contacts sharing the load.

    Returns
    -------
    ndarray
        ``n N max(0, mu cos(theta) - sin(theta))`` (N).
    """
    n = np.asarray(normal_force_n, dtype=np.float64)
    theta = np.asarray(face_tilt_rad, dtype=np.float64)
    per_contact = np.clip(friction_coeff * np.cos(theta) - np.sin(theta), 0.0, None)
    return n_contacts * np.clip(n, 0.0, None) * per_contact


@dataclass(frozen=True)
class AdhesionParams:
    """Thermally switchable adhesion pads.

    Attributes
    ----------
    max_pulloff_n : float
        Pull-off force of both pads fully activated on a flat surface (N).
    activation_c : float
        Pad temperature at half activation (°C).
    width_k : float
        Width of the activation (K).
    """

    max_pulloff_n: float = 6.0
    activation_c: float = 50.0
    width_k: float = 2.5


def adhesion_pulloff_n(
    pad_temp_c: ArrayLike, flat_surface: bool, params: AdhesionParams
) -> FloatArray:
    """Pull-off force the heated pads add on a flat surface (N).

    Parameters
    ----------
    pad_temp_c : array_like
        Pad temperature (°C).
    flat_surface : bool
        Whether the object offers a flat (or low-curvature) face.
    params : AdhesionParams
        Pad constants.

    Returns
    -------
    ndarray
        ``F_max sigmoid((T - T_act) / w)`` on flat surfaces, 0 otherwise.
    """
    t = np.asarray(pad_temp_c, dtype=np.float64)
    if not flat_surface:
        return np.zeros_like(t)
    activation = 0.5 * (1.0 + np.tanh(0.5 * (t - params.activation_c) / params.width_k))
    return params.max_pulloff_n * activation
