"""Channels of a relaxgrip recording and their JSON Schemas (MCAP ``jsonschema`` encoding).

Every channel's messages are JSON objects (message encoding ``json``); each
channel carries a JSON Schema (schema encoding ``jsonschema``).  The two image
channels use Foxglove's published schemas, so the file opens in Foxglove
(Image panel) as it is:

* ``/rgb``: ``foxglove.CompressedImage``, the RGB camera frame as ``jpeg``
  (default, quality 95) or ``png`` (lossless: offline replay then matches bit
  for bit).  The image is RGB as a viewer shows it.
* ``/ir``: ``foxglove.RawImage``, encoding ``32FC1``: the infrared frame's
  temperatures in °C as little-endian float32, row-major (``step = 4·width``).

The relaxgrip channels (``relaxgrip.*`` schemas) carry the loop's numbers in SI
units with units in the field names; a value the loop does not have (nan) is
``null``.  Times inside messages are seconds on the loop's clock; every
message's ``log_time`` and ``publish_time`` are that time in nanoseconds.
"""

from __future__ import annotations

import json
from typing import Any

__all__ = [
    "CHANNELS",
    "RECORDING_FORMAT",
    "RECORDING_VERSION",
    "schema_bytes",
]

RECORDING_FORMAT = "relaxgrip-recording"
RECORDING_VERSION = 1

_DRAFT = "https://json-schema.org/draft/2020-12/schema"
_NUM = {"type": ["number", "null"]}
_PAIR = {"type": "array", "items": {"type": ["number", "null"]}, "minItems": 2, "maxItems": 2}
_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
}


def _obj(title: str, description: str, properties: dict[str, Any],
         required: tuple[str, ...] = ()) -> dict[str, Any]:
    return {"$schema": _DRAFT, "title": title, "description": description, "type": "object",
            "properties": properties, "required": list(required)}


def _nums(*names: str) -> dict[str, Any]:
    return {name: _NUM for name in names}


#: Foxglove's CompressedImage (published JSON Schema, data base64 in JSON).
COMPRESSED_IMAGE = _obj("foxglove.CompressedImage", "A compressed image", {
    "timestamp": {**_TIME, "description": "Timestamp of image"},
    "frame_id": {"type": "string", "description": "Frame of reference for the image."},
    "data": {"type": "string", "contentEncoding": "base64",
             "description": "Compressed image data"},
    "format": {"type": "string", "description": "Image format (jpeg, png, webp)"},
})
#: Foxglove's RawImage (published JSON Schema, data base64 in JSON).
RAW_IMAGE = _obj("foxglove.RawImage", "A raw image", {
    "timestamp": {**_TIME, "description": "Timestamp of image"},
    "frame_id": {"type": "string", "description": "Frame of reference for the image."},
    "width": {"type": "integer", "minimum": 0, "description": "Image width"},
    "height": {"type": "integer", "minimum": 0, "description": "Image height"},
    "encoding": {"type": "string", "description": "Encoding of the raw image data"},
    "step": {"type": "integer", "minimum": 0, "description": "Byte length of a single row"},
    "data": {"type": "string", "contentEncoding": "base64", "description": "Raw image data"},
})

#: Topic of the session message, the first of every recording.
SESSION_TOPIC = "/relaxgrip/session"
#: Name of the MCAP metadata record that holds a copy of the session message, written at
#: once outside any chunk: ``relaxgrip recover`` restores the session from it when the
#: chunk that held the message is lost.  Its keys: ``log_time_ns`` and ``message`` (JSON).
SESSION_METADATA = "relaxgrip.session"

SESSION = _obj("relaxgrip.Session", "Who recorded what: written once, first.", {
    "format": {"const": RECORDING_FORMAT},
    "format_version": {"type": "integer"},
    "relaxgrip_version": {"type": "string"},
    "backend": {"type": "object", "properties": {
        "name": {"type": "string"}, "version": {"type": "string"},
        "has_truth": {"type": "boolean"}}},
    "estimator": {"type": "string", "description": "fixed, icfn, relax, ..."},
    "plan": {"type": "object", "description": "GraspPlan fields (inf as null)"},
    "rig": {"type": "object", "description": "RigGeometry fields (cameras, marker, fingers)"},
    "t0_s": {"type": "number", "description": "loop start on the backend's clock"},
    "rgb_format": {"type": "string"},
    "ir_encoding": {"type": "string"},
    "scenario": {"type": "object", "additionalProperties": {"type": "string"},
                 "description": "profiles the run applied besides the plan, as given "
                                "(temp_profile, target_profile, disturbance)"},
    "lost_start_s": {"type": "number",
                     "description": "set by relaxgrip recover when the damage took the first "
                                    "chunk: the loop time the recording resumes at (s)"},
    "models": {"type": ["object", "null"],
               "description": "the estimator's models: directory, sha256 of each model file, "
                              "hold_bias_sha256, and the observer's directory, sha256 and band "
                              "scales (null: built on bare models)"},
}, ("format", "format_version", "backend", "estimator", "rig", "t0_s"))

OBSERVATION = _obj("relaxgrip.Observation",
                   "What the backend reported this period (what the controller read).", {
    "t_s": {"type": "number"},
    "motor_position_mm": {"type": "number"},
    "arm_height_mm": {"type": "number"},
    "arm_forward_mm": {"type": "number"},
    "heater_duty": _PAIR,
    "rgb_seq": {"type": ["integer", "null"], "description": "frame counter of the RGB frame"},
    "rgb_t_s": _NUM,
    "ir_seq": {"type": ["integer", "null"], "description": "frame counter of the IR frame"},
    "ir_t_s": _NUM,
    "faults": {"type": "array", "items": {"type": "string"}},
}, ("t_s", "motor_position_mm", "arm_height_mm", "heater_duty", "rgb_seq", "ir_seq"))

PERCEPTION = _obj("relaxgrip.Perception", "Perception's output this period.", {
    "t_s": {"type": "number"},
    "marker_status": {"type": "string", "description": "zeroing, tracking, rejected, lost, "
                                                       "invalid"},
    "marker_pose": {"type": ["array", "null"], "items": {"type": "number"},
                    "description": "dx, dy, dz (m), rx, ry, rz (rad) from the zero pose"},
    "ir_age_s": _NUM,
    "ir_error": {"type": "string"},
    "has_features": {"type": "boolean"},
}, ("t_s", "marker_status"))

ESTIMATE = _obj("relaxgrip.ForceEstimate", "The force estimator's output (N, s).", {
    "t_s": {"type": "number"},
    **_nums("force_n", "f_icfn_n", "f_onset_n", "k_n", "tau_s", "hold_s", "calibration_n",
            "chain_n"),
    "valid": {"type": "boolean"},
}, ("t_s", "force_n", "f_icfn_n"))

RELAXATION = _obj("relaxgrip.Relaxation",
                  "Eq. 10's parameters during the hold (from the hold onset on).", {
    "t_s": {"type": "number"},
    **_nums("f_onset_n", "k_n", "tau_s", "kappa", "hold_s", "closure_stiffness_n_per_mm"),
}, ("t_s",))

COMMAND = _obj("relaxgrip.Command", "What the controller asked of the gripper.", {
    "t_s": {"type": "number"},
    "motor_velocity_mm_s": {"type": "number"},
    "arm_velocity_mm_s": {"type": "number"},
    "approach_velocity_mm_s": {"type": "number"},
    "heater_duty": _PAIR,
}, ("t_s", "motor_velocity_mm_s", "heater_duty"))

TEMPERATURE = _obj("relaxgrip.Temperature", "Finger temperatures (°C) and the setpoint.", {
    "t_s": {"type": "number"},
    "ir_temp_c": _PAIR,
    "setpoint_c": _NUM,
    "truth_temp_c": {"type": ["array", "null"], "items": {"type": "number"},
                     "description": "true mean temperature per finger (twin only)"},
}, ("t_s", "ir_temp_c"))

PHASE = _obj("relaxgrip.Phase", "The grasp phase this period, and the force it holds.", {
    "t_s": {"type": "number"},
    "phase": {"type": "string"},
    "target_n": {"type": "number", "description": "the plan's target force now (N)"},
}, ("t_s", "phase"))

EVENT = _obj("relaxgrip.Event",
             "A phase transition (kind 'phase'), a controller event (contact, hold_onset, ...) "
             "or 'marker_rezero' (the controller zeroed the marker again after this period).", {
    "t_s": {"type": "number"},
    "kind": {"type": "string"},
    "detail": {"type": "string"},
}, ("t_s", "kind"))

TRUTH = _obj("relaxgrip.Truth", "Ground truth of the backend (never read by the controller).", {
    "t_s": {"type": "number"},
    "contact_force_n": {"type": "number"},
    "finger_temp_c": {"type": "array", "items": {"type": "number"}},
    "finger_deflection_m": {"type": "array", "items": {"type": "number"}},
    "marker_deflection_m": {"type": "array", "items": {"type": "number"}},
    "contact_position_m": {"type": "number"},
    "aperture_m": {"type": "number"},
    "object_name": {"type": ["string", "null"]},
    "object_lifted": {"type": "boolean"},
    "object_slipping": {"type": "boolean"},
    "object_crushed": {"type": "boolean"},
}, ("t_s", "contact_force_n"))

FORCE_REF = _obj("relaxgrip.ForceSamples",
                 "Reference force sensor readings since the previous period (ground truth).", {
    "t_s": {"type": "array", "items": {"type": "number"}},
    "force_n": {"type": "array", "items": {"type": "number"}},
}, ("t_s", "force_n"))

#: Topic -> JSON Schema, in the order the channels are registered.
CHANNELS: dict[str, dict[str, Any]] = {
    "/relaxgrip/session": SESSION,
    "/rgb": COMPRESSED_IMAGE,
    "/ir": RAW_IMAGE,
    "/relaxgrip/observation": OBSERVATION,
    "/relaxgrip/perception": PERCEPTION,
    "/relaxgrip/estimate": ESTIMATE,
    "/relaxgrip/relaxation": RELAXATION,
    "/relaxgrip/command": COMMAND,
    "/relaxgrip/temperature": TEMPERATURE,
    "/relaxgrip/phase": PHASE,
    "/relaxgrip/events": EVENT,
    "/relaxgrip/truth": TRUTH,
    "/relaxgrip/force_ref": FORCE_REF,
}


def schema_bytes(schema: dict[str, Any]) -> bytes:
    """A schema as the bytes of an MCAP Schema record."""
    return json.dumps(schema, sort_keys=True).encode()
