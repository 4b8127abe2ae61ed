"""Byte transports under the MCU protocol: in-memory (the test default), file descriptor, serial.

A transport moves bytes and knows nothing of frames.  :class:`MemoryLink`
is a null modem between two :class:`MemoryTransport` ends that waits on an
injected clock, so a whole host <-> MCU exchange runs deterministically in
virtual time; it can also drop or corrupt bytes on purpose.
:class:`SerialTransport` wraps :class:`serial.Serial` (a USB-serial adapter
or a pseudo-terminal path) and needs the ``hardware`` extra;
:class:`FdTransport` serves the master side of a pseudo-terminal.
"""

from __future__ import annotations

import errno
import os
import select
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from relaxgrip.clock import Clock, WallClock
from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol.errors import DependencyNotInstalledError, LinkError

if TYPE_CHECKING:
    import serial

__all__ = [
    "FdTransport",
    "MemoryLink",
    "MemoryTransport",
    "SerialTransport",
    "Transport",
    "import_serial",
]


@runtime_checkable
class Transport(Protocol):
    """A bidirectional byte stream."""

    def write(self, data: bytes) -> None:
        """Send ``data`` (all of it)."""
        ...

    def read(self, timeout_s: float) -> bytes:
        """Bytes available, waiting up to ``timeout_s`` for the first (``b""`` if none)."""
        ...

    def close(self) -> None:
        """Release the link; further use is an error."""
        ...


def _check_timeout(timeout_s: float) -> float:
    t = float(timeout_s)
    if not t >= 0.0:
        raise InputError(f"timeout_s must be >= 0, got {timeout_s}")
    return t


# --------------------------------------------------------------------------- in memory


class MemoryTransport:
    """One end of a :class:`MemoryLink`; build it through the link."""

    def __init__(self, link: MemoryLink, name: str) -> None:
        self._link = link
        self.name = name
        self._rx = bytearray()
        self._closed = False
        self._service: Callable[[], None] | None = None
        self.peer: MemoryTransport | None = None
        self.tamper: Callable[[bytes], bytes] | None = None
        """Applied to every write from this end (corruption injection)."""

    def set_service(self, service: Callable[[], None] | None) -> None:
        """Run ``service`` whenever this end waits for bytes.

        In a single thread this lets the peer (e.g. an MCU emulator's
        ``poll``) answer while the host waits, in virtual time.
        """
        self._service = service

    def write(self, data: bytes) -> None:
        """Send ``data`` to the peer (dropped while the link is cut)."""
        if self._closed:
            raise LinkError(f"write on closed in-memory transport {self.name!r}")
        peer = self.peer
        if peer is None or self._link.is_cut:
            return
        payload = bytes(data)
        if self.tamper is not None:
            payload = self.tamper(payload)
        with self._link.lock:
            peer._rx += payload

    def _take(self) -> bytes:
        with self._link.lock:
            data = bytes(self._rx)
            self._rx.clear()
        return data

    def read(self, timeout_s: float) -> bytes:
        """Bytes received, waiting on the link's clock up to ``timeout_s`` for the first.

        Parameters
        ----------
        timeout_s : float
            Longest wait (s); 0 polls.

        Returns
        -------
        bytes
            Everything received so far, ``b""`` on timeout.
        """
        if self._closed:
            raise LinkError(f"read on closed in-memory transport {self.name!r}")
        timeout = _check_timeout(timeout_s)
        clock = self._link.clock
        deadline = clock.now() + timeout
        while True:
            if self._service is not None:
                self._service()
            data = self._take()
            if data:
                return data
            now = clock.now()
            if now >= deadline:
                return b""
            clock.sleep_until(min(deadline, now + self._link.poll_step_s))

    def close(self) -> None:
        """Close this end (the peer sees silence)."""
        self._closed = True

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` was called."""
        return self._closed


class MemoryLink:
    """Null modem between two in-memory ends, ``host`` and ``device``.

    Parameters
    ----------
    clock : Clock or None
        Clock the ends wait on; a :class:`~relaxgrip.clock.VirtualClock`
        makes waits instant and deterministic.  Default: wall clock.
    poll_step_s : float
        Granularity of waits (s).
    """

    def __init__(self, clock: Clock | None = None, poll_step_s: float = 0.001) -> None:
        self.clock: Clock = clock if clock is not None else WallClock()
        self.poll_step_s = _check_timeout(poll_step_s)
        if self.poll_step_s == 0.0:
            raise InputError("poll_step_s must be > 0")
        self.lock = threading.Lock()
        self.is_cut = False
        self.host = MemoryTransport(self, "host")
        self.device = MemoryTransport(self, "device")
        self.host.peer = self.device
        self.device.peer = self.host

    def cut(self) -> None:
        """Unplug the cable: bytes written from now on are lost both ways."""
        self.is_cut = True

    def restore(self) -> None:
        """Plug the cable back in."""
        self.is_cut = False


# --------------------------------------------------------------------------- file descriptor


class FdTransport:
    """Transport over a raw file descriptor (the master side of a pseudo-terminal).

    On a non-blocking descriptor (the MCU emulator's) :meth:`write` never
    waits: what does not fit the full buffer of a peer that stops reading is
    dropped and counted, as a UART drops what overflows its TX FIFO, so the
    writer (the MCU loop and its watchdog) goes on.

    Parameters
    ----------
    fd : int
        An open descriptor, e.g. from :func:`os.openpty` after ``tty.setraw``.
    close_fd : bool
        Close ``fd`` in :meth:`close`.

    Attributes
    ----------
    tx_overflows : int
        Writes cut short by a full buffer (non-blocking descriptors only).
    tx_dropped_bytes : int
        Bytes those writes dropped.
    """

    def __init__(self, fd: int, close_fd: bool = False) -> None:
        self.fd = fd
        self._close_fd = close_fd
        self._closed = False
        self.tx_overflows = 0
        self.tx_dropped_bytes = 0

    def write(self, data: bytes) -> None:
        """Write all of ``data`` (on a non-blocking descriptor: what fits; see the class)."""
        if self._closed:
            raise LinkError(f"write on closed fd transport {self.fd}")
        view = memoryview(bytes(data))
        while view:
            try:
                n = os.write(self.fd, view)
            except BlockingIOError:
                self.tx_overflows += 1
                self.tx_dropped_bytes += len(view)
                return
            view = view[n:]

    def read(self, timeout_s: float) -> bytes:
        """Bytes available, waiting up to ``timeout_s`` (wall clock) for the first."""
        if self._closed:
            raise LinkError(f"read on closed fd transport {self.fd}")
        ready, _, _ = select.select([self.fd], [], [], _check_timeout(timeout_s))
        if not ready:
            return b""
        try:
            return os.read(self.fd, 4096)
        except BlockingIOError:  # a non-blocking descriptor that select() woke spuriously
            return b""
        except OSError as exc:  # EIO once the slave side is closed
            raise LinkError(f"read on fd {self.fd} failed: {exc}") from exc

    def close(self) -> None:
        """Stop using the descriptor (and close it if owned)."""
        if not self._closed and self._close_fd:
            os.close(self.fd)
        self._closed = True


# --------------------------------------------------------------------------- serial


def import_serial() -> Any:
    """Import pyserial, or say how to install it.

    Returns
    -------
    module
        The ``serial`` module.

    Raises
    ------
    DependencyNotInstalledError
        If pyserial is missing.
    """
    try:
        import serial
    except ImportError as exc:
        raise DependencyNotInstalledError(
            "the serial transport needs pyserial: pip install 'relaxgrip[hardware]'"
        ) from exc
    return serial


def _termios_request(name: str) -> int | None:
    """A terminal ioctl request by name, None where the platform has none."""
    import termios

    value = getattr(termios, name, None)
    return value if isinstance(value, int) else None


def _set_exclusive(port: serial.Serial, request: int | None) -> bool:
    """Issue ``TIOCEXCL`` or ``TIOCNXCL`` on an open port; whether it took (a device that is
    not a terminal, or a platform without them, keeps the flock alone)."""
    if request is None:
        return False
    import fcntl

    try:
        fcntl.ioctl(port.fileno(), request)
    except (OSError, ValueError):
        return False
    return True


class SerialTransport:
    """Transport over a serial port (or a pseudo-terminal path) through pyserial.

    Parameters
    ----------
    port : str
        Device path, e.g. ``/dev/ttyACM0`` or ``os.ttyname(slave_fd)``.
    baudrate : int
        Line speed (bit/s); ignored by USB CDC devices and pseudo-terminals.

    Raises
    ------
    LinkError
        If the port cannot be opened, or another process has it open (the
        port is locked for as long as it is open: a second host's Hello would
        reset the running session).

    Notes
    -----
    The lock is pyserial's ``flock``, which every relaxgrip honours, and the
    terminal's exclusive mode (``TIOCEXCL``), which makes the kernel refuse
    anyone else's open of the device (``EBUSY``; ``screen``, a serial
    monitor, an older relaxgrip) except a superuser's.
    """

    def __init__(self, port: str, baudrate: int = 115_200) -> None:
        serial_mod = import_serial()
        try:
            self._serial: serial.Serial = serial_mod.Serial(
                port, baudrate=baudrate, timeout=0.0, write_timeout=1.0, exclusive=True
            )
        except serial_mod.SerialException as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK):  # the flock is taken
                raise LinkError(f"serial port {port} is in use by another process (a running "
                                "host, check-rig or a dashboard): stop it first") from exc
            raise LinkError(f"cannot open serial port {port}: {exc}") from exc
        except (OSError, ValueError) as exc:  # e.g. a NUL byte in the path
            raise LinkError(f"cannot open serial port {port!r}: {exc}") from exc
        self._exclusive = _set_exclusive(self._serial, _termios_request("TIOCEXCL"))
        self._timeout: float | None = 0.0
        self.port = port

    def write(self, data: bytes) -> None:
        """Write all of ``data`` to the port's driver (within the 1 s write timeout).

        It does not wait for the bytes to leave the wire (``tcdrain``, which has
        no timeout: a USB device that stopped reading would hold the host there
        for ever, its loop stuck between two periods).
        """
        self._serial.write(bytes(data))

    def read(self, timeout_s: float) -> bytes:
        """Bytes available, waiting up to ``timeout_s`` (wall clock) for the first."""
        timeout = _check_timeout(timeout_s)
        if self._timeout != timeout:  # changing it reconfigures the port: only when needed
            self._serial.timeout = timeout
            self._timeout = timeout
        first = self._serial.read(1)
        if not first:
            return b""
        waiting = self._serial.in_waiting
        return first + (self._serial.read(waiting) if waiting else b"")

    def close(self) -> None:
        """Leave the exclusive mode (it outlives the descriptor while another holds the
        device open) and close the port."""
        if self._exclusive and self._serial.is_open:
            _set_exclusive(self._serial, _termios_request("TIOCNXCL"))
        self._serial.close()
