"""Ctrl-C, ``kill`` and a closed terminal stop a command between writes, never inside one.

The command line turns SIGINT, SIGTERM and SIGHUP into ``KeyboardInterrupt``
(:func:`interrupt`), so that each command's clean-up runs: a recording is
closed with its summary, temporary files go, the heaters are switched off.
Raised inside a writer, though, the interrupt can leave its state behind its
file: MCAP's writer takes a chunk's messages out of its builder, compresses
them and only then writes them, and an interrupt in between loses the chunk
while the summary still counts its messages.  A block that must not be cut
runs under :func:`deferred`; a signal that comes during it stops the command
as the block ends.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["deferred", "interrupt"]

_depth = 0
_pending = False


def interrupt(signum: int, frame: FrameType | None) -> None:
    """A signal handler that stops the command as Ctrl-C does: its clean-up runs.

    At once, or inside :func:`deferred`, as the block ends.
    """
    global _pending
    if _depth:
        _pending = True
        return
    raise KeyboardInterrupt


@contextmanager
def deferred() -> Iterator[None]:
    """A block that :func:`interrupt` does not cut; it raises ``KeyboardInterrupt`` at its
    end if a signal came during it.

    Only the main thread gets signals: in another thread the block runs as it is.
    """
    global _depth, _pending
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
    if _depth == 0 and _pending:
        _pending = False
        raise KeyboardInterrupt
