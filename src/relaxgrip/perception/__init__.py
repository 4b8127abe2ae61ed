"""Perception: camera frames and the motor encoder in, marker pose and thermal features out.

Reads only what a real gripper provides, never the twin's ground truth.
"""

from relaxgrip.perception.features import ICFN_SCHEMA, FeatureSchema, build_icfn_features
from relaxgrip.perception.frames import FrameError
from relaxgrip.perception.marker import MarkerState, MarkerTracker, TrackStatus
from relaxgrip.perception.pipeline import Percept, Perception, StreamSync
from relaxgrip.perception.proximity import Proximity, ProximityEstimator, ProximityTarget
from relaxgrip.perception.thermal import ThermalFeatures, ThermalPerception

__all__ = [
    "ICFN_SCHEMA",
    "FeatureSchema",
    "FrameError",
    "MarkerState",
    "MarkerTracker",
    "Percept",
    "Perception",
    "Proximity",
    "ProximityEstimator",
    "ProximityTarget",
    "StreamSync",
    "ThermalFeatures",
    "ThermalPerception",
    "TrackStatus",
    "build_icfn_features",
]
