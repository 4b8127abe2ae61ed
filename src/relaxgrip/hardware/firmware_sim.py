"""The MCU firmware (``firmware/``) built with avr-gcc and run in simavr, from Python.

:func:`build_firmware` makes the ELF with the firmware's own Makefile, for a
gripper's constants (``make ENCODER_NM_PER_COUNT=... MAX_VELOCITY_UM_S=...``),
into a cache folder keyed by the sources and the constants.  :class:`SimAvr`
runs that unmodified ELF on simavr's ATmega328P through ``firmware/sim/rgsim.c``,
a small C library compiled against libsimavr on first use and loaded with
ctypes: it wires the UART, the PWM and direction pins (their high time
integrated to the cycle), the encoder inputs and an HX711 around the chip, and
keeps a sleeping AVR from waiting in wall-clock time.

Nothing here knows the twin; :mod:`relaxgrip.hardware.firmware_emulator` puts
one behind these pins.
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol.codec import (
    PROTOCOL_VERSION,
    DecodeResult,
    FrameDecoder,
    Message,
    encode_frame,
)

__all__ = [
    "BYTE_S",
    "CPU_HZ",
    "PINS",
    "FirmwareImage",
    "FirmwareToolchainError",
    "PinReport",
    "SimAvr",
    "SimLink",
    "build_firmware",
    "build_shim",
    "cache_dir",
    "firmware_dir",
    "toolchain_missing",
    "watchdog_reactions",
]

CPU_HZ = 16_000_000
"""The ATmega328P's clock on an Arduino Uno or Nano (Hz)."""
BYTE_S = 10 / 115_200
"""A byte on the UART at 115 200 bit/s, 8N1 (s)."""
PINS = ("motor_en", "motor_in1", "motor_in2", "heater0", "heater1")
"""The output pins the simulation measures, in ``rgsim.c``'s order."""
#: Deepest the painted SRAM may be found untouched from (0x100 + .data + .bss), to RAMEND.
_RAMEND = 0x8FF
#: Offsets in ``rg_mcu_t`` (``src/rg_mcu.h``; avr-gcc aligns every field to a byte): its
#: configuration (the 16-byte firmware id, i32, u16, u16, u8), then handshaken, enabled,
#: session_minor, fault_flags (u16), watchdog_ms (u16), now_us, last_feed_us (u32),
#: last_seq (u16), velocity_um_s (i32), heater_duty (2 x u16).
_MCU_ENABLED = 16 + 4 + 2 + 2 + 1 + 1
_MCU_VELOCITY = _MCU_ENABLED + 2 + 2 + 2 + 4 + 4 + 2
_MCU_DUTY = _MCU_VELOCITY + 4
_MCU_SPAN = _MCU_DUTY + 4 - _MCU_ENABLED
_PAINT = 0xA5
_APT = "apt-get install gcc-avr avr-libc simavr libsimavr-dev"


class FirmwareToolchainError(InputError):
    """avr-gcc, avr-libc, simavr or a C compiler is missing."""


def firmware_dir() -> Path:
    """The firmware's sources: ``firmware/`` beside ``src/`` in a checkout.

    Raises
    ------
    FirmwareToolchainError
        If they are not there (a relaxgrip installed from a wheel has no firmware).
    """
    candidate = Path(__file__).resolve().parents[3] / "firmware"
    if (candidate / "Makefile").is_file() and (candidate / "src" / "main.c").is_file():
        return candidate
    raise FirmwareToolchainError(f"the firmware sources are not at {candidate}: the simulated "
                                 "firmware runs from a source checkout of relaxgrip")


def toolchain_missing() -> list[str]:
    """What the simulated firmware needs and this machine lacks (empty when complete)."""
    missing = [tool for tool in ("avr-gcc", "avr-objcopy", "avr-size", "make", "cc")
               if shutil.which(tool) is None]
    if not Path("/usr/include/avr/io.h").is_file() and not Path(
            "/usr/lib/avr/include/avr/io.h").is_file():
        missing.append("avr-libc")
    if not Path("/usr/include/simavr/sim_avr.h").is_file():
        missing.append("libsimavr-dev")
    return missing


def _require_toolchain() -> None:
    missing = toolchain_missing()
    if missing:
        raise FirmwareToolchainError(f"the simulated firmware needs {', '.join(missing)}: "
                                     f"{_APT}")


def cache_dir() -> Path:
    """Where built firmware and the simulator library are kept:
    ``$RELAXGRIP_CACHE_DIR`` or ``~/.cache/relaxgrip``."""
    root = os.environ.get("RELAXGRIP_CACHE_DIR")
    base = Path(root) if root else Path(os.path.expanduser("~")) / ".cache" / "relaxgrip"
    return base / "firmware"


def _digest(paths: list[Path], extra: str) -> str:
    h = hashlib.sha256(extra.encode())
    for path in sorted(paths):
        h.update(str(path.name).encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


@contextlib.contextmanager
def _building(final: Path) -> Iterator[Path]:
    """A temporary folder beside ``final`` that becomes it (atomically) if the block ends
    well; a concurrent build of the same key wins the rename and this one is dropped."""
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=final.name + ".", dir=final.parent))
    try:
        yield tmp
        try:
            tmp.rename(final)
        except OSError:
            if not final.is_dir():
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def _run(cmd: list[str], cwd: Path | None = None) -> str:
    run = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    if run.returncode != 0:
        tail = (run.stderr or run.stdout).strip().splitlines()[-3:]
        raise InputError(f"{cmd[0]} failed: {' / '.join(tail)}")
    return run.stdout


@dataclass(frozen=True)
class FirmwareImage:
    """A built firmware.

    Attributes
    ----------
    elf : Path
        The ELF simavr runs (``relaxgrip.hex`` beside it is what avrdude flashes).
    text_bytes, data_bytes, bss_bytes : int
        ``avr-size`` of the image: flash is text + data, static RAM data + bss.
    options : dict
        The make variables it was built with.
    """

    elf: Path
    text_bytes: int
    data_bytes: int
    bss_bytes: int
    options: Mapping[str, int | str]

    def symbol(self, name: str) -> int:
        """Data-space address of the firmware's variable ``name`` (from ``avr-nm``)."""
        for line in _run(["avr-nm", str(self.elf)]).splitlines():
            parts = line.split()
            if len(parts) == 3 and parts[2] == name and parts[1] in "bBdD":
                return int(parts[0], 16) - 0x800000  # avr-gcc puts SRAM at 0x800000
        raise InputError(f"{self.elf}: no variable {name!r} in the firmware")

    @property
    def flash_bytes(self) -> int:
        """Flash used (text + initialised data)."""
        return self.text_bytes + self.data_bytes

    @property
    def static_ram_bytes(self) -> int:
        """SRAM used before the stack (data + bss)."""
        return self.data_bytes + self.bss_bytes


def _size(elf: Path) -> tuple[int, int, int]:
    lines = _run(["avr-size", "--format=berkeley", str(elf)]).strip().splitlines()
    text, data, bss = (int(v) for v in lines[-1].split()[:3])
    return text, data, bss


def build_firmware(options: Mapping[str, int | str] | None = None) -> FirmwareImage:
    """Build the firmware for a gripper's constants (cached).

    Parameters
    ----------
    options : mapping, optional
        Make variables of ``firmware/src/config.h`` (``MAX_VELOCITY_UM_S``,
        ``ENCODER_NM_PER_COUNT``, ``LOAD_CELL``, ...); default: its defaults.

    Returns
    -------
    FirmwareImage

    Raises
    ------
    FirmwareToolchainError
        If avr-gcc or avr-libc is missing.
    InputError
        If make fails (an option the code refuses, e.g.).
    """
    _require_toolchain()
    opts = dict(sorted((options or {}).items()))
    src = firmware_dir()
    files = [src / "Makefile", *sorted((src / "src").glob("*.[ch]"))]
    compiler = _run(["avr-gcc", "--version"]).splitlines()[0]
    key = _digest(files, repr(opts) + compiler)
    final = cache_dir() / f"fw-{key}"
    if not (final / "relaxgrip.elf").is_file():
        with _building(final) as tmp:
            args = [f"{k}={v}" for k, v in opts.items()]
            _run(["make", "-s", "-C", str(src), f"BUILD={tmp}", *args, str(tmp / "relaxgrip.hex")])
    text, data, bss = _size(final / "relaxgrip.elf")
    return FirmwareImage(final / "relaxgrip.elf", text, data, bss, opts)


def build_shim() -> Path:
    """``firmware/sim/rgsim.c`` compiled against libsimavr (cached); its path.

    Raises
    ------
    FirmwareToolchainError
        If simavr's headers or a C compiler are missing.
    """
    _require_toolchain()
    source = firmware_dir() / "sim" / "rgsim.c"
    key = _digest([source], _run(["cc", "--version"]).splitlines()[0])
    final = cache_dir() / f"rgsim-{key}"
    lib = final / "librgsim.so"
    if not lib.is_file():
        with _building(final) as tmp:
            _run(["cc", "-O2", "-shared", "-fPIC", "-Wall", "-Wextra", str(source), "-o",
                  str(tmp / "librgsim.so"), "-lsimavr"])
    return lib


def _load(lib_path: Path) -> ctypes.CDLL:
    lib = ctypes.CDLL(str(lib_path))
    u8p = ctypes.POINTER(ctypes.c_uint8)
    u64p = ctypes.POINTER(ctypes.c_uint64)
    sigs: dict[str, tuple[object, list[object]]] = {
        "rgsim_open": (ctypes.c_void_p, [ctypes.c_char_p, ctypes.c_uint32, ctypes.c_char_p,
                                         ctypes.c_int]),
        "rgsim_close": (None, [ctypes.c_void_p]),
        "rgsim_cycle": (ctypes.c_uint64, [ctypes.c_void_p]),
        "rgsim_run_until": (ctypes.c_int, [ctypes.c_void_p, ctypes.c_uint64]),
        "rgsim_error": (ctypes.c_char_p, []),
        "rgsim_uart_write": (None, [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_uint32]),
        "rgsim_uart_pending": (ctypes.c_uint32, [ctypes.c_void_p]),
        "rgsim_uart_read": (ctypes.c_uint32, [ctypes.c_void_p, u8p, ctypes.c_uint32]),
        "rgsim_uart_last_tx_cycle": (ctypes.c_uint64, [ctypes.c_void_p]),
        "rgsim_uart_tx_total": (ctypes.c_uint64, [ctypes.c_void_p]),
        "rgsim_take_pins": (ctypes.c_uint64, [ctypes.c_void_p, u64p, u8p, u64p, u64p]),
        "rgsim_encoder_to": (None, [ctypes.c_void_p, ctypes.c_int64, ctypes.c_uint64]),
        "rgsim_encoder_position": (ctypes.c_int64, [ctypes.c_void_p]),
        "rgsim_hx711_push": (ctypes.c_int, [ctypes.c_void_p, ctypes.c_int32, ctypes.c_uint64]),
        "rgsim_hx711_reads": (ctypes.c_uint32, [ctypes.c_void_p]),
        "rgsim_hx711_lost": (ctypes.c_uint32, [ctypes.c_void_p]),
        "rgsim_read_data": (ctypes.c_int, [ctypes.c_void_p, ctypes.c_uint16, u8p,
                                           ctypes.c_uint16]),
        "rgsim_step": (ctypes.c_int, [ctypes.c_void_p, ctypes.c_int64, ctypes.c_uint64,
                                      ctypes.POINTER(ctypes.c_double)]),
    }
    for name, (restype, argtypes) in sigs.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


@dataclass(frozen=True)
class PinReport:
    """The output pins over one stretch of simulated time.

    Attributes
    ----------
    span_cycles : int
        Cycles since the previous report.
    high_cycles : tuple of int
        Cycles each pin of :data:`PINS` was high in that stretch.
    level : tuple of int
        Each pin's level now (0 or 1).
    last_change_cycle : tuple of int
        Cycle of each pin's last change.
    edges : tuple of int
        Each pin's level changes since power-up.
    """

    span_cycles: int
    high_cycles: tuple[int, ...]
    level: tuple[int, ...]
    last_change_cycle: tuple[int, ...]
    edges: tuple[int, ...]

    def duty(self, pin: str) -> float:
        """Mean level of ``pin`` over the stretch (0..1)."""
        i = PINS.index(pin)
        return self.high_cycles[i] / self.span_cycles if self.span_cycles else float(
            self.level[i])


class SimAvr:
    """One simulated ATmega328P running a firmware ELF, with its board's pins.

    Parameters
    ----------
    image : FirmwareImage
        The firmware (:func:`build_firmware`).

    Raises
    ------
    FirmwareToolchainError
        If simavr is missing.
    InputError
        If simavr cannot load the ELF.
    """

    def __init__(self, image: FirmwareImage) -> None:
        self.image = image
        self._lib = _load(build_shim())
        err = ctypes.create_string_buffer(256)
        handle = self._lib.rgsim_open(str(image.elf).encode(), CPU_HZ, err, len(err))
        if not handle:
            raise InputError(f"simavr: {err.value.decode(errors='replace')}")
        self._h: int | None = handle
        n = len(PINS)
        self._high = (ctypes.c_uint64 * n)()
        self._level = (ctypes.c_uint8 * n)()
        self._since = (ctypes.c_uint64 * n)()
        self._edges = (ctypes.c_uint64 * n)()
        self._rx = (ctypes.c_uint8 * 65536)()
        self._duty = (ctypes.c_double * n)()
        self._mcu_addr: int | None = None

    def _handle(self) -> int:
        if self._h is None:
            raise InputError("the simulated MCU is closed")
        return self._h

    def close(self) -> None:
        """Free the simulator."""
        if self._h is not None:
            self._lib.rgsim_close(self._h)
            self._h = None

    @property
    def cycle(self) -> int:
        """CPU cycles since power-up."""
        return int(self._lib.rgsim_cycle(self._handle()))

    @property
    def time_s(self) -> float:
        """Simulated time since power-up (s)."""
        return self.cycle / CPU_HZ

    def run_until(self, cycle: int) -> None:
        """Run the AVR up to ``cycle``.

        Raises
        ------
        InputError
            If the firmware stopped (sleeping with interrupts off) or crashed.
        """
        if self._lib.rgsim_run_until(self._handle(), cycle) != 0:
            why = (self._lib.rgsim_error() or b"").decode(errors="replace").strip()
            raise InputError(f"the simulated firmware stopped at {self.time_s:.6f} s"
                             + (f": {why}" if why else ""))

    def run_for(self, seconds: float) -> None:
        """Run the AVR for ``seconds`` of simulated time."""
        self.run_until(self.cycle + round(seconds * CPU_HZ))

    def write(self, data: bytes) -> None:
        """Bytes from the host to the AVR's RX line (delivered at the line rate)."""
        self._lib.rgsim_uart_write(self._handle(), bytes(data), len(data))

    @property
    def rx_pending(self) -> int:
        """Host bytes the firmware has not read from its UART yet."""
        return int(self._lib.rgsim_uart_pending(self._handle()))

    def read(self) -> bytes:
        """Bytes the AVR sent since the last call."""
        n = self._lib.rgsim_uart_read(self._handle(), self._rx, len(self._rx))
        return bytes(self._rx[:n])

    @property
    def last_tx_cycle(self) -> int:
        """Cycle at which the AVR sent its latest byte."""
        return int(self._lib.rgsim_uart_last_tx_cycle(self._handle()))

    def take_pins(self) -> PinReport:
        """The output pins since the previous call (see :class:`PinReport`)."""
        span = self._lib.rgsim_take_pins(self._handle(), self._high, self._level, self._since,
                                         self._edges)
        return PinReport(int(span), tuple(self._high), tuple(self._level), tuple(self._since),
                         tuple(self._edges))

    def step(self, encoder_counts: int, end_cycle: int) -> tuple[float, ...]:
        """Move the encoder to ``encoder_counts`` by ``end_cycle`` (evenly), run to it, and
        return each pin's mean level over the step (:data:`PINS` order); a co-simulation
        step in one call.

        Raises
        ------
        InputError
            If the firmware stopped or crashed.
        """
        if self._lib.rgsim_step(self._handle(), encoder_counts, end_cycle, self._duty) != 0:
            self.run_until(end_cycle)  # raises with the reason
        return tuple(self._duty)

    def encoder_to(self, counts: int, by_cycle: int) -> None:
        """Move the encoder to ``counts`` (x4 quadrature counts) by ``by_cycle``, its edges
        evenly spaced from now."""
        self._lib.rgsim_encoder_to(self._handle(), counts, by_cycle)

    @property
    def encoder_counts(self) -> int:
        """The encoder position the pins show now (counts)."""
        return int(self._lib.rgsim_encoder_position(self._handle()))

    def hx711_push(self, counts: int, cycle: int) -> None:
        """A load-cell conversion the HX711 has ready at ``cycle`` (24-bit counts)."""
        if self._lib.rgsim_hx711_push(self._handle(), counts, cycle) != 0:
            raise InputError("the simulated HX711 holds 16 conversions already")

    @property
    def hx711_reads(self) -> int:
        """Conversions the firmware shifted out of the HX711."""
        return int(self._lib.rgsim_hx711_reads(self._handle()))

    @property
    def hx711_lost(self) -> int:
        """Conversions replaced before the firmware read them."""
        return int(self._lib.rgsim_hx711_lost(self._handle()))

    def read_data(self, addr: int, n: int) -> bytes:
        """``n`` bytes of the AVR's data space (registers, I/O, SRAM) from ``addr``."""
        buf = (ctypes.c_uint8 * n)()
        if self._lib.rgsim_read_data(self._handle(), addr, buf, n) != 0:
            raise InputError(f"AVR data 0x{addr:x}+{n} is outside its data space")
        return bytes(buf)

    def mcu_setpoint(self) -> tuple[bool, int, tuple[int, int]]:
        """The firmware's protocol state (``rg_mcu_t mcu`` in ``src/main.c``): whether it
        is enabled, its velocity setpoint (µm/s) and its heater duty setpoints
        (permyriad), read from its SRAM."""
        if self._mcu_addr is None:
            self._mcu_addr = self.image.symbol("mcu")
        raw = self.read_data(self._mcu_addr + _MCU_ENABLED, _MCU_SPAN)
        enabled = raw[0] != 0
        velocity = int.from_bytes(raw[_MCU_VELOCITY - _MCU_ENABLED:][:4], "little", signed=True)
        d = _MCU_DUTY - _MCU_ENABLED
        duty = (int.from_bytes(raw[d:d + 2], "little"), int.from_bytes(raw[d + 2:d + 4], "little"))
        return enabled, velocity, duty

    def stack_bytes(self) -> int:
        """Deepest the stack has reached since power-up (bytes below RAMEND), from the SRAM
        the simulator painted before the firmware started."""
        start = 0x100 + self.image.static_ram_bytes
        n = _RAMEND + 1 - start
        buf = (ctypes.c_uint8 * n)()
        self._lib.rgsim_read_data(self._handle(), start, buf, n)
        data = bytes(buf)
        untouched = len(data) - len(data.lstrip(bytes([_PAINT])))
        return n - untouched

    def __enter__(self) -> SimAvr:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()




class SimLink:
    """The host's end of a :class:`SimAvr`'s UART, on the AVR's clock (tests, benchmarks).

    Parameters
    ----------
    sim : SimAvr
        The simulated MCU.
    """

    def __init__(self, sim: SimAvr) -> None:
        self.sim = sim
        self.decoder = FrameDecoder()
        self.seq = 0
        self.delivered_cycle = 0
        """Cycle at which the AVR had the last byte written (its delimiter)."""

    def write(self, data: bytes) -> None:
        """Put ``data`` on the line now."""
        self.sim.write(data)
        self.delivered_cycle = self.sim.cycle + round(len(data) * BYTE_S * CPU_HZ)

    def send(self, message: Message, *, seq: int | None = None, version: int = PROTOCOL_VERSION,
             settle_s: float = 0.001, limit_s: float = 0.2) -> list[DecodeResult]:
        """Frame ``message`` (next seq unless given), send it and return what came back."""
        s = self.seq if seq is None else seq
        if seq is None:
            self.seq = (self.seq + 1) % 65536
        frame = encode_frame(message, s, version=version, leading_delimiter=True)
        return self.exchange(frame, settle_s, limit_s)

    def exchange(self, data: bytes, settle_s: float = 0.001,
                 limit_s: float = 0.2) -> list[DecodeResult]:
        """Send raw bytes; run until the firmware has read them all and its line has been
        quiet for ``settle_s`` since (at most ``limit_s`` past their line time); decode what
        it sent."""
        sim = self.sim
        self.write(data)
        settle = round(settle_s * CPU_HZ)
        limit = self.delivered_cycle + round(limit_s * CPU_HZ)
        slice_ = round(0.0002 * CPU_HZ)
        drained: int | None = None
        while sim.cycle < limit:
            sim.run_until(sim.cycle + slice_)
            if sim.rx_pending:
                drained = None
                continue
            drained = sim.cycle if drained is None else drained
            if sim.cycle - max(drained, sim.last_tx_cycle) >= settle:
                break
        return self.receive()

    def receive(self) -> list[DecodeResult]:
        """Decode what the AVR sent since the last call (packets and frame errors)."""
        return list(self.decoder.feed(self.sim.read()))

    def run_for(self, seconds: float) -> list[DecodeResult]:
        """Let ``seconds`` pass; what the AVR sent meanwhile."""
        self.sim.run_for(seconds)
        return self.receive()


def watchdog_reactions(link: SimLink, trials: int, rng: np.random.Generator) -> list[float]:
    """Inject ``trials`` link losses; the time from the last Command to all pins low, each.

    Each trial enables the MCU, sends 2-10 Commands at 30 Hz (motor closing, both
    heaters on) starting at a random phase, then falls silent; the firmware must
    then drive every output pin low, send an unsolicited Status with the WATCHDOG
    fault, and refuse the next Command with NOT_ENABLED.  The reaction is measured
    on the pins, from the last Command's arrival (its delimiter) to the last pin's
    fall.

    Parameters
    ----------
    link : SimLink
        The simulated MCU, after its handshake.
    trials : int
        Link losses to inject.
    rng : numpy.random.Generator
        Phases and command counts.

    Returns
    -------
    list of float
        Reaction times (s).

    Raises
    ------
    InputError
        If a trial does not end as described.
    """
    from relaxgrip.hardware.protocol.codec import (
        Command,
        ErrorCode,
        ErrorReply,
        FaultFlag,
        Packet,
        SetEnable,
        Status,
    )

    sim = link.sim
    out = []
    period = round(CPU_HZ / 30)
    for trial in range(trials):
        link.send(SetEnable(True))
        sim.run_for(float(rng.uniform(0.0, 1 / 30)))
        for _ in range(int(rng.integers(2, 11))):
            replies = link.send(Command(8_000, (8_000, 5_000)))
            if not any(isinstance(r, Packet) and isinstance(r.message, Status) for r in replies):
                raise InputError(f"watchdog trial {trial}: a Command got {replies}")
            sim.run_until(link.delivered_cycle + period)
        last = link.delivered_cycle
        if sim.take_pins().edges[PINS.index("heater0")] == 0:
            raise InputError(f"watchdog trial {trial}: the heater PWM never ran")
        replies = link.run_for(0.4)
        report = sim.take_pins()
        if any(report.level):
            raise InputError(f"watchdog trial {trial}: pins still high 400 ms after the link "
                             f"fell silent: {dict(zip(PINS, report.level, strict=True))}")
        trips = [r.message for r in replies if isinstance(r, Packet)]
        if not (len(trips) == 1 and isinstance(trips[0], Status) and trips[0].unsolicited
                and trips[0].fault_flags & FaultFlag.WATCHDOG):
            raise InputError(f"watchdog trial {trial}: no unsolicited WATCHDOG Status: {trips}")
        refused = [r.message for r in link.send(Command(1_000, (0, 0))) if isinstance(r, Packet)]
        if not (refused and isinstance(refused[0], ErrorReply)
                and refused[0].code == ErrorCode.NOT_ENABLED):
            raise InputError(f"watchdog trial {trial}: a Command after the trip got {refused}")
        out.append((max(report.last_change_cycle) - last) / CPU_HZ)
    return out
