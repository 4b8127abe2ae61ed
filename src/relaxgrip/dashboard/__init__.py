"""The live web dashboard (the paper's user interface): ``relaxgrip dashboard``.

:mod:`relaxgrip.dashboard.session` runs a backend through the grasp
controller in a background thread; :mod:`relaxgrip.dashboard.render` draws
the frames; :mod:`relaxgrip.dashboard.app` serves the page and the WebSocket
(FastAPI, from the ``dashboard`` extra).  This package imports without the
web stack; :func:`require_web_stack` says how to install it.
"""

from __future__ import annotations

from relaxgrip.errors import InputError

__all__ = ["require_web_stack"]


def require_web_stack() -> None:
    """Raise a helpful :class:`~relaxgrip.errors.InputError` if the web stack is missing."""
    missing = []
    for name in ("fastapi", "uvicorn", "websockets"):
        try:
            __import__(name)
        except ImportError:
            missing.append(name)
    if missing:
        raise InputError(f"the dashboard needs {' and '.join(missing)}: "
                         "pip install 'relaxgrip[dashboard]'")
