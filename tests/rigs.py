"""The two example rigs the end-to-end tests run on: ours and another lab's.

``ours`` is ``docs/rigs/relaxgrip.toml`` (the twin's defaults); ``lab`` is
``docs/rigs/lab-125mm.toml``: a longer, stiffer finger of another SMP, another
marker, cameras and placement, the marker on finger 1.  Tests take ``rig`` from
:data:`RIGS` and build its twin with :func:`twin_of`.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

from relaxgrip.hardware.rig_twin import load_twin_config
from relaxgrip.twin import TwinConfig

DOCS = Path(__file__).resolve().parents[1] / "docs"
RIG_FILES = {"ours": DOCS / "rigs" / "relaxgrip.toml", "lab": DOCS / "rigs" / "lab-125mm.toml"}
#: Rig names, for ``pytest.mark.parametrize("rig", RIGS)``.
RIGS = tuple(RIG_FILES)


@cache
def twin_of(rig: str) -> TwinConfig:
    """The twin of an example rig (frozen, shared)."""
    return load_twin_config(RIG_FILES[rig])
