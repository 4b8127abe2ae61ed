"""A signal stops a command between writes, never inside one (relaxgrip.interrupts)."""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator

import pytest

from relaxgrip.interrupts import deferred, interrupt


@pytest.fixture
def terminating() -> Iterator[None]:
    previous = signal.signal(signal.SIGTERM, interrupt)
    yield
    signal.signal(signal.SIGTERM, previous)


def test_a_signal_outside_a_deferred_block_stops_at_once(terminating: None) -> None:
    with pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGTERM)  # the handler runs as the call returns


def test_a_signal_inside_a_deferred_block_stops_as_it_ends(terminating: None) -> None:
    done = []

    def nested() -> None:
        with deferred():
            with deferred():  # nested: the outermost block's end raises
                os.kill(os.getpid(), signal.SIGTERM)
                done.append("inner")
            done.append("outer")

    with pytest.raises(KeyboardInterrupt):
        nested()
    assert done == ["inner", "outer"]
    with deferred():  # nothing pending any more
        pass


def test_a_deferred_block_off_the_main_thread_runs_as_it_is() -> None:
    ran = []

    def work() -> None:
        with deferred():
            ran.append(threading.current_thread().name)

    thread = threading.Thread(target=work, name="loop")
    thread.start()
    thread.join()
    assert ran == ["loop"]
