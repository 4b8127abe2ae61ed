"""relaxgrip: a variable-stiffness soft gripper with relaxation-aware force sensing.

Layers (imports flow one way, top to bottom never up)::

    physics -> twin / hardware -> perception -> learning -> control
            -> experiments -> plots / dashboard / cli

``relaxgrip.physics`` holds pure functions of arrays in SI units;
``relaxgrip.twin`` composes them into a stepped, seeded digital twin that
implements the :class:`relaxgrip.backend.Gripper` protocol.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("relaxgrip")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
