"""The twin's object catalogue: what the gripper can hold in the paper's experiments."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from relaxgrip.errors import InputError

__all__ = ["CATALOGUE", "ObjectSpec", "get_object"]

Surface = Literal["flat", "curved", "rough"]


@dataclass(frozen=True)
class ObjectSpec:
    """Mechanical and thermal description of a graspable object.

    Attributes
    ----------
    name : str
        Catalogue key.
    width_m : float
        Width between the two contact faces (m).
    stiffness_n_per_m : float
        Contact stiffness of the object across its width (N/m).
    mass_kg : float
        Mass (kg).
    friction_coeff : float
        Coulomb friction against the finger skin.
    surface : {"flat", "curved", "rough"}
        Contact surface; the adhesion pads only grip flat ones.
    temp_c : float
        Surface temperature seen by the infrared camera (°C).
    yield_force_n : float
        Squeezing force above which it deforms permanently (N); ``inf`` if never.
    grip_length_m : float
        Height over which the fingers can slide along it before losing it (m).
    emissivity : float
        Thermal emissivity seen by the infrared camera (polished metal is low).
    color_rgb : tuple of int
        Mean colour seen by the RGB camera (0-255 per channel).
    force_sensor : bool
        Whether it carries a force sensor (the paper's force-measurement ball),
        whose readings the twin reports as a reference force stream.
    """

    name: str
    width_m: float
    stiffness_n_per_m: float
    mass_kg: float
    friction_coeff: float
    surface: Surface
    temp_c: float = 25.0
    yield_force_n: float = math.inf
    grip_length_m: float = 0.04
    emissivity: float = 0.95
    color_rgb: tuple[int, int, int] = (200, 200, 200)
    force_sensor: bool = False

    @property
    def weight_n(self) -> float:
        """Weight at standard gravity (N)."""
        return self.mass_kg * 9.80665


def _obj(name: str, width_mm: float, k_n_per_mm: float, mass_kg: float, mu: float,
         surface: Surface, temp_c: float = 25.0, yield_n: float = math.inf, *,
         emissivity: float = 0.95, color: tuple[int, int, int] = (200, 200, 200),
         force_sensor: bool = False) -> ObjectSpec:
    return ObjectSpec(name, width_mm * 1e-3, k_n_per_mm * 1e3, mass_kg, mu, surface, temp_c,
                      yield_n, emissivity=emissivity, color_rgb=color, force_sensor=force_sensor)


CATALOGUE: dict[str, ObjectSpec] = {
    o.name: o
    for o in (
        # The paper's spherical force-measurement unit: a silicone ball around a
        # pressure sensor, softer than the finger (which is why a fixed aperture
        # loses less force than the finger alone relaxes).
        _obj("force_ball", 60, 0.70, 0.15, 0.8, "curved", color=(40, 90, 200), force_sensor=True),
        _obj("hammer", 32, 20.0, 0.60, 0.7, "curved", color=(150, 90, 50)),
        _obj("orange", 75, 1.5, 0.20, 0.6, "curved", yield_n=25.0, color=(240, 140, 20)),
        _obj("balloon", 110, 0.05, 0.005, 0.5, "curved", yield_n=3.0, color=(220, 30, 40)),
        # Room-temperature water evaporates through the paper: a kelvin or two below the air.
        _obj("paper_cup", 75, 0.60, 0.21, 0.5, "curved", temp_c=23.5, yield_n=4.0,
             emissivity=0.92, color=(240, 240, 235)),
        _obj("paper_cup_hot", 75, 0.60, 0.21, 0.5, "curved", temp_c=70.0, yield_n=4.0,
             emissivity=0.92, color=(240, 240, 235)),
        _obj("glass", 70, 200.0, 0.25, 0.4, "curved", emissivity=0.90, color=(180, 210, 215)),
        # Bare aluminium reflects most of the infrared: it shows the room, not itself.
        _obj("aluminium_can", 66, 1.2, 0.015, 0.4, "curved", yield_n=5.0, emissivity=0.10,
             color=(190, 195, 200)),
        _obj("weight_1kg", 50, 100.0, 1.00, 0.6, "curved", emissivity=0.80, color=(70, 70, 75)),
        _obj("feather", 10, 0.005, 0.001, 0.3, "rough", color=(245, 245, 240)),
        _obj("brush", 30, 0.05, 0.05, 0.5, "rough", color=(120, 80, 40)),
        _obj("wrench", 12, 100.0, 0.30, 0.4, "flat", emissivity=0.30, color=(160, 160, 165)),
        _obj("flat_box", 40, 10.0, 0.30, 0.2, "flat", color=(200, 170, 110)),
    )
}


def get_object(name: str) -> ObjectSpec:
    """Look up an object by name.

    Raises
    ------
    InputError
        If ``name`` is not in the catalogue (the message lists the known ones).
    """
    try:
        return CATALOGUE[name]
    except KeyError:
        known = ", ".join(sorted(CATALOGUE))
        raise InputError(f"unknown object {name!r}; known objects: {known}") from None
