"""The real-hardware backend: :class:`SerialGripper`, a Gripper behind the MCU.

It speaks the MCU protocol through :class:`~relaxgrip.hardware.protocol.McuClient`
and reads two :class:`~relaxgrip.hardware.cameras.FrameSource` objects (whatever
the rig file names: live cameras or the emulator's frame channel).  Every
:meth:`observe` asks the MCU for a Status (fresh encoder, link check; it does
not feed the watchdog), every :meth:`act` sends one Command (which does).

A :class:`~relaxgrip.hardware.force_ref.ForceReference` (the MCU's load
cell, an external force gauge, an emulator's force ball) fills the
observation's ``force_ref``; :func:`open_rig_gripper` makes the one the rig
file names.  Only the in-process emulator
(:func:`~relaxgrip.hardware.emulator.open_emulated_gripper`) has a truth
feed: a gripper opened from a rig file, an emulator rig's too, carries no
truth, and its force reference is the only force it knows.

The MCU's own configuration is checked against the rig's limits at the
handshake (its velocity limit may not be higher), and a Status saying the
MCU has stopped its outputs itself (its watchdog, a hardware fault) is a
fault too: a host whose commands stopped being applied (a link that repeats
its sequence numbers) learns it there.

On any fault (a dead, corrupted or truncated link, a protocol version
mismatch, an MCU fault, a stalled camera) the gripper stops the motor and
switches the heaters off (a zero Command if the link still answers; the
MCU's 200 ms watchdog covers a dead link), marks itself failed and raises a
one-line :class:`GripperFaultError` naming what happened.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from relaxgrip.backend import BackendInfo, Command, ForceSamples, Frame, Observation, Truth
from relaxgrip.clock import Clock, VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.hardware.cameras import CameraError, FrameSource
from relaxgrip.hardware.force_ref import (
    ForceReference,
    ForceRefError,
    rig_force_reference,
)
from relaxgrip.hardware.protocol.client import McuClient
from relaxgrip.hardware.protocol.codec import PROTOCOL_VERSION, TRIP_FAULTS, FaultFlag, Status
from relaxgrip.hardware.protocol.errors import (
    LinkCorruptedError,
    LinkError,
    McuFaultError,
    ProtocolError,
    VersionMismatchError,
)
from relaxgrip.hardware.protocol.transport import SerialTransport, Transport
from relaxgrip.hardware.rig_file import RigFile
from relaxgrip.limits import OUR_LIMITS, LimitsSpec

__all__ = [
    "GripperFaultError",
    "GuardedTransport",
    "SerialGripper",
    "TruthFeed",
    "fault_names",
    "open_rig_gripper",
]

TruthFeed = Callable[[], tuple[Truth | None, ForceSamples | None]]
"""Returns the twin's truth and force readings (the emulator only)."""


class GripperFaultError(InputError):
    """The gripper stopped on a fault; the message says what and how the outputs were stopped."""


class GuardedTransport:
    """A transport whose OS-level failures become :class:`LinkError`, optionally in virtual time.

    With a :class:`~relaxgrip.clock.VirtualClock` (the in-process emulator in
    lockstep), a wait that sees no byte within ``grace_s`` of wall-clock time
    counts as the whole requested timeout of virtual time: the clock is
    advanced, so the client's reply deadline (100 ms) expires in virtual time
    and a dead link is detected exactly as on hardware.  A live lockstep
    emulator answers within milliseconds of wall time.

    Parameters
    ----------
    inner : Transport
        The real transport (a serial port).
    clock : Clock
        The host clock.
    grace_s : float
        Longest wall-clock wait for the first byte in virtual time (s).
    sync : callable, optional
        In lockstep, ``sync(t_s)`` waits for the device (the emulated MCU) to
        run at ``t_s``: the virtual timeout is then spent in 1 ms steps, the
        device running at each, so that what it does meanwhile (its watchdog
        trips 200 ms after the last command) happens when it would on
        hardware, not at the end of a jump over the whole timeout.
    """

    #: Step of a virtual-time wait with ``sync`` (s).
    SYNC_STEP_S = 0.001

    def __init__(self, inner: Transport, clock: Clock, grace_s: float = 2.0,
                 sync: Callable[[float], object] | None = None) -> None:
        self.inner = inner
        self.clock = clock
        self.grace_s = grace_s
        self.sync = sync
        self.tamper_rx: Callable[[bytes], bytes] | None = None
        """Applied to every read (fault injection in tests)."""

    def write(self, data: bytes) -> None:
        """Send ``data``."""
        try:
            self.inner.write(data)
        except LinkError:
            raise
        except Exception as exc:  # pyserial's SerialException, OSError
            raise LinkError(f"serial link lost while writing: {exc}") from None

    def read(self, timeout_s: float) -> bytes:
        """Bytes available within ``timeout_s`` (see the class docstring for virtual time)."""
        virtual = isinstance(self.clock, VirtualClock)
        wait = self.grace_s if virtual and timeout_s > 0 else timeout_s
        try:
            data = self.inner.read(wait)
        except LinkError:
            raise
        except Exception as exc:
            raise LinkError(f"serial link lost: {exc}") from None
        if not data and virtual and timeout_s > 0:
            end = self.clock.now() + timeout_s
            if self.sync is None:
                self.clock.sleep_until(end)
            while self.sync is not None and self.clock.now() < end and not data:
                self.clock.sleep_until(min(end, self.clock.now() + self.SYNC_STEP_S))
                self.sync(self.clock.now())
                data = self._read_now()
        if self.tamper_rx is not None and data:
            data = self.tamper_rx(data)
        return data

    def _read_now(self) -> bytes:
        try:
            data: bytes = self.inner.read(0.0)
        except LinkError:
            raise
        except Exception as exc:
            raise LinkError(f"serial link lost: {exc}") from None
        return data

    def close(self) -> None:
        """Close the inner transport."""
        # Closing a dead port must not hide the fault that killed it.
        with contextlib.suppress(Exception):
            self.inner.close()


def fault_names(flags: int) -> frozenset[str]:
    """Names of the set bits of a Status's fault flags (unknown bits as ``BITn``)."""
    known = 0
    names = set()
    for flag in FaultFlag:
        known |= int(flag)
        if flags & int(flag):
            names.add(str(flag.name))
    names |= {f"BIT{b}" for b in range(16) if flags & ~known & (1 << b)}
    return frozenset(names)


class SerialGripper:
    """The gripper behind its MCU and cameras, as a :class:`~relaxgrip.backend.Gripper`.

    Parameters
    ----------
    client : McuClient
        Protocol client on the MCU's transport (its clock is the host clock).
    rgb, ir : FrameSource or None
        Camera sources (started by :meth:`reset`).
    limits : LimitsSpec
        Host-side limits: commanded speed and duty are clamped, and the
        heaters are switched off while the infrared image is hotter than
        ``max_temp_c``.
    name : str
        Backend name (``serial`` on hardware, ``emulator`` for the emulator).
    truth_feed : callable, optional
        Source of the twin's truth (the emulator's frame channel); without it
        observations carry no truth.
    twin_version : str, optional
        Version of the twin behind an emulator (recorded in :attr:`info`).
    on_close : callable, optional
        Called last by :meth:`close` (e.g. to stop an in-process emulator).
    boot_wait_s : float
        How long :meth:`reset` says Hello again while the MCU gives no valid
        answer (s): opening a USB-serial port raises DTR, which resets an
        Arduino-class MCU, and its bootloader answers nothing for a second or
        two.  0: one Hello.
    force_ref : ForceReference, optional
        The rig's reference force sensor (started by :meth:`reset`, after the
        handshake); it fills ``Observation.force_ref``.
    watchdog_s : float, optional
        The MCU watchdog's period, set at every :meth:`reset` before the
        outputs are enabled (s); default: the firmware's.
    """

    def __init__(self, client: McuClient, rgb: FrameSource | None, ir: FrameSource | None, *,
                 limits: LimitsSpec | None = None, name: str = "serial",
                 truth_feed: TruthFeed | None = None, twin_version: str | None = None,
                 on_close: Callable[[], None] | None = None, boot_wait_s: float = 0.0,
                 force_ref: ForceReference | None = None,
                 watchdog_s: float | None = None) -> None:
        self.client = client
        self.watchdog_s = watchdog_s
        self.force_ref = force_ref
        self.boot_wait_s = boot_wait_s
        self.clock: Clock = client.clock
        self.rgb = rgb
        self.ir = ir
        self.limits = limits if limits is not None else OUR_LIMITS
        self.name = name
        self.truth_feed = truth_feed
        self.twin_version = twin_version
        self._on_close = on_close
        self._started = False
        self._failed: str | None = None
        self._closed = False
        self._last_status: Status | None = None
        self._overtemp = False
        self.fault_time_s: float | None = None
        """Host time at which the last fault was detected (s)."""

    # -- Gripper protocol ---------------------------------------------------
    @property
    def info(self) -> BackendInfo:
        """Name, protocol and firmware (and the emulated twin's version)."""
        ack = self.client.hello_ack
        firmware = ack.firmware_id if ack is not None else "not connected"
        minor = self.client.session_minor
        version = f"protocol {PROTOCOL_VERSION}.{minor}; firmware {firmware}"
        if self.twin_version is not None:
            version += f"; {self.twin_version}"
        return BackendInfo(self.name, version, has_truth=self.truth_feed is not None)

    def reset(self, seed: int | None = None) -> Observation:
        """Open the session (handshake, enable), start the cameras and observe.

        ``seed`` is accepted for the interface; the hardware has none (an
        emulator's twin is seeded when the emulator starts).
        """
        self._failed = None
        self._guard(self._start)
        return self.observe()

    def _start(self) -> None:
        if not self._started:  # cameras first: an emulator publishes frames from its first answer
            started: list[FrameSource] = []
            try:
                for source in (self.rgb, self.ir):
                    if source is not None:
                        source.start()
                        started.append(source)
            except BaseException:
                # All or none: the next reset() starts them all again, and a camera left
                # open here would refuse that second opening (and leak its reader).
                for source in started:
                    source.close()
                raise
            self._started = True
        deadline = self.clock.now() + self.boot_wait_s
        while True:
            try:
                ack = self.client.handshake()
                break
            except LinkError as exc:  # silence or a bootloader's bytes: booting, maybe
                if self.clock.now() >= deadline:
                    if self.boot_wait_s > 0:
                        raise type(exc)(f"{exc} (Hello said for {self.boot_wait_s:g} s: "
                                        "the MCU did not boot)") from None
                    raise
        try:  # before enabling: an MCU that would let a faster motor through never drives
            self.limits.check_mcu_speed_mm_s(ack.max_velocity_um_s / 1000.0)
        except InputError as exc:
            raise McuFaultError(str(exc)) from None
        if self.watchdog_s is not None:
            self.client.set_watchdog(self.watchdog_s)
        if self.force_ref is not None:
            self.force_ref.start()
        self.client.set_enabled(True)

    def observe(self) -> Observation:
        """Ask the MCU for a Status, read the cameras, report (raises on a fault)."""
        self._check_alive()
        obs: Observation = self._guard(self._observe)
        return obs

    def _observe(self) -> Observation:
        status = self.client.request_status()
        self._last_status = status
        tripped = status.fault_flags & int(TRIP_FAULTS)
        if tripped or not status.enabled:
            why = ", ".join(sorted(fault_names(tripped))) if tripped else "disabled"
            raise McuFaultError(f"the MCU stopped its outputs itself ({why})")
        now = self.clock.now()
        rgb = self.rgb.read(now) if self.rgb is not None else None
        ir = self.ir.read(now) if self.ir is not None else None
        self._overtemp = ir is not None and _hottest_c(ir) > self.limits.max_temp_c
        faults = set(fault_names(status.fault_flags))
        if self._overtemp:
            faults.add("HOST_OVERTEMP")
        truth, force = (None, None) if self.truth_feed is None else self.truth_feed()
        if self.force_ref is not None:
            force = self.force_ref.read(now)
        return Observation(
            t_s=now,
            motor_position_mm=status.encoder_position_um / 1000.0,
            arm_height_mm=0.0,
            heater_duty=status.heater_duty,
            rgb=rgb,
            ir=ir,
            faults=frozenset(faults),
            force_ref=force,
            truth=truth,
        )

    def act(self, command: Command) -> None:
        """Send ``command`` (speed and duty clamped to the rig's limits) as one MCU Command.

        The arm is not driven by the MCU: its velocities are ignored.  After
        a fault only the all-stop command is accepted (and sent if the link
        still answers); anything else raises.
        """
        stop = command.motor_velocity_mm_s == 0.0 and command.heater_duty == (0.0, 0.0)
        if self._failed is not None:
            if stop:
                self._safe_stop()
                return
            raise GripperFaultError(f"gripper stopped earlier: {self._failed}")
        if self._closed:
            raise GripperFaultError("gripper is closed")
        v, duty = self.limits.clamp(command.motor_velocity_mm_s, command.heater_duty)
        if self._overtemp:
            duty = (0.0, 0.0)
        self._guard(lambda: self.client.command(v, duty))

    def close(self) -> None:
        """Stop the motor, switch the heaters off, disable the MCU, release everything."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._failed is None and self.client.hello_ack is not None:
                try:
                    self.client.command(0.0, (0.0, 0.0))
                    self.client.set_enabled(False)
                except ProtocolError:
                    pass  # the MCU's watchdog stops the outputs of a dead link
            for source in (self.rgb, self.ir):
                if source is not None:
                    source.close()
            if self.force_ref is not None:
                self.force_ref.close()
            self.client.close()
        finally:
            if self._on_close is not None:
                self._on_close()

    def tare_force_ref(self, duration_s: float = 0.5, min_readings: int = 3) -> float:
        """Zero the force reference: its mean over ``duration_s`` becomes 0 N.

        Nothing may touch the load cell meanwhile.  The motor is held stopped
        and the heaters off (zero Commands at 30 Hz keep the MCU's watchdog
        fed), and the time passes on the gripper's clock.

        Parameters
        ----------
        duration_s : float
            How long to average (s), 0.1..10.
        min_readings : int
            Fewest readings the mean may rest on.

        Returns
        -------
        float
            The force the reference read before the tare (N): what was taken off.

        Raises
        ------
        InputError
            Without a force reference, before :meth:`reset`, or with fewer
            than ``min_readings`` readings in ``duration_s``.
        GripperFaultError
            If the link or the MCU fails meanwhile.
        """
        ref = self.force_ref
        if ref is None:
            raise InputError("this gripper has no force reference to tare")
        if not 0.1 <= duration_s <= 10.0:
            raise InputError(f"tare duration_s must be 0.1..10 s, got {duration_s}")
        self._check_alive()
        if self.client.hello_ack is None:
            raise InputError("tare the force reference after reset(): the MCU is not connected")
        clock = self.clock
        ref.read(clock.now())  # readings from before the tare are not part of it
        readings: list[float] = []
        end = clock.now() + duration_s
        while clock.now() < end:
            self._guard(lambda: self.client.command(0.0, (0.0, 0.0)))
            clock.sleep_until(min(end, clock.now() + 1.0 / 30.0))
            got = ref.read(clock.now())
            if got is not None:
                readings.extend(float(f) for f in got.force_n)
        if len(readings) < min_readings:
            raise InputError(f"tare: the force reference gave {len(readings)} reading(s) in "
                             f"{duration_s:g} s, {min_readings} needed: is it connected?")
        mean_n = float(np.mean(readings))
        ref.shift_zero(mean_n)
        return mean_n

    # -- faults ---------------------------------------------------------------
    @property
    def failed(self) -> str | None:
        """What stopped the gripper, if something did."""
        return self._failed

    @property
    def last_status(self) -> Status | None:
        """The latest Status from the MCU."""
        return self._last_status

    def _check_alive(self) -> None:
        if self._failed is not None:
            raise GripperFaultError(f"gripper stopped earlier: {self._failed}")
        if self._closed:
            raise GripperFaultError("gripper is closed")

    def _guard(self, call: Callable[[], Any]) -> Any:
        try:
            return call()
        except (ProtocolError, CameraError, ForceRefError) as exc:
            self.fault_time_s = self.clock.now()
            what = _describe(exc)
            # A silent link or an MCU of another version cannot take a command; a
            # corrupted link may still carry one (the MCU applies it, whatever comes back).
            dead = isinstance(exc, VersionMismatchError) or (
                isinstance(exc, LinkError) and not isinstance(exc, LinkCorruptedError))
            stopped = ("outputs never enabled in this session" if isinstance(
                exc, VersionMismatchError) else self._safe_stop(link_dead=dead))
            self._failed = f"{what}; {stopped}"
            raise GripperFaultError(f"gripper stopped: {self._failed}") from exc

    def _safe_stop(self, link_dead: bool = False) -> str:
        """Zero the outputs if the link answers; say how they were stopped."""
        if not link_dead:
            try:
                self.client.command(0.0, (0.0, 0.0))
                return "motor stopped and heaters off (zero command acknowledged)"
            except ProtocolError:
                return ("zero command sent without a valid answer; the MCU watchdog stops the "
                        f"motor and heaters within {self._watchdog_ms()} ms if it was lost")
        return ("link not answering: the MCU watchdog stops the motor and heaters within "
                f"{self._watchdog_ms()} ms")

    def _watchdog_ms(self) -> int:
        if self.watchdog_s is not None:
            return round(self.watchdog_s * 1000.0)
        ack = self.client.hello_ack
        return ack.watchdog_ms if ack is not None else 200


def _describe(exc: Exception) -> str:
    if isinstance(exc, VersionMismatchError):
        return f"wrong protocol version: {exc}"
    if isinstance(exc, (CameraError, ForceRefError)):
        return str(exc)
    if isinstance(exc, LinkError):
        return f"MCU link fault: {exc}"
    return f"MCU fault: {exc}"


def _hottest_c(frame: Frame) -> float:
    image = np.asarray(frame.image)
    if image.ndim != 2 or image.size == 0:
        return -math.inf
    return float(np.nanmax(image))


def open_rig_gripper(rig: RigFile, clock: Clock, *,
                     sources: tuple[FrameSource, FrameSource] | None = None,
                     force_ref: Callable[[McuClient], ForceReference] | None = None,
                     ) -> SerialGripper:
    """A :class:`SerialGripper` on the port, cameras and force reference a rig file names.

    Not yet reset.  The force reference is the rig's ``[force_ref]``
    (:func:`~relaxgrip.hardware.force_ref.rig_force_reference`): the MCU's
    load cell with its scale and offset, an external gauge on its own port,
    or (an emulator rig) the twin's force ball.  There is no truth feed.

    Parameters
    ----------
    rig : RigFile
        The rig.
    clock : Clock
        Host clock (a wall clock on hardware).
    sources : (FrameSource, FrameSource), optional
        RGB and thermal sources (default: those the rig file names).
    force_ref : callable, optional
        Makes the force reference from the MCU's client instead of the rig
        file's (tests).

    Returns
    -------
    SerialGripper
    """
    from relaxgrip.hardware.cameras import EmulatorChannel, open_frame_sources

    channel = None
    if sources is None and "emulator" in (rig.rgb.source, rig.ir.source):
        assert rig.emulator is not None  # the rig file checks it
        channel = EmulatorChannel(rig.emulator.socket, clock)
    transport = GuardedTransport(SerialTransport(rig.serial.port, rig.serial.baud), clock)
    client = McuClient(transport, clock, reply_timeout_s=rig.serial.reply_timeout_s)
    rgb, ir = sources if sources is not None else open_frame_sources(rig, clock,
                                                                     channel=channel)
    ref = (force_ref(client) if force_ref is not None
           else rig_force_reference(rig.force_ref, client, clock, channel))
    return SerialGripper(client, rgb, ir, limits=rig.limits,
                         name="emulator" if rig.rgb.source == "emulator" else "serial",
                         boot_wait_s=rig.serial.boot_wait_s, force_ref=ref,
                         watchdog_s=rig.serial.watchdog_s)
