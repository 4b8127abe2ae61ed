"""A signal stops a command between writes, never inside one (relaxgrip.interrupts)."""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator

import pytest

from relaxgrip.interrupts import STOP_SIGNALS, deferred, interrupt, stop_signals


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


@pytest.fixture
def hup_ignored() -> Iterator[None]:
    """SIGHUP ignored, as under ``nohup``, SIGINT and SIGTERM not (a test run started with
    ``&`` ignores SIGINT); every stop signal's handler back afterwards."""
    previous = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    yield
    for sig, handler in previous.items():
        signal.signal(sig, handler)


def test_stop_signals_stop_the_block_and_are_put_back(hup_ignored: None) -> None:
    before = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    with stop_signals() as caught:
        assert caught == (signal.SIGINT, signal.SIGTERM)  # SIGHUP stays ignored
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
    assert {sig: signal.getsignal(sig) for sig in STOP_SIGNALS} == before


def test_stop_signals_take_an_ignored_one_when_asked(hup_ignored: None) -> None:
    with stop_signals(even_if_ignored=(signal.SIGHUP,)) as caught:
        assert signal.SIGHUP in caught
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGHUP)
    assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN


def test_stop_signals_off_the_main_thread_set_nothing() -> None:
    seen: list[tuple[int, ...]] = []

    def run() -> None:
        with stop_signals() as caught:
            seen.append(caught)

    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    assert seen == [()]
