"""The MCU emulator: the digital twin behind a pseudo-terminal, speaking the MCU protocol.

:class:`McuEmulator` runs :class:`~relaxgrip.hardware.protocol.McuEndpoint`
(the firmware's state machine, watchdog included) on the master side of a
pseudo-terminal, with a :class:`TwinPlant` (a
:class:`~relaxgrip.twin.GripperTwin`) as its motor, encoder and heaters.  The
host opens the slave side like any serial port.  The twin's RGB and infrared
frames (and its truth) go out on the frame channel
(:mod:`relaxgrip.hardware.frame_channel`), a Unix socket.

Timing (``docs/emulator.md``): in **wall-clock** mode (``relaxgrip
emulator``) the emulator runs on its own clock like the real MCU.  In
**lockstep** (in process, :func:`open_emulated_gripper`) the emulator and the
host share one :class:`~relaxgrip.clock.VirtualClock`: the emulator handles
each host frame at the host's current virtual time and the host's loop alone
moves time, so a 280 s hold runs as fast as the CPU allows and sees exactly
what the twin backend would.
"""

from __future__ import annotations

import collections
import contextlib
import fcntl
import os
import socket
import stat
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from relaxgrip.backend import Command, Frame, Truth
from relaxgrip.clock import Clock, VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.hardware.cameras import EmulatorChannel, EmulatorFrameSource
from relaxgrip.hardware.force_ref import LinearCalibration, McuLoadCell
from relaxgrip.hardware.frame_channel import (
    KIND_IR,
    KIND_RGB,
    encode_frame_message,
    encode_tick,
)
from relaxgrip.hardware.gripper import GuardedTransport, SerialGripper
from relaxgrip.hardware.hx711 import Hx711Config, Hx711Model
from relaxgrip.hardware.protocol.client import McuClient
from relaxgrip.hardware.protocol.mcu import AppliedOutputs, McuConfig, McuCore, McuEndpoint
from relaxgrip.hardware.protocol.transport import FdTransport, SerialTransport
from relaxgrip.limits import OUR_LIMITS
from relaxgrip.twin import TWIN_VERSION, GripperTwin, TwinConfig
from relaxgrip.twin.objects import get_object

if TYPE_CHECKING:
    from relaxgrip.hardware.firmware_emulator import FirmwareEndpoint

__all__ = [
    "DEFAULT_LOAD_CELL",
    "EMULATOR_DIR",
    "FramePublisher",
    "McuEmulator",
    "TwinPlant",
    "check_parent_dir",
    "load_cell_force_n",
    "load_cell_model",
    "open_emulated_gripper",
    "ready_emulated_gripper",
]

#: Messages that may wait for a slow wall-clock host (a third of a second of RGB
#: frames and ticks; at most about 15 MB of frames).
_HOST_QUEUE = 16
#: The ``/proc/net/unix`` flag of a listening socket.
_SO_ACCEPTCON = 0x10000
#: Longest Unix socket path Linux takes (``sun_path`` is 108 bytes with its NUL).
_MAX_SOCKET_PATH = 107
#: The folder of the default link and socket (``docs/rig-emulator.toml``): the only folder
#: ``relaxgrip emulator`` makes (and removes), so that it runs with no rig file; any other
#: folder must exist already (a typo in a rig file must not grow a tree of folders).
EMULATOR_DIR = Path("/tmp/relaxgrip-emulator")
#: The emulator's load cell: a 2 kg bar cell at 10 SPS (:class:`Hx711Config`'s defaults).
DEFAULT_LOAD_CELL = Hx711Config()


def check_parent_dir(path: Path, what: str) -> None:
    """Refuse ``path`` (a link or socket to make) if its folder is missing.

    Raises
    ------
    InputError
        Naming ``what`` (``[serial] port``) and the folder.
    """
    parent = path.parent
    if parent.is_dir():
        return
    if os.path.lexists(parent):
        raise InputError(f"{what} {path}: {parent} is not a directory")
    raise InputError(f"{what} {path}: directory {parent} does not exist")


class _QueuedSender:
    """Sends whole messages to one host from a thread of its own.

    :meth:`put` never waits: when ``depth`` messages are already queued the
    new one is dropped whole (a camera that the host does not read drops
    frames), so the byte stream stays framed.  A send that fails or times
    out marks the sender dead and closes the socket.
    """

    def __init__(self, client: socket.socket, depth: int) -> None:
        self.client = client
        self.depth = depth
        self.dead = False
        self._queue: collections.deque[bytes] = collections.deque()
        self._ready = threading.Condition()
        self._closing = False
        self._thread = threading.Thread(target=self._run, name="frame-channel-send",
                                        daemon=True)
        self._thread.start()

    def put(self, data: bytes) -> bool:
        """Queue ``data``; False if it was dropped (queue full, or the host is gone)."""
        with self._ready:
            if self.dead or self._closing or len(self._queue) >= self.depth:
                return False
            self._queue.append(data)
            self._ready.notify()
            return True

    def _run(self) -> None:
        while True:
            with self._ready:
                while not self._queue and not self._closing:
                    self._ready.wait()
                if self._closing:
                    return
                data = self._queue.popleft()
            try:
                self.client.sendall(data)
            except OSError:
                with self._ready:
                    self.dead = True
                    self._queue.clear()
                self.client.close()
                return

    def close(self) -> None:
        """Stop sending and close the socket (what is queued is dropped)."""
        with self._ready:
            self._closing = True
            self._queue.clear()
            self._ready.notify()
        with contextlib.suppress(OSError):
            self.client.shutdown(socket.SHUT_RDWR)
        self._thread.join(timeout=2.0)
        self.client.close()


class FramePublisher:
    """Server end of the frame channel: sends messages to the connected host, if any.

    A send that fails drops the host (it may reconnect); the MCU side never
    waits for a host that is not there.  ``muted`` streams are not sent (a
    stalled camera, for tests).

    In lockstep the messages go out on the MCU's thread, before its answer,
    so the host finds a step's frames when it reads the answer.  A host
    attached with a ``queue`` (the wall-clock emulator's) is sent to from a
    thread of its own instead: a host that stops reading then loses frames,
    as from a real camera, and never delays the MCU (its 200 ms watchdog
    among it).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._client: socket.socket | None = None
        self._sender: _QueuedSender | None = None
        self.muted: set[int] = set()
        self.messages_sent = 0
        self.messages_dropped = 0

    def attach(self, client: socket.socket, send_timeout_s: float = 5.0,
               queue: int | None = None) -> None:
        """Send to ``client`` from now on (replacing any previous host).

        A host that reads nothing for ``send_timeout_s`` is dropped, so that
        the MCU loop never hangs on the frame channel.  With ``queue``, at
        most that many messages wait for a slow host, sent from a thread of
        their own; more are dropped.
        """
        client.settimeout(send_timeout_s)
        sender = None if queue is None else _QueuedSender(client, queue)
        with self._lock:
            old = self._client, self._sender
            self._client, self._sender = client, sender
        self._release(*old)

    @staticmethod
    def _release(client: socket.socket | None, sender: _QueuedSender | None) -> None:
        if sender is not None:
            sender.close()
        elif client is not None:
            with contextlib.suppress(OSError):
                client.shutdown(socket.SHUT_RDWR)
            client.close()

    @property
    def connected(self) -> bool:
        """Whether a host is attached."""
        return self._client is not None and not (self._sender is not None and self._sender.dead)

    def send(self, kind: int, data: bytes) -> None:
        """Send one message of ``kind`` (skipped if muted or nobody listens)."""
        if kind in self.muted:
            return
        with self._lock:
            client, sender = self._client, self._sender
            if client is None:
                return
            if sender is not None:
                if sender.put(data):
                    self.messages_sent += 1
                else:
                    self.messages_dropped += 1
                return
            try:
                client.sendall(data)
                self.messages_sent += 1
            except OSError:
                client.close()
                self._client = None

    def close(self) -> None:
        """Drop the host."""
        with self._lock:
            old = self._client, self._sender
            self._client, self._sender = None, None
        self._release(*old)


def load_cell_force_n(truth: Truth | None) -> float:
    """Force on the calibration object's load cell (N): the contact force, if the held
    object carries a load cell (the force ball), else nothing."""
    if truth is None or truth.object_name is None:
        return 0.0
    return truth.contact_force_n if get_object(truth.object_name).force_sensor else 0.0


def load_cell_model(config: Hx711Config, seed: int, start_s: float) -> Hx711Model:
    """The emulator's HX711 for a twin seed (its own stream of the seed)."""
    return Hx711Model(config, np.random.default_rng((seed, 0x711)), start_s)


class TwinPlant:
    """The twin as the MCU's :class:`~relaxgrip.hardware.protocol.Plant`.

    Reading the encoder integrates the twin to that time and publishes the
    frames captured on the way and a tick (truth, force readings) on the
    frame channel, before the MCU's answer goes out; the load cell reads the
    force on the calibration object at the same times.

    Parameters
    ----------
    twin : GripperTwin
        The twin, on the emulator's clock.
    publisher : FramePublisher
        Frame channel.
    load_cell : Hx711Model, optional
        The load cell in the calibration object.
    """

    def __init__(self, twin: GripperTwin, publisher: FramePublisher,
                 load_cell: Hx711Model | None = None) -> None:
        self.twin = twin
        self.publisher = publisher
        self.load_cell = load_cell
        self._t_s = -float("inf")
        self._sent: dict[int, int] = {}
        self._ticks = 0
        self._position_um = 0
        self._conversions: list[tuple[float, int]] = []
        #: When the MCU's outputs changed, and to what: ``(time (s), outputs)``.
        self.output_log: list[tuple[float, AppliedOutputs]] = []
        self._applied = threading.Condition()
        self.applied_s = -float("inf")
        """Time of the MCU's latest poll (s on its clock)."""

    def _publish(self, kind: int, frame: Frame | None) -> None:
        if frame is not None and self._sent.get(kind) != frame.seq:
            self.publisher.send(kind, encode_frame_message(kind, frame))
            self._sent[kind] = frame.seq

    def encoder_position_um(self, now_s: float) -> int:
        """Integrate the twin to ``now_s``, publish frames and a tick, read the encoder."""
        if now_s > self._t_s:
            obs = self.twin.observe()
            self._publish(KIND_RGB, obs.rgb)
            self._publish(KIND_IR, obs.ir)
            self.publisher.send(0, encode_tick(self._ticks, obs.t_s, obs.truth, obs.force_ref))
            self._ticks += 1
            self._t_s = now_s
            self._position_um = round(obs.motor_position_mm * 1000.0)
            if self.load_cell is not None:
                self._conversions += self.load_cell.feed(obs.t_s, load_cell_force_n(obs.truth))
        return self._position_um

    def load_cell_conversions(self, now_s: float) -> list[tuple[float, int]]:
        """Conversions the load cell completed since the last call."""
        out, self._conversions = self._conversions, []
        return out

    def apply(self, outputs: AppliedOutputs, now_s: float) -> None:
        """Drive the twin's motor and heaters with ``outputs`` from ``now_s`` on."""
        self.twin.act(Command(motor_velocity_mm_s=outputs.velocity_mm_s,
                              heater_duty=outputs.heater_duty))
        with self._applied:
            if not self.output_log or self.output_log[-1][1] != outputs:
                self.output_log.append((now_s, outputs))
            self.applied_s = now_s
            self._applied.notify_all()

    def wait_applied(self, t_s: float, timeout_s: float = 2.0) -> bool:
        """Wait (wall clock) until the MCU has polled at ``t_s`` or later; whether it did.

        In lockstep the host moves the shared clock and the MCU thread catches
        up on its next poll: a fault test that advances the clock with no host
        traffic (a silent host, a cut cable) waits here for the MCU to see the
        new time.
        """
        with self._applied:
            return self._applied.wait_for(lambda: self.applied_s >= t_s, timeout_s)


class _TamperableFd(FdTransport):
    """The MCU's end of the pty; ``tamper`` rewrites what it sends (fault injection).

    Once :meth:`cut`, the MCU's side of a cable that is gone: nothing it sends
    arrives, nothing comes in, and the MCU goes on running (its watchdog with it).
    """

    tamper: Callable[[bytes], bytes] | None = None
    fd_closed = False
    is_cut = False

    def __init__(self, fd: int) -> None:
        super().__init__(fd)
        # Held around every use of the descriptor: it is closed only between two uses.
        self._fd_lock = threading.Lock()

    def write(self, data: bytes) -> None:
        """Send ``data`` (after ``tamper``, if set); nothing once the cable is cut."""
        with self._fd_lock:
            if self.is_cut:
                return
            if self.tamper is not None:
                data = self.tamper(data)
            super().write(data)

    def read(self, timeout_s: float) -> bytes:
        """What arrived within ``timeout_s`` (wall clock); nothing once the cable is cut."""
        with self._fd_lock:
            if not self.is_cut:
                return super().read(timeout_s)
        time.sleep(timeout_s)  # an idle UART: the MCU's loop goes on at its pace
        return b""

    def cut(self) -> None:
        """Cut the cable: the descriptor is closed (the host sees a dead line)."""
        with self._fd_lock:
            self.is_cut = True
            self._close_fd_once()

    def close_fd(self) -> None:
        """Close the descriptor once (the peer then sees a dead line)."""
        with self._fd_lock:
            self._close_fd_once()

    def _close_fd_once(self) -> None:
        if not self.fd_closed:
            os.close(self.fd)
            self.fd_closed = True


@dataclass
class _Pty:
    master: int
    slave: int
    path: str


def _open_pty() -> _Pty:
    master, slave = os.openpty()
    tty.setraw(master)
    # Never wait on a host that stops reading: a full buffer drops the MCU's answers
    # (FdTransport counts them), as a UART overflows, and the watchdog goes on.
    os.set_blocking(master, False)
    return _Pty(master, slave, os.ttyname(slave))


class McuEmulator:
    """The twin behind a pseudo-terminal, served by a thread.

    Parameters
    ----------
    config : TwinConfig
        The twin.
    seed : int
        Twin seed.
    clock : Clock
        Emulator clock: the host's :class:`~relaxgrip.clock.VirtualClock` in
        lockstep, a wall clock otherwise.
    mcu : McuConfig, optional
        Firmware constants (default: velocity limit of the twin's motor).
    poll_s : float
        Wall-clock poll period of the serving thread (s).
    load_cell : Hx711Config or None
        The calibration object's load cell and ADC; None: the MCU has none.
    firmware : bool
        Run the compiled firmware in simavr (:mod:`relaxgrip.hardware.firmware_emulator`)
        instead of the Python MCU; ``mcu`` is then ignored (the firmware is built for
        the twin's motor and encoder).
    twin : GripperTwin, optional
        The twin to run (one taken over mid-grasp, on ``clock``); default a
        new one of ``config`` and ``seed``.
    """

    def __init__(self, config: TwinConfig | None = None, seed: int = 0,
                 clock: Clock | None = None, mcu: McuConfig | None = None,
                 poll_s: float = 0.002,
                 load_cell: Hx711Config | None = DEFAULT_LOAD_CELL,
                 firmware: bool = False, twin: GripperTwin | None = None) -> None:
        self.clock: Clock = clock if clock is not None else VirtualClock()
        # The firmware's AVR keeps the twin's time, a step ahead of the host's at most.
        twin_clock = VirtualClock(self.clock.now()) if firmware else self.clock
        if twin is not None:
            self.config = twin.config
            self.twin = twin
            twin.clock = twin_clock
        else:
            self.config = config if config is not None else TwinConfig()
            self.twin = GripperTwin(self.config, seed=seed, clock=twin_clock)
        max_um_s = round(self.config.motor.max_velocity_mm_s * 1000.0)
        self.mcu_config = mcu if mcu is not None and not firmware else McuConfig(
            max_velocity_um_s=max_um_s, load_cell=load_cell is not None)
        self.publisher = FramePublisher()
        self.load_cell = None if load_cell is None else load_cell_model(
            load_cell, seed, self.clock.now())
        self._pty = _open_pty()
        self.transport = _TamperableFd(self._pty.master)
        self._python: McuEndpoint | None = None
        self.firmware: FirmwareEndpoint | None = None
        """The simulated firmware, with ``firmware=True``."""
        if firmware:
            from relaxgrip.hardware.firmware_emulator import (
                FirmwareEndpoint,
                MotorDrive,
                firmware_for_twin,
            )

            assert isinstance(twin_clock, VirtualClock)
            self.plant = TwinPlant(self.twin, self.publisher)
            drive = MotorDrive()
            try:
                image = firmware_for_twin(self.config, drive, load_cell is not None)
                self.firmware = FirmwareEndpoint(self.transport, self.clock, self.plant,
                                                 twin_clock, image, drive, self.load_cell)
            except BaseException:
                self._close_pty()
                raise
        else:
            self.plant = TwinPlant(self.twin, self.publisher, self.load_cell)
            self._python = McuEndpoint(self.transport, self.clock,
                                       McuCore(self.mcu_config, start_s=self.clock.now()),
                                       self.plant)
        self.poll_s = poll_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._server: socket.socket | None = None
        self._socket_path: Path | None = None
        self._socket_lock: tuple[int, Path] | None = None
        self._accept_thread: threading.Thread | None = None
        self.error: BaseException | None = None

    @property
    def endpoint(self) -> McuEndpoint:
        """The Python MCU and its state machine.

        Raises
        ------
        InputError
            If this emulator runs the firmware (see :attr:`firmware`).
        """
        if self._python is None:
            raise InputError("this emulator runs the compiled firmware: see .firmware")
        return self._python

    def wait_applied(self, t_s: float, timeout_s: float = 2.0) -> bool:
        """Wait (wall clock) until the MCU, Python or firmware, has run to host time
        ``t_s`` while the host is quiet; whether it did (the lockstep's sync)."""
        if self.firmware is not None:
            return self.firmware.wait_ran(t_s, timeout_s)
        return self.plant.wait_applied(t_s, timeout_s)

    def outputs(self) -> list[tuple[float, float, tuple[float, float]]]:
        """What the MCU drove, at each change: ``(time (s), |motor velocity| (mm/s),
        heater duties)``, from its own outputs (the firmware's: its velocity setpoint, 0 when
        disabled, and its heater pins)."""
        if self.firmware is not None:
            with self.firmware._ran:
                log = list(self.firmware.output_log)
            return [(t, abs(v), (float(duty[0]), float(duty[1]))) for t, (v, duty) in log]
        with self.plant._applied:
            applied = list(self.plant.output_log)
        return [(t, abs(o.velocity_mm_s), o.heater_duty) for t, o in applied]

    @property
    def fault_flags(self) -> int:
        """The MCU's fault flags: the Python MCU's state, or the firmware's latest Status."""
        if self.firmware is not None:
            return self.firmware.fault_flags
        return self.endpoint.core.fault_flags

    @property
    def port(self) -> str:
        """Path of the pseudo-terminal's slave side: the host's serial port."""
        return self._pty.path

    @property
    def tamper_tx(self) -> Callable[[bytes], bytes] | None:
        """Applied to every frame the MCU sends (fault injection in tests)."""
        return self.transport.tamper

    @tamper_tx.setter
    def tamper_tx(self, tamper: Callable[[bytes], bytes] | None) -> None:
        self.transport.tamper = tamper

    def start(self) -> McuEmulator:
        """Start serving on a thread."""
        if self._thread is not None:
            return self
        self._thread = threading.Thread(target=self._serve, name="mcu-emulator", daemon=True)
        self._thread.start()
        return self

    def _serve(self) -> None:
        try:
            server = self.firmware if self.firmware is not None else self.endpoint
            server.serve(self._stop, self.poll_s)
        except BaseException as exc:  # reported by stop(); the host sees a dead link
            if not self._stop.is_set():
                self.error = exc

    def connect_host(self) -> socket.socket:
        """An in-process frame channel: a connected socket pair; return the host's end."""
        mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        self.publisher.attach(mine)
        return theirs

    def listen(self, path: str) -> None:
        """Serve the frame channel on a Unix socket at ``path`` (one host at a time).

        An old socket at ``path`` (a previous emulator's) is replaced; any
        other file there is left alone.  The emulator holds a lock on
        ``path + ".lock"`` until :meth:`stop`, so that a second emulator is
        refused however it spells the same path (relative, through a linked
        folder).

        Raises
        ------
        InputError
            If ``path`` is taken by something other than a socket, is served
            by another emulator, is too long for a Unix socket, is in a
            missing folder, or cannot be created.
        """
        p = Path(path)
        if len(os.fsencode(p)) > _MAX_SOCKET_PATH:
            raise InputError(f"frame channel socket {p}: longer than the {_MAX_SOCKET_PATH} "
                             "bytes a Unix socket path may have")
        if p.is_symlink() or (p.exists() and not stat.S_ISSOCK(p.stat().st_mode)):
            raise InputError(f"frame channel socket {p}: a file that is not a socket is "
                             "there; the emulator will not replace it")
        check_parent_dir(p, "frame channel socket")
        lock = _lock_socket(p)
        try:
            if p.exists() and _answers(p):
                raise InputError(f"frame channel socket {p}: another emulator is serving it; "
                                 "stop it or give this one another [emulator] socket")
            server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                with contextlib.suppress(FileNotFoundError):
                    p.unlink()
                server.bind(str(p))
            except OSError as exc:
                server.close()
                raise InputError(f"frame channel socket {p}: {exc.strerror or exc}") from None
        except BaseException:
            _unlock_socket(lock)
            raise
        server.listen(1)
        server.settimeout(0.2)
        # Absolute, so that stop() removes the socket whatever the working folder by then.
        self._server, self._socket_path = server, Path(os.path.abspath(p))
        self._socket_lock = lock

        def accept() -> None:
            while not self._stop.is_set():
                try:
                    client, _ = server.accept()
                except TimeoutError:
                    continue
                except OSError:
                    return
                self.publisher.attach(client, queue=_HOST_QUEUE)

        self._accept_thread = threading.Thread(target=accept, name="frame-channel-accept",
                                               daemon=True)
        self._accept_thread.start()

    def disconnect(self) -> None:
        """Cut the cable with the MCU powered: the host's port goes dead, the MCU runs on.

        Nothing crosses the line any more; the emulated MCU keeps polling its
        plant and its clock, so its watchdog trips 200 ms after the last
        command it got and switches the motor and heaters off, as a real MCU
        on a cut USB cable (powered from its own supply) does.
        """
        self.transport.cut()

    def stop(self) -> None:
        """Stop serving and release the pseudo-terminal and the frame channel."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self.publisher.close()
        if self._server is not None:
            self._server.close()
            if self._accept_thread is not None:
                self._accept_thread.join(timeout=2.0)
            self._server = None
        if self._socket_path is not None:
            with contextlib.suppress(OSError):
                self._socket_path.unlink()
            self._socket_path = None
        if self._socket_lock is not None:
            _unlock_socket(self._socket_lock)
            self._socket_lock = None
        self._close_pty()
        if self.firmware is not None:
            self.firmware.close()

    def _close_pty(self) -> None:
        self.transport.close_fd()
        if self._pty.slave >= 0:  # once: a second stop must not close a reused descriptor
            with contextlib.suppress(OSError):
                os.close(self._pty.slave)
            self._pty.slave = -1


def _lock_socket(path: Path) -> tuple[int, Path]:
    """Lock ``path + ".lock"``, the mark of the socket's owner; its descriptor and absolute path.

    The lock is on the file, whatever the spelling of its path, and dies
    with the process that holds it (a crashed emulator's socket is replaced).

    Raises
    ------
    InputError
        If another emulator holds it, or the lock file cannot be made.
    """
    lock_path = path.with_name(path.name + ".lock")
    for _ in range(3):  # the holder may remove the file between our open and our lock
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            raise InputError(f"frame channel socket {path}: cannot make its lock file "
                             f"{lock_path}: {exc.strerror or exc}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise InputError(f"frame channel socket {path}: another emulator is serving it "
                             f"(it holds {lock_path}); stop it or give this one another "
                             "[emulator] socket") from None
        try:
            current = os.stat(lock_path, follow_symlinks=False)
        except FileNotFoundError:
            current = None
        if current is not None and os.path.samestat(current, os.fstat(fd)):
            return fd, Path(os.path.abspath(lock_path))
        os.close(fd)  # locked a file its holder had just removed: take the new one
    raise InputError(f"frame channel socket {path}: its lock file {lock_path} keeps changing; "
                     "is another emulator starting and stopping on it?")


def _unlock_socket(lock: tuple[int, Path]) -> None:
    """Remove the lock file, then release it (never the reverse: see :func:`_lock_socket`)."""
    fd, lock_path = lock
    with contextlib.suppress(OSError):
        lock_path.unlink()
    os.close(fd)


def _answers(path: Path) -> bool:
    """Whether a process listens on the Unix socket at ``path`` (Linux: ``/proc/net/unix``).

    Read from the kernel's table rather than by connecting: a connection
    would take the running emulator's frame channel from its host.
    """
    try:
        table = Path("/proc/net/unix").read_text(encoding="utf-8").splitlines()[1:]
    except OSError:  # not Linux: nothing to tell by
        return False
    target = str(path.resolve())
    for line in table:
        parts = line.split()
        if len(parts) >= 8 and int(parts[3], 16) & _SO_ACCEPTCON and \
                " ".join(parts[7:]) in (target, str(path)):
            return True
    return False


def open_emulated_gripper(config: TwinConfig | None = None, seed: int = 0,
                          clock: VirtualClock | None = None, *,
                          mcu: McuConfig | None = None,
                          grace_s: float = 2.0,
                          reply_timeout_s: float = 0.1,
                          firmware: bool = False,
                          twin: GripperTwin | None = None) -> tuple[SerialGripper, McuEmulator]:
    """An in-process emulator thread and a :class:`SerialGripper` on its pty, in lockstep.

    Parameters
    ----------
    config : TwinConfig, optional
        The emulated twin.
    seed : int
        Twin seed.
    clock : VirtualClock, optional
        Shared virtual clock (a new one by default).
    mcu : McuConfig, optional
        Firmware constants of the emulated MCU.
    grace_s : float
        Wall-clock wait after which silence counts as a timeout (s).
    reply_timeout_s : float
        Host reply timeout in virtual time (s).
    firmware : bool
        Run the compiled firmware in simavr instead of the Python MCU.
    twin : GripperTwin, optional
        The twin the emulator runs (see :class:`McuEmulator`).

    Returns
    -------
    (SerialGripper, McuEmulator)
        The gripper (closing it stops the emulator) and the emulator.
    """
    clk = clock if clock is not None else VirtualClock()
    emu = McuEmulator(config, seed, clk, mcu, firmware=firmware, twin=twin)
    try:
        host_sock = emu.connect_host()
        emu.start()
        serial = SerialTransport(emu.port)
    except BaseException:
        emu.stop()
        raise
    transport = GuardedTransport(serial, clk, grace_s, sync=emu.wait_applied)
    client = McuClient(transport, clk, reply_timeout_s=reply_timeout_s)
    channel = EmulatorChannel(host_sock, clk, lockstep=True, wait_timeout_s=grace_s)
    cfg = emu.config
    rgb = EmulatorFrameSource(channel, "rgb", max(0.2, 3.0 / cfg.rig.rgb.rate_hz))
    ir = EmulatorFrameSource(channel, "ir", max(2.5, 2.5 / cfg.rig.ir.rate_hz))
    # Our gripper's limits, at the speed of the emulated motor (a rig file's, for its twin).
    limits = replace(OUR_LIMITS, max_motor_speed_mm_s=cfg.motor.max_velocity_mm_s)
    force_ref = None
    if emu.load_cell is not None and emu.mcu_config.load_cell:
        # Calibrated as a rig file would give it: the unit's scale and zero.
        cell = emu.load_cell
        force_ref = McuLoadCell(client, LinearCalibration(1.0 / cell.config.counts_per_n,
                                                          cell.offset_counts))
    on_close = emu.stop
    if cfg.rgb is None and cfg.ir is None:
        # No camera starts the frame channel: start it here, or its ticks (the truth) would
        # fill the socket until the emulator's thread blocks on it.
        channel.start()

        def on_close() -> None:
            channel.close()
            emu.stop()

    gripper = SerialGripper(client, rgb if cfg.rgb is not None else None,
                            ir if cfg.ir is not None else None, limits=limits,
                            name="emulator", truth_feed=channel.take_truth,
                            twin_version=TWIN_VERSION, on_close=on_close, force_ref=force_ref)
    return gripper, emu


def ready_emulated_gripper(config: TwinConfig | None, seed: int,
                           clock: VirtualClock, firmware: bool = False) -> SerialGripper:
    """:func:`open_emulated_gripper`, then reset (handshake, first frames); closed if that fails."""
    gripper, _ = open_emulated_gripper(config, seed, clock, firmware=firmware)
    try:
        gripper.reset()
    except BaseException:
        gripper.close()
        raise
    return gripper
