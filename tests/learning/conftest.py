"""Fixtures of the learning tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from relaxgrip.learning.build import build_dataset
from relaxgrip.learning.datasets import DatasetSpec
from tests.rigs import twin_of

#: Four 10-s holds (the repeatability ones, at 40, 50, 60 and 40 °C, all test) and two
#: ICFN episodes: seconds to build.
TINY = DatasetSpec(icfn_samples=40, rcfn_sequences=4, hold_s=10.0, seed=1)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A dataset of :data:`TINY`, built once per test module."""
    out = tmp_path_factory.mktemp("data") / "tiny"
    build_dataset(out, TINY, jobs=2)
    return out


@pytest.fixture(scope="module")
def lab_tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """:data:`TINY` on the twin of the second example rig (``docs/rigs/lab-125mm.toml``)."""
    out = tmp_path_factory.mktemp("data") / "lab-tiny"
    build_dataset(out, TINY, jobs=2, config=twin_of("lab"))
    return out
