"""Recordings shared by the recording tests: short holds on the twin (seeded, deterministic)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from relaxgrip.experiments.controlled_hold import HoldResult, run_hold
from relaxgrip.learning.store import ModelBundle
from relaxgrip.learning.training import load_default_models
from relaxgrip.recording import McapRecorder

HOLD_S = 6.0


def copy_recording(src: Path, dst: Path,
                   change: Callable[[str, bytes, int], bytes | None]) -> None:
    """Copy a recording as mcap's own writer lays it out (the schemas and channels in the
    first chunk only), each message's data through ``change(topic, data, log_time_ns)``
    (None: left out)."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        writer = Writer(out)
        writer.start()
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            data = change(channel.topic, message.data, message.log_time)
            if data is None:
                continue
            if channel.id not in channels:
                assert schema is not None
                schemas.setdefault(schema.id, writer.register_schema(
                    schema.name, schema.encoding, schema.data))
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id])
            writer.add_message(channels[channel.id], message.log_time, data,
                               message.publish_time)
        writer.finish()  # type: ignore[no-untyped-call]


def chunk_indexes(path: Path) -> list[Any]:
    """The chunk index a complete MCAP file's summary lists, in file order."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def damage_first_chunk(src: Path, dst: Path, killed: bool = False) -> None:
    """``src`` with a byte of its first chunk's records flipped; ``killed``: cut as a kill
    leaves it too (no summary, no footer)."""
    first = chunk_indexes(src)[0]
    data = bytearray(src.read_bytes())
    data[first.chunk_start_offset + first.chunk_length - 100] ^= 0xFF
    if killed:
        del data[len(data) * 2 // 3:]
    dst.write_bytes(bytes(data))


def record_hold(path: Path, estimator: str, target_n: float, duration_s: float,
                temp_c: float, seed: int, models: ModelBundle, rgb_format: str = "jpeg",
                **hold: Any) -> tuple[Path, HoldResult]:
    """A hold on the twin (:func:`run_hold`, ``hold`` its further arguments), recorded at
    ``path``."""
    with McapRecorder(path, rgb_format=rgb_format) as rec:
        result = run_hold(estimator, target_n, duration_s, temp_c, seed, models, recorder=rec,
                          **hold)
    return path, result


@pytest.fixture(scope="session")
def models() -> ModelBundle:
    return load_default_models()


@pytest.fixture(scope="session")
def relax_hold(tmp_path_factory: pytest.TempPathFactory,
               models: ModelBundle) -> tuple[Path, HoldResult]:
    """A 6 s relax hold at 5 N, 40 °C, recorded with JPEG frames."""
    return record_hold(tmp_path_factory.mktemp("rec") / "relax.mcap", "relax", 5.0, HOLD_S,
                       40.0, 0, models)


@pytest.fixture(scope="session")
def uncalibrated(models: ModelBundle) -> ModelBundle:
    """The shipped models without their closed-loop calibration."""
    return replace(models, hold_bias=None)


@pytest.fixture(scope="session")
def png_relax_hold(tmp_path_factory: pytest.TempPathFactory,
                   uncalibrated: ModelBundle) -> tuple[Path, HoldResult]:
    """An 8 s relax hold at 5 N, 40 °C, uncalibrated, with lossless frames and the object
    located (the closed chain reads from 5 s of the hold on): it replays bit for bit."""
    return record_hold(tmp_path_factory.mktemp("png") / "relax.mcap", "relax", 5.0, 8.0, 40.0,
                       3, uncalibrated, rgb_format="png", locate_object=True)


@pytest.fixture(scope="session")
def fixed_holds(tmp_path_factory: pytest.TempPathFactory, models: ModelBundle) -> list[Path]:
    """Three 6 s fixed-aperture holds (different seeds, targets, temperatures)."""
    folder = tmp_path_factory.mktemp("fixed")
    return [record_hold(folder / f"fixed-{seed}.mcap", "fixed", target, 6.0, temp, seed,
                        models)[0]
            for seed, target, temp in ((0, 5.0, 40.0), (1, 4.0, 45.0), (2, 6.0, 35.0))]
