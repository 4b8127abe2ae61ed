"""The compiled firmware in simavr behind the emulator's pseudo-terminal, driving the twin.

:class:`FirmwareEndpoint` takes the place of the Python MCU
(:class:`~relaxgrip.hardware.protocol.McuEndpoint`) in
:class:`~relaxgrip.hardware.emulator.McuEmulator`: the host's bytes go to the
simulated ATmega328P's UART and its answers back to the pty; the twin's motor
is driven by the firmware's motor pins, its heaters by the heater pins, and
the twin's motor motion drives the encoder pins; the load cell's conversions
are shifted out of a simulated HX711.

Co-simulation, in steps of ``step_s`` (2 ms, the firmware's control period) of
simulated time on a fixed grid:
the pins' mean levels over a step (:class:`MotorDrive` turns the enable duty
and direction into a closing velocity) drive the twin over the next step; the
twin's motor position at the end of a step becomes evenly spaced encoder
edges within it.  A pin therefore acts on the twin 1.5 steps later on
average (3 ms), far inside the motor's 50 ms lag.

Time (docs/emulator.md): in lockstep the AVR runs, step by step, up to the
host's virtual time when a frame arrives, takes the frame at the line rate and
runs on until it has answered (the UART idle for ``idle_s``); the host's clock
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
    PinReport,
    SimAvr,
    build_firmware,
)
from relaxgrip.hardware.hx711 import Hx711Model
from relaxgrip.hardware.protocol.transport import Transport
from relaxgrip.twin import GripperTwin, TwinConfig
from relaxgrip.twin.objects import get_object

if TYPE_CHECKING:
    from relaxgrip.hardware.emulator import TwinPlant

__all__ = ["FirmwareEndpoint", "MotorDrive", "firmware_for_twin"]

#: Steps the firmware runs before the emulator's start (it sets up its UART in microseconds).
_BOOT_STEPS = 5


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

    def command(self, pins: PinReport) -> Command:
        """The twin's motor velocity and heater duties for the pins' mean levels."""
        closing = pins.duty("motor_in1")
        opening = pins.duty("motor_in2")
        # A direction pin that changed within the step drives for the part it was high.
        drive = closing - opening
        v = pins.duty("motor_en") * drive * self.full_speed_mm_s
        return Command(motor_velocity_mm_s=v,
                       heater_duty=(pins.duty("heater0"), pins.duty("heater1")))


def firmware_for_twin(config: TwinConfig, drive: MotorDrive, load_cell: bool) -> FirmwareImage:
    """The firmware built for a twin's gripper: its velocity limit, encoder and motor.

    Raises
    ------
    FirmwareToolchainError
        If avr-gcc or simavr is missing.
    """
    return build_firmware({
        "MAX_VELOCITY_UM_S": round(config.motor.max_velocity_mm_s * 1000.0),
        "ENCODER_NM_PER_COUNT": round(config.motor.encoder_resolution_mm * 1e6),
        "MOTOR_FULL_SPEED_UM_S": round(drive.full_speed_mm_s * 1000.0),
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
        Co-simulation step (s); the lockstep answer is found at this granularity.
    idle_s : float
        In lockstep, the AVR has answered once its UART has been idle this long.
    """

    def __init__(self, transport: Transport, clock: Clock, plant: TwinPlant,
                 twin_clock: VirtualClock, image: FirmwareImage, drive: MotorDrive,
                 load_cell: Hx711Model | None = None, step_s: float = 0.002,
                 idle_s: float = 0.001) -> None:
        self.transport = transport
        self.clock = clock
        self.plant = plant
        self.twin: GripperTwin = plant.twin
        self.twin_clock = twin_clock
        self.drive = drive
        self.load_cell = load_cell
        self.sim = SimAvr(image)
        self._step = max(1, round(step_s * CPU_HZ))
        self._idle = round(idle_s * CPU_HZ)
        # The MCU has booted (its UART set up) when the emulator starts: its first
        # BOOT_STEPS steps run before the twin's time 0, outputs off.
        boot = _BOOT_STEPS * self._step
        self._t0 = clock.now() - boot / CPU_HZ
        self.sim.run_until(boot)
        self._lockstep = isinstance(clock, VirtualClock)
        self._command = Command()
        self._cell_sensor = False
        self._steps = 0
        self._res_mm = self.twin.config.motor.encoder_resolution_mm
        self.sim.take_pins()
        self.frames_sent = 0
        self.bytes_in = 0
        self.bytes_out = 0

    # ------------------------------------------------------------------ time

    def _cycle_at(self, t_s: float) -> int:
        """The first step boundary at or after host time ``t_s`` (cycles since power-up)."""
        c = math.ceil(round((t_s - self._t0) * CPU_HZ, 3) / self._step) * self._step
        return max(0, c)

    def _time_of(self, cycle: int) -> float:
        return self._t0 + cycle / CPU_HZ

    def _step_once(self) -> None:
        sim = self.sim
        start = sim.cycle
        end = start + self._step
        self._command = self.drive.command(sim.take_pins())
        t_end = self._time_of(end)
        self.twin_clock.sleep_until(t_end)
        self.twin.act(self._command)  # [start, end] under the previous step's pins
        counts = round(self.twin.motor_position_mm / self._res_mm)
        sim.encoder_to(counts, end)
        cell = self.load_cell
        if cell is not None:
            if self._steps % 100 == 0:  # the object changes seldom: its load cell with it
                name = self.twin.truth().object_name
                self._cell_sensor = name is not None and get_object(name).force_sensor
            force = self.twin.contact_force_n if self._cell_sensor else 0.0
            for t_c, value in cell.feed(t_end, force):
                sim.hx711_push(value, round((t_c - self._t0) * CPU_HZ))
        self._steps += 1
        sim.run_until(end)

    def run_to(self, cycle: int) -> None:
        """Co-simulate the AVR and the twin up to ``cycle`` (rounded up to a step)."""
        while self.sim.cycle < cycle:
            self._step_once()

    # ------------------------------------------------------------------ link

    def _publish(self) -> None:
        """Frames and a tick of the twin at the AVR's time, on the frame channel."""
        self.plant.encoder_position_um(self.twin_clock.now())

    def _answered(self, drained: int) -> bool:
        """Whether the firmware, which read the host's last byte at ``drained``, has
        finished answering: its line quiet for ``idle_s`` since then."""
        return self.sim.cycle - max(self.sim.last_tx_cycle, drained) >= self._idle

    def poll(self, timeout_s: float = 0.0) -> None:
        """Read what the host sent (waiting up to ``timeout_s``), run the AVR, send its bytes."""
        data = self.transport.read(timeout_s)
        self.run_to(self._cycle_at(self.clock.now()))
        if data:
            self.bytes_in += len(data)
            injected = self.sim.cycle
            self.sim.write(data)
            if self._lockstep:
                limit = injected + round((len(data) * BYTE_S + 0.05) * CPU_HZ)
                drained: int | None = None
                while self.sim.cycle < limit:
                    self._step_once()
                    if self.sim.rx_pending:
                        continue
                    drained = self.sim.cycle if drained is None else drained
                    if self._answered(drained):
                        break
        out = self.sim.read()
        self._publish()
        if out:
            if self._lockstep:
                self.clock.sleep_until(self._time_of(self.sim.cycle))
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
