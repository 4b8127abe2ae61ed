"""Round trip of a recorded hold: every channel back, schemas valid, frames decode, times right."""

from __future__ import annotations

import json
import math
from collections import defaultdict
from itertools import islice
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
from mcap.reader import make_reader

from relaxgrip.experiments.controlled_hold import HoldResult
from relaxgrip.recording import CHANNELS, iter_messages, iter_periods, read_session
from relaxgrip.recording.reader import decode_ir, decode_rgb


def _by_topic(path: Path) -> dict[str, list[tuple[int, dict[str, Any]]]]:
    out: dict[str, list[tuple[int, dict[str, Any]]]] = defaultdict(list)
    for topic, log_ns, message in iter_messages(path):
        out[topic].append((log_ns, message))
    return out


def test_every_channel_round_trips(relax_hold: tuple[Path, HoldResult]) -> None:
    path, result = relax_hold
    loop = result.loop
    topics = _by_topic(path)
    # The twin has truth and a force ball: every channel carries messages.
    assert set(topics) == set(CHANNELS)
    n = loop["t_s"].size
    for topic in ("/relaxgrip/observation", "/relaxgrip/estimate", "/relaxgrip/command",
                  "/relaxgrip/phase", "/relaxgrip/temperature", "/relaxgrip/truth"):
        assert len(topics[topic]) == n, topic
    est = topics["/relaxgrip/estimate"]
    t = np.array([m["t_s"] for _, m in est])
    np.testing.assert_array_equal(t, loop["t_s"])
    assert [ns for ns, _ in est] == [round(v * 1e9) for v in loop["t_s"]]
    rec = np.array([np.nan if m["force_n"] is None else m["force_n"] for _, m in est])
    np.testing.assert_array_equal(rec, loop["estimate_n"])
    cmd = np.array([m["motor_velocity_mm_s"] for _, m in topics["/relaxgrip/command"]])
    np.testing.assert_array_equal(cmd, loop["velocity_cmd_mm_s"])
    truth = np.array([m["contact_force_n"] for _, m in topics["/relaxgrip/truth"]])
    np.testing.assert_array_equal(truth, loop["truth_force_n"])
    session = read_session(path)
    assert session["estimator"] == "relax"
    assert session["backend"]["version"] == result.twin_version
    assert session["plan"]["target_n"] == 5.0
    onsets = [m for _, m in topics["/relaxgrip/events"] if m["kind"] == "hold_onset"]
    assert len(onsets) == 1
    assert math.isclose(onsets[0]["t_s"], loop.hold_onset_s() or -1.0, abs_tol=1e-9)
    phases = [m["detail"] for _, m in topics["/relaxgrip/events"] if m["kind"] == "phase"]
    assert phases == [p.value for _, p in loop.log.transitions]
    relax = topics["/relaxgrip/relaxation"]
    assert relax
    assert all(m["hold_s"] is not None for _, m in relax)
    assert any(m["k_n"] is not None and m["tau_s"] is not None for _, m in relax)


def test_schemas_are_json_schema_and_messages_conform(relax_hold: tuple[Path, HoldResult]) -> None:
    path, _ = relax_hold
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        stored = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        assert sum(counts.values()) > 0
    assert set(stored) == set(CHANNELS)
    for topic, schema in stored.items():
        assert schema.encoding == "jsonschema"
        doc = json.loads(schema.data)
        jsonschema.Draft202012Validator.check_schema(doc)
        assert schema.name == doc["title"] == CHANNELS[topic]["title"]
    assert stored["/rgb"].name == "foxglove.CompressedImage"
    assert stored["/ir"].name == "foxglove.RawImage"
    validators = {t: jsonschema.Draft202012Validator(json.loads(s.data)) for t, s in stored.items()}
    seen: dict[str, int] = defaultdict(int)
    for topic, _, message in iter_messages(path):
        if seen[topic] < 40:  # a sample of each channel (the frames are large)
            validators[topic].validate(message)
            seen[topic] += 1
    # A message that breaks a schema is caught: the validators are not vacuous.
    bad = {"t_s": 0.0, "motor_velocity_mm_s": "fast", "heater_duty": [0.0, 0.0]}
    assert not validators["/relaxgrip/command"].is_valid(bad)


def test_frames_decode_to_their_shapes(relax_hold: tuple[Path, HoldResult]) -> None:
    path, result = relax_hold
    topics = _by_topic(path)
    rgb = decode_rgb(topics["/rgb"][0][1])
    assert rgb.shape == (480, 640, 3)
    assert rgb.dtype == np.uint8
    ir_msg = topics["/ir"][0][1]
    ir = decode_ir(ir_msg)
    assert ir.shape == (ir_msg["height"], ir_msg["width"]) == (192, 256)
    assert ir.dtype == np.float32
    assert ir_msg["step"] == 4 * ir_msg["width"]
    assert 15.0 < float(np.median(ir)) < 70.0  # temperatures in °C
    # One RGB frame per period at 30 Hz, one IR frame per second (new frames only).
    n = result.loop["t_s"].size
    assert len(topics["/rgb"]) == n
    duration = result.loop["t_s"][-1] - result.loop["t_s"][0]
    assert abs(len(topics["/ir"]) - duration) <= 2
    periods = list(islice(iter_periods(path), 90))
    assert [p.t_s for p in periods] == list(result.loop["t_s"][:90])
    assert all(p.rgb is not None and p.ir is not None for p in periods[31:])
    assert len({p.rgb.seq for p in periods if p.rgb is not None}) == 90
