"""The compiled firmware in simavr behind the emulator's pseudo-terminal, driving the twin.

:class:`FirmwareEndpoint` takes the place of the Python MCU
(:class:`~relaxgrip.hardware.protocol.McuEndpoint`) in
:class:`~relaxgrip.hardware.emulator.McuEmulator`: the host's bytes go to the
simulated ATmega328P's UART and its answers back to the pty; the twin's motor
is driven by the firmware's motor pins, its heaters by the heater pins, and
the twin's motor motion drives the encoder pins; the load cell's conversions
are shifted out of a simulated HX711.

Co-simulation, in steps of simulated time on a fixed grid (8 ms, ``coarse_s``,
between the host's frames; one step of the exchange's length, about 6 ms, for
a host frame and its answer): the pins' mean levels over a step
(:class:`MotorDrive` turns the enable duty and direction into a closing
velocity) drive the twin over the next step; the twin's motor position at the
end of a step becomes evenly spaced encoder edges within it.  A pin thus acts
on the twin one step later, far inside the motor's 50 ms lag, and the
firmware's 2 ms velocity loop sees the encoder move continuously.

Time (docs/emulator.md): in lockstep the AVR runs, step by step, up to the
host's virtual time when a frame arrives, takes the frame at the line rate and
runs on until it has answered it (docs/protocol.md: one answer per frame); the host's clock
is moved to that moment, so the host sees the link's real latency (about 5 ms
for a Command and its Status at 115 200 bit/s).  In wall-clock time the AVR
follows the wall clock and its bytes go out as it sends them.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

from relaxgrip.backend import Command
from relaxgrip.clock import Clock, VirtualClock
from relaxgrip.errors import InputError
from relaxgrip.hardware.firmware_sim import (
    BYTE_S,
    CPU_HZ,
    FirmwareImage,
    SimAvr,
    build_firmware,
)
from relaxgrip.hardware.hx711 import Hx711Model
from relaxgrip.hardware.protocol.codec import (
    ErrorReply,
    FrameDecoder,
    GetStatus,
    HelloAck,
    Packet,
    Status,
)
from relaxgrip.hardware.protocol.transport import Transport
from relaxgrip.twin import GripperTwin, TwinConfig
from relaxgrip.twin.objects import get_object

if TYPE_CHECKING:
    from relaxgrip.hardware.emulator import TwinPlant

__all__ = ["FirmwareEndpoint", "MotorDrive", "firmware_for_twin"]

#: Steps the firmware runs before the emulator's start (it sets up its UART in microseconds).
_BOOT_STEPS = 5
#: Cycles between encoder edges while a twin's travel is turned in during the boot.
_BOOT_EDGE_CYCLES = 200
#: A Status of minor 1 on the wire (bytes) and the firmware's time to make it (s): the
#: lockstep's first step after a host frame covers both.
_ANSWER_BYTES = 43
_TURNAROUND_S = 0.0005


@dataclass(frozen=True)
class MotorDrive:
    """The L298N and gearmotor between the firmware's motor pins and the twin's motor.

    The bridge applies the supply to the motor while the enable pin is high,
    in the direction IN1 / IN2 set (both low or both high: no drive), so the
    motor's speed is the enable pin's mean duty times its full speed; the
    twin's motor adds its lag and its speed limit.

    Attributes
    ----------
    full_speed_mm_s : float
        Closing speed at 100 % duty (mm/s): the firmware's feed-forward
        (``MOTOR_FULL_SPEED_UM_S``) is built from it.
    """

    full_speed_mm_s: float = 25.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.full_speed_mm_s) and self.full_speed_mm_s > 0.0):
            raise InputError(f"full_speed_mm_s must be > 0, got {self.full_speed_mm_s}")

    def command(self, duty: tuple[float, ...]) -> Command:
        """The twin's motor velocity and heater duties for the pins' mean levels.

        Parameters
        ----------
        duty : tuple of float
            Mean level of each pin of :data:`~relaxgrip.hardware.firmware_sim.PINS`.
        """
        en, in1, in2, heater0, heater1 = duty
        # A direction pin that changed within the step drives for the part it was high.
        v = en * (in1 - in2) * self.full_speed_mm_s
        return Command(motor_velocity_mm_s=v, heater_duty=(heater0, heater1))


def firmware_for_twin(config: TwinConfig, drive: MotorDrive, load_cell: bool) -> FirmwareImage:
    """The firmware built for a twin's gripper: its velocity limit, encoder and motor
    (speed at full duty, velocity lag).

    Raises
    ------
    FirmwareToolchainError
        If avr-gcc or simavr is missing.
    """
    return build_firmware({
        "MAX_VELOCITY_UM_S": round(config.motor.max_velocity_mm_s * 1000.0),
        "ENCODER_NM_PER_COUNT": round(config.motor.encoder_resolution_mm * 1e6),
        "MOTOR_FULL_SPEED_UM_S": round(drive.full_speed_mm_s * 1000.0),
        "MOTOR_LAG_MS": round(config.motor.lag_s * 1000.0),
        "LOAD_CELL": int(load_cell),
    })


class FirmwareEndpoint:
    """The simulated MCU on a transport, its pins wired to a twin.

    Parameters
    ----------
    transport : Transport
        The MCU's end of the link (the pty's master side).
    clock : Clock
        The emulator's clock: the host's :class:`~relaxgrip.clock.VirtualClock`
        in lockstep, a wall clock otherwise.
    plant : TwinPlant
        The twin and the frame channel (frames and ticks are published from it).
    twin_clock : VirtualClock
        The twin's own clock, which this endpoint moves with the AVR.
    image : FirmwareImage
        The firmware.
    drive : MotorDrive
        The motor driver's model.
    load_cell : Hx711Model or None
        The load cell whose conversions the simulated HX711 gives the firmware.
    step_s : float
        The fine grid of steps (s): a host frame is taken at its first boundary, and the
        lockstep answer found at this granularity.
    coarse_s : float
        Step between the host's frames (s), a multiple of ``step_s``.
    """

    def __init__(self, transport: Transport, clock: Clock, plant: TwinPlant,
                 twin_clock: VirtualClock, image: FirmwareImage, drive: MotorDrive,
                 load_cell: Hx711Model | None = None, step_s: float = 0.001,
                 coarse_s: float = 0.008) -> None:
        self.transport = transport
        self.clock = clock
        self.plant = plant
        self.twin: GripperTwin = plant.twin
        self.twin_clock = twin_clock
        self.drive = drive
        self.load_cell = load_cell
        self.sim = SimAvr(image)
        self._step = max(1, round(step_s * CPU_HZ))
        self._coarse = self._step * max(1, round(coarse_s / step_s))
        # The MCU has booted (its UART set up) when the emulator starts: its first
        # BOOT_STEPS steps run before the twin's time 0, outputs off.  A twin whose motor
        # is not fully open (one taken over mid-grasp) has its travel from encoder 0 turned
        # in during the boot, an edge every _BOOT_EDGE_CYCLES: the firmware counts from
        # power-up, as a real MCU that followed the motor from fully open would have.
        self._res_mm = self.twin.config.motor.encoder_resolution_mm
        counts = round(self.twin.motor_position_mm / self._res_mm)
        setup = _BOOT_STEPS * self._step  # the firmware's set-up: its interrupts on
        turn = math.ceil(abs(counts) * _BOOT_EDGE_CYCLES / self._step) * self._step
        boot = setup + (turn + self._step if counts else 0)
        self._t0 = clock.now() - boot / CPU_HZ
        self.sim.run_until(setup)
        if counts:
            self.sim.encoder_to(counts, setup + turn)
            self.sim.run_until(boot)
        self._at = boot  # the end of the last step, on the grid (cycles)
        self._lockstep = isinstance(clock, VirtualClock)
        self._command = Command()
        self._cell_sensor = False
        self._steps = 0
        self.sim.take_pins()
        self.frames_sent = 0
        self.bytes_in = 0
        self.bytes_out = 0
        self._host_frames = FrameDecoder()
        self._mcu_frames = FrameDecoder()
        self._waiting: list[int | None] = []  # host frames not answered yet: seq, or None
        self._observed = False  # a GetStatus (the host's observe) came since the last tick
        #: What the firmware drives, at each change: ``(time (s), (motor velocity setpoint
        #: (mm/s, 0 when disabled), heater duties from the pins))``.
        self.output_log: list[tuple[float, tuple[float, tuple[float, ...]]]] = []
        self.fault_flags = 0
        """Fault flags of the latest Status the firmware sent (delivered or not)."""
        self._ran = threading.Condition()

    # ------------------------------------------------------------------ time

    def _cycle_at(self, t_s: float) -> int:
        """The first boundary of the fine grid at or after host time ``t_s`` (cycles since
        power-up)."""
        g = self._step
        return max(0, math.ceil(round((t_s - self._t0) * CPU_HZ, 3) / g) * g)

    def _coarse_before(self, t_s: float) -> int:
        """The last coarse-grid boundary at or before host time ``t_s``."""
        g = self._coarse
        return max(0, math.floor(round((t_s - self._t0) * CPU_HZ, 3) / g) * g)

    def _time_of(self, cycle: int) -> float:
        return self._t0 + cycle / CPU_HZ

    def _step_once(self, cycles: int | None = None) -> None:
        sim = self.sim
        # On the grid: the AVR ends a step a few cycles late (its last instruction's).
        end = self._at + (self._step if cycles is None else cycles)
        t_end = self._time_of(end)
        self.twin_clock.sleep_until(t_end)
        self.twin.act(self._command)  # this step under the previous step's pins
        counts = round(self.twin.motor_position_mm / self._res_mm)
        cell = self.load_cell
        if cell is not None:
            if self._steps % 100 == 0:  # the object changes seldom: its load cell with it
                name = self.twin.truth().object_name
                self._cell_sensor = name is not None and get_object(name).force_sensor
            force = self.twin.contact_force_n if self._cell_sensor else 0.0
            for t_c, value in cell.feed(t_end, force):
                sim.hx711_push(value, round((t_c - self._t0) * CPU_HZ))
        self._steps += 1
        command = self.drive.command(sim.step(counts, end))
        # What the MCU drives: the heaters as their pins do; the motor as its setpoint
        # says (at velocity 0 the velocity loop holds position, its duty is no motion).
        enabled, velocity_um_s, _ = sim.mcu_setpoint()
        outputs = (velocity_um_s / 1000.0 if enabled else 0.0, command.heater_duty)
        with self._ran:
            if not self.output_log or self.output_log[-1][1] != outputs:
                self.output_log.append((t_end, outputs))
            self._command = command
            self._at = end
            self._ran.notify_all()

    def wait_ran(self, t_s: float, timeout_s: float = 2.0) -> bool:
        """Wait (wall clock) until the AVR has run as far as host time ``t_s`` takes it
        while the host is quiet (the last coarse boundary at or before it); whether it did.

        The counterpart of :meth:`~relaxgrip.hardware.emulator.TwinPlant.wait_applied`:
        a fault test that moves the clock with no host traffic waits here.
        """
        target = self._coarse_before(t_s)
        with self._ran:
            return self._ran.wait_for(lambda: self._at >= target, timeout_s)

    def run_to(self, cycle: int) -> None:
        """Co-simulate the AVR and the twin up to ``cycle`` (a boundary of the fine grid).

        A step goes to the next boundary of the coarse grid, or the whole coarse step
        from one, or to ``cycle`` if that comes first.  The partition of time into steps
        thus depends on the target alone, not on how many polls reached it (a poll
        without a frame catches up to a coarse boundary only), so that a run is the same
        run whatever the threads' timing.
        """
        coarse = self._coarse
        while self._at < cycle:
            next_boundary = (self._at // coarse + 1) * coarse
            self._step_once(min(next_boundary, cycle) - self._at)

    # ------------------------------------------------------------------ link

    def _publish(self) -> None:
        """Frames and a tick of the twin at the AVR's time, on the frame channel."""
        self.plant.encoder_position_um(self.twin_clock.now())

    def _track(self, data: bytes) -> None:
        """Note what each host frame in ``data`` waits for (docs/protocol.md §4: one answer
        per non-empty frame)."""
        for item in self._host_frames.feed(data):
            # A frame whose CRC failed has no seq: its answer is an Error of type 0.
            self._waiting.append(item.seq)
            if isinstance(item, Packet):
                self._observed |= isinstance(item.message, GetStatus)

    def _answered(self, out: bytes) -> None:
        """Note the fault flags of each Status in ``out`` (the firmware's bytes, each once)
        and strike off the host frames it answers."""
        for item in self._mcu_frames.feed(out):
            if not isinstance(item, Packet):
                continue
            msg = item.message
            if isinstance(msg, Status):
                self.fault_flags = msg.fault_flags
            if not self._waiting:
                continue
            if isinstance(msg, Status) and msg.unsolicited:
                continue
            if isinstance(msg, ErrorReply) and msg.offending_type == 0:
                key: int | None = None
            elif isinstance(msg, Status | HelloAck | ErrorReply):
                key = msg.ack_seq
            else:
                continue
            if key in self._waiting:
                self._waiting.remove(key)

    def poll(self, timeout_s: float = 0.0) -> None:
        """Read what the host sent (waiting up to ``timeout_s``), run the AVR, send its bytes.

        In lockstep the AVR runs on until it has answered every host frame (for at most
        50 ms of its time past the frame's arrival), and the host's clock follows it.
        """
        data = self.transport.read(timeout_s)
        now = self.clock.now()
        # A frame is taken at the first step after its arrival; in lockstep, time without
        # one is caught up on the coarse grid only (see run_to).
        self.run_to(self._cycle_at(now) if data or not self._lockstep
                    else self._coarse_before(now))
        out = b""
        if data:
            self.bytes_in += len(data)
            self.sim.write(data)
            if self._lockstep:
                self._track(data)
                limit = self._at + round((len(data) * BYTE_S + 0.05) * CPU_HZ)
                # One step for the frame and a Status back (most answers), then fine ones.
                first = math.ceil(((len(data) + _ANSWER_BYTES) * BYTE_S + _TURNAROUND_S)
                                  * CPU_HZ / self._step) * self._step
                while self._waiting and self._at < limit:
                    self._step_once(first)
                    first = self._step
                    more = self.sim.read()
                    self._answered(more)
                    out += more
                self._waiting.clear()  # an MCU that did not answer: the host's timeout says so
        rest = self.sim.read()
        self._answered(rest)
        out += rest
        # The host reads frames and truth after its GetStatus (SerialGripper.observe): in
        # lockstep a tick then is all it needs; in wall-clock time every poll sends one.
        if self._observed or not self._lockstep:
            self._publish()
            self._observed = False
        if out:
            if self._lockstep:
                self.clock.sleep_until(self._time_of(self._at))
            self.bytes_out += len(out)
            self.frames_sent += out.count(0)
            self.transport.write(out)

    def serve(self, stop: threading.Event, poll_s: float = 0.002) -> None:
        """Poll until ``stop`` is set (the emulator's thread)."""
        while not stop.is_set():
            self.poll(poll_s)

    def close(self) -> None:
        """Free the simulator."""
        self.sim.close()
