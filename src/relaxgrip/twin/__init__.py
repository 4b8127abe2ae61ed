"""The digital twin: a stepped, seeded world built from :mod:`relaxgrip.physics`."""

from relaxgrip.twin.config import (
    MODELS_FROM,
    SAME_RUNS_AS,
    TWIN_VERSION,
    MotorParams,
    ScatterParams,
    TwinConfig,
)
from relaxgrip.twin.objects import CATALOGUE, ObjectSpec, get_object
from relaxgrip.twin.twin import GripperTwin, TwinMaterial

__all__ = [
    "CATALOGUE",
    "MODELS_FROM",
    "SAME_RUNS_AS",
    "TWIN_VERSION",
    "GripperTwin",
    "MotorParams",
    "ObjectSpec",
    "ScatterParams",
    "TwinConfig",
    "TwinMaterial",
    "get_object",
]
