"""Ctrl-C, ``kill`` and a closed terminal stop a command between writes, never inside one.

The command line turns SIGINT, SIGTERM and SIGHUP into ``KeyboardInterrupt``
(:func:`interrupt`), so that each command's clean-up runs: a recording is
closed with its summary, temporary files go, the heaters are switched off.
Raised inside a writer, though, the interrupt can leave its state behind its
file: MCAP's writer takes a chunk's messages out of its builder, compresses
them and only then writes them, and an interrupt in between loses the chunk
while the summary still counts its messages.  A block that must not be cut
runs under :func:`deferred`; a signal that comes during it stops the command
as the block ends.  :func:`stop_signals` sets the handlers for a block.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["STOP_SIGNALS", "deferred", "interrupt", "stop_signals"]

#: Signals that stop a command as Ctrl-C does: Ctrl-C, ``kill`` and a closed terminal.
#: SIGINT too: Python's own handler raises at once, inside a record half written.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

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


@contextmanager
def stop_signals(even_if_ignored: Collection[int] = ()) -> Iterator[tuple[int, ...]]:
    """A block in which :data:`STOP_SIGNALS` stop the command through :func:`interrupt`.

    A signal the process ignores stays ignored (``nohup`` ignores SIGHUP, and
    that stays), unless it is in ``even_if_ignored`` (a shell's ``&`` starts a
    command with SIGINT ignored).  The block gets the signals it set: a
    clean-up may ignore them so that a second one does not cut it short.  The
    handlers before it are back as it ends.  Only the main thread can set
    handlers: in another thread none are set, and the block gets none.
    """
    if threading.current_thread() is not threading.main_thread():
        yield ()
        return
    previous = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    caught = tuple(sig for sig, handler in previous.items()
                   if handler is not signal.SIG_IGN or sig in even_if_ignored)
    for sig in caught:
        signal.signal(sig, interrupt)
    try:
        yield caught
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
