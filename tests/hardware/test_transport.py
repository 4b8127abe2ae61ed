"""Transports: in-memory link, a real pseudo-terminal through pyserial, and the optional extra."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import threading
import tty
from collections.abc import Iterator

import pytest

from relaxgrip.clock import VirtualClock, WallClock
from relaxgrip.hardware.protocol import (
    FdTransport,
    LinkError,
    McuClient,
    McuEndpoint,
    MemoryLink,
    SerialTransport,
    Transport,
)


def test_memory_link_moves_bytes_both_ways_and_waits_on_its_clock() -> None:
    clock = VirtualClock()
    link = MemoryLink(clock)
    assert isinstance(link.host, Transport)
    link.host.write(b"abc")
    link.host.write(b"def")
    assert link.device.read(0.0) == b"abcdef"
    assert link.device.read(0.0) == b""
    assert clock.now() == 0.0
    assert link.device.read(0.05) == b""
    assert clock.now() == pytest.approx(0.05)
    link.device.write(b"\x00\x01")
    assert link.host.read(1.0) == b"\x00\x01"
    assert clock.now() == pytest.approx(0.05)  # data was there: no wait


def test_memory_link_cut_and_close() -> None:
    link = MemoryLink(VirtualClock())
    link.cut()
    link.host.write(b"lost")
    link.restore()
    assert link.device.read(0.0) == b""
    link.host.close()
    with pytest.raises(LinkError, match="write on closed in-memory transport 'host'"):
        link.host.write(b"x")


@pytest.fixture
def pty_pair() -> Iterator[tuple[int, str]]:
    master, slave = os.openpty()
    tty.setraw(master)
    path = os.ttyname(slave)
    yield master, path
    os.close(master)
    os.close(slave)


def test_client_talks_to_mcu_thread_over_a_real_pty(pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    clock = WallClock()
    mcu = McuEndpoint(FdTransport(master), clock)
    stop = threading.Event()
    thread = threading.Thread(target=mcu.serve, args=(stop,), daemon=True)
    thread.start()
    host = SerialTransport(path)
    try:
        client = McuClient(host, clock, reply_timeout_s=0.5)
        ack = client.handshake()
        assert ack.firmware_id == "relaxgrip-emu 1"
        assert client.set_enabled(True).enabled
        for _ in range(10):
            st = client.command(3.0, (0.5, 0.0))
            assert st.velocity_mm_s == 3.0
            assert st.heater_duty == (0.5, 0.0)
        assert client.stats.decode_errors == 0
        assert client.stats.frames_received == client.stats.frames_sent == 12
        client.set_enabled(False)
    finally:
        stop.set()
        thread.join(timeout=2.0)
        host.close()
    assert not thread.is_alive()
    assert mcu.core.outputs.velocity_um_s == 0


def test_serial_transport_on_a_pty_reads_with_timeout(pty_pair: tuple[int, str]) -> None:
    master, path = pty_pair
    port = SerialTransport(path)
    try:
        assert port.read(0.01) == b""
        os.write(master, b"\x00hello\x00")
        data = b""
        for _ in range(50):
            data += port.read(0.05)
            if len(data) == 7:
                break
        assert data == b"\x00hello\x00"
        port.write(b"\x01\x02")
        assert FdTransport(master).read(1.0) == b"\x01\x02"
    finally:
        port.close()


def test_serial_transport_bad_port_is_one_line() -> None:
    with pytest.raises(LinkError, match="cannot open serial port /nonexistent/tty"):
        SerialTransport("/nonexistent/tty")
    with pytest.raises(LinkError, match="embedded null byte"):
        SerialTransport("/dev/tty\x00S0")


def test_a_serial_port_in_use_is_refused_with_one_line(pty_pair: tuple[int, str]) -> None:
    """A second host on the port (check-rig during a hold) would reset the session with its
    Hello: the port is locked while open."""
    _, path = pty_pair
    first = SerialTransport(path)
    try:
        with pytest.raises(LinkError) as info:
            SerialTransport(path)
    finally:
        first.close()
    assert str(info.value) == (f"serial port {path} is in use by another process (a running "
                               "host, check-rig or a dashboard): stop it first")
    SerialTransport(path).close()  # free again once closed


def test_a_write_does_not_wait_for_the_line_to_drain(pty_pair: tuple[int, str],
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """tcdrain has no timeout: a device that stopped reading would hold the host for ever."""
    import termios

    master, path = pty_pair

    def stuck(fd: int) -> None:
        raise AssertionError("the write waited for the line to drain")

    monkeypatch.setattr(termios, "tcdrain", stuck)
    port = SerialTransport(path)
    try:
        port.write(b"\x01\x02\x00")
        assert os.read(master, 16) == b"\x01\x02\x00"
    finally:
        port.close()


def test_a_full_non_blocking_descriptor_drops_and_counts_instead_of_waiting(
        pty_pair: tuple[int, str]) -> None:
    """As a UART overflows its TX buffer: the writer (the MCU loop) never waits."""
    master, _ = pty_pair
    os.set_blocking(master, False)
    fd = FdTransport(master)
    frame = bytes(range(1, 33)) + b"\x00"
    for _ in range(100_000):  # the slave side is never read: its buffer fills
        fd.write(frame)
        if fd.tx_overflows:
            break
    assert fd.tx_overflows == 1
    assert 0 < fd.tx_dropped_bytes <= len(frame)


def test_core_imports_without_pyserial_and_says_how_to_install() -> None:
    code = (
        "import sys; sys.modules['serial'] = None\n"
        "import relaxgrip.hardware.protocol as p\n"
        "try:\n"
        "    p.SerialTransport('/dev/null')\n"
        "except p.DependencyNotInstalledError as e:\n"
        "    print(e)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    assert "pip install 'relaxgrip[hardware]'" in out


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0,
                    reason="opens the port as another user: needs root to switch to one")
def test_the_kernel_refuses_other_programs_the_open_port(pty_pair: tuple[int, str]) -> None:
    """pyserial's flock binds only programs that ask for it: a serial monitor (screen,
    minicom) or an older relaxgrip opened the port beside a running hold.  The terminal's
    exclusive mode makes the kernel refuse them (a superuser excepted)."""
    _, path = pty_pair
    os.chmod(path, 0o666)

    def open_as_nobody() -> int:
        """0 if a user without privileges opens the port, else the errno."""
        pid = os.fork()
        if pid == 0:  # pragma: no cover  (the child)
            code = 0
            try:
                os.setuid(65534)
                os.close(os.open(path, os.O_RDWR | os.O_NOCTTY))
            except OSError as exc:
                code = exc.errno or 1
            os._exit(code)
        return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])

    assert open_as_nobody() == 0
    port = SerialTransport(path)
    try:
        assert open_as_nobody() == errno.EBUSY
    finally:
        port.close()
    assert open_as_nobody() == 0  # free again once closed
