"""The options every twin command shares to say which gripper its twin is.

``--rig RIG.toml`` runs the twin of that rig (:mod:`relaxgrip.hardware.rig_twin`);
without it, the twin is our gripper (``docs/rigs/relaxgrip.toml``, the twin's
defaults).  Commands declare ``rig: RigOption = None`` and build their twin
with :func:`twin_config`, so a further option on the same commands goes here.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

if TYPE_CHECKING:
    from relaxgrip.twin import TwinConfig

__all__ = ["MaterialOption", "RigOption", "twin_config"]

RigOption = Annotated[Path | None, typer.Option(
    "--rig", help="Rig file whose twin runs (docs/rig-file.md; default: our gripper, "
                  "docs/rigs/relaxgrip.toml).", show_default=False)]


MaterialOption = Annotated[Path | None, typer.Option(
    "--material", metavar="FILE.json", help="Material file (relaxgrip fit-material --out) "
    "whose SMP the twin's fingers are made of (docs/material.md; default: the rig's).",
    show_default=False)]


def twin_config(rig: Path | None, base: TwinConfig | None = None,
                material: Path | None = None) -> TwinConfig:
    """The twin a command runs: of the ``--rig`` file, or our gripper.

    Parameters
    ----------
    rig : Path or None
        ``--rig``.
    base : TwinConfig, optional
        The twin-only settings to start from (default: ``TwinConfig()``).
    material : Path or None
        ``--material``: the SMP and its branches from this material file,
        over the rig's own (:meth:`TwinConfig.with_material`).

    Raises
    ------
    InputError
        A rig file that is unreadable or has a bad field (one line naming it).
    """
    from relaxgrip.hardware.rig_twin import load_twin_config

    config = load_twin_config(rig, base)
    if material is not None:
        from relaxgrip.hardware.material_file import load_material_file

        config = config.with_material(load_material_file(material))
    return config
