"""The fault matrix: every fault injected on every backend, and how fast the rig is safe.

A cell is one fault on one backend.  Every cell starts from the same hold:
the twin and the controller (``relax``, 3 N at 40 °C, heaters regulating) as
they were half a second into the hold, copied, and handed to the backend,
which runs them for :data:`LEAD_S` before the fault comes.  The cell then
measures, at the actuators (what the twin is driven with; what the MCU drives,
from its own output log), the time from the fault to the **safe state**:
motor stopped and both heaters off, for good (to the end of the cell).  The
budget is 200 ms plus one control period.  Time is the backends' virtual
time: the MCU emulator runs in lockstep, and a cell advances its clock in
1 ms steps, letting the MCU poll at each, wherever the host is quiet.

When a fault *is* a fault: most at once; a stalled camera once its newest
frame is older than the limit that defines a stall (RGB 200 ms; infrared
3 s for the controller, 2.5 s for the serial gripper's camera watch), which
is where its reaction is timed from (the cell's ``allowance_s``).

Each cell also checks the reason the system gives (one line) and the
recording (every cell records to MCAP): closed complete, read strictly.

**Backends.**  A column is a :class:`FaultBackend`: ``twin`` (the twin
itself; its controller is the safety), ``emulator`` (the twin behind the
Python MCU on a pseudo-terminal; the host and the MCU's watchdog) and
``firmware`` (the same with the compiled firmware in simavr as the MCU; its
outputs are its velocity setpoint and its heater pins).  A fault a backend
cannot have (a serial-link fault on the twin; any fault on the firmware
without its toolchain) is ``n/a`` with the reason.  Another backend is one
more :class:`FaultBackend` in :data:`BACKENDS` (``docs/safety.md``).
"""

from __future__ import annotations

import copy
import math
import os
import signal
import statistics
import tempfile
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from relaxgrip.backend import BackendInfo, Command, Frame, Gripper, Observation
from relaxgrip.clock import VirtualClock
from relaxgrip.control import GraspController, GraspPlan, bundle_estimator, run_loop
from relaxgrip.control.estimators import ForceEstimate, ForceEstimator
from relaxgrip.control.runner import LoopInterrupted
from relaxgrip.errors import InputError
from relaxgrip.hardware.protocol.codec import FrameDecoder, Packet, encode_frame
from relaxgrip.interrupts import STOP_SIGNALS, deferred, stop_signals
from relaxgrip.learning.store import ModelBundle
from relaxgrip.learning.training import load_default_models
from relaxgrip.perception.pipeline import Percept
from relaxgrip.twin import TWIN_VERSION, GripperTwin, TwinConfig

__all__ = ["BACKENDS", "BUDGET_S", "CONTROL_PERIOD_S", "FAULTS", "Fault", "FaultBackend",
           "FaultCell", "FaultMatrix", "run_fault_matrix"]

#: The control period (s): the loop runs at the RGB camera's 30 Hz.
CONTROL_PERIOD_S = 1.0 / 30.0
#: The reaction budget (s): 200 ms (the MCU watchdog's period) plus one control period.
BUDGET_S = 0.2 + CONTROL_PERIOD_S
#: Normal running on the backend before the fault (s).
LEAD_S = 1.0
#: How long a cell watches after the fault (s): past the budget, to see the safe state stay.
WATCH_S = 0.5
#: The hold every cell starts from.
HOLD_TARGET_N = 3.0
HOLD_TEMP_C = 40.0
#: Time step of a cell's clock where the host is quiet (s): the MCU polls at each.
STEP_S = 0.001
#: An infrared image read this much hotter (K) puts a 40 °C finger past the 70 °C cut-off.
OVERHEAT_K = 40.0
#: What a model that has gone wrong outputs (N).
ABSURD_FORCE_N = 1e6


@dataclass(frozen=True)
class Fault:
    """One row of the matrix.

    Attributes
    ----------
    name : str
        Its key (``relaxgrip bench faults --faults NAME``).
    description : str
        What is injected, in a line.
    link : bool
        A serial-link fault (no such fault on the twin).
    """

    name: str
    description: str
    link: bool = False


#: The rows, in the order of the table.
FAULTS: tuple[Fault, ...] = (
    Fault("host_silent", "the host stops sending (hung or killed mid-hold)", link=True),
    Fault("cable_cut", "the USB cable is cut, the MCU powered", link=True),
    Fault("corrupt_frames", "every MCU frame has a flipped byte", link=True),
    Fault("truncated_frames", "every MCU frame is cut in half", link=True),
    Fault("duplicate_seq", "the host's frames repeat one sequence number", link=True),
    Fault("stale_seq", "the host's sequence numbers jump 1000 back", link=True),
    Fault("rgb_stall", "the RGB camera stops delivering frames"),
    Fault("marker_lost", "the marker is out of view (black RGB frames)"),
    Fault("ir_stale", "the thermal camera delivers its last frame again and again"),
    Fault("ir_missing", "the thermal camera delivers no frame"),
    Fault("over_temperature", f"the thermal image reads {OVERHEAT_K:g} K hotter"),
    Fault("model_out_of_range", f"the force model outputs {ABSURD_FORCE_N:g} N"),
    *(Fault(f"{sig.name.lower()}_{where}", f"{sig.name} during a {label}")
      for where, label in (("hold", "hold"), ("recording", "recording's write"))
      for sig in STOP_SIGNALS),
)
_BY_NAME = {f.name: f for f in FAULTS}


class FaultBackend(Protocol):
    """A column of the matrix: a backend that takes over a hold and can be faulted.

    Every method but :meth:`open` acts on the gripper :meth:`open` returned.
    """

    name: str
    #: The backend's own stall limits (s), or None where only the controller watches.
    rgb_stall_s: float | None
    ir_stall_s: float | None

    def unsupported(self, fault: Fault) -> str | None:
        """Why ``fault`` does not exist on this backend, or None."""
        ...

    def open(self, twin: GripperTwin, clock: VirtualClock) -> Gripper:
        """A gripper running ``twin`` (a copy mid-hold, on ``clock``), reset and ready."""
        ...

    def outputs(self) -> list[tuple[float, float, tuple[float, float]]]:
        """What the actuators were driven with: ``(time, motor mm/s, heater duties)`` at
        each change (or each command), in time order."""
        ...

    def sync(self, t_s: float) -> None:
        """Let the actuator side (an MCU) run up to ``t_s`` while the host is quiet."""
        ...

    def inject(self, fault: Fault, gripper: Gripper) -> bool:
        """Inject a backend-level fault (the link's, a camera's); whether it did.

        The faults it does not inject are put in the host's view by the cell: a
        camera stall on the twin (the same frame again, or none), the marker
        out of view, a hot image, an absurd force model, a signal.
        """
        ...

    def mcu_reason(self) -> str | None:
        """What the MCU itself reports having done (its latched faults), if anything."""
        ...

    def close(self) -> None:
        """Release everything (threads, ports)."""
        ...


class _Passing:
    """A gripper passed through to ``inner`` (on ``clock``); subclasses change a part."""

    def __init__(self, inner: Gripper, clock: VirtualClock) -> None:
        self.inner = inner
        self.clock = clock

    @property
    def info(self) -> BackendInfo:
        """The inner backend's."""
        return self.inner.info

    def reset(self, seed: int | None = None) -> Observation:
        """Reset the inner backend."""
        return self.inner.reset(seed)

    def observe(self) -> Observation:
        """The inner backend's observation."""
        return self.inner.observe()

    def act(self, command: Command) -> None:
        """Apply ``command``."""
        self.inner.act(command)

    def close(self) -> None:
        """Close the inner backend."""
        self.inner.close()


class _Recorded(_Passing):
    """A gripper whose commands are logged with their time: the twin's actuator log."""

    def __init__(self, inner: Gripper, clock: VirtualClock) -> None:
        super().__init__(inner, clock)
        self.log: list[tuple[float, float, tuple[float, float]]] = []

    def act(self, command: Command) -> None:
        """Apply and log ``command`` (the arm counts as motion too)."""
        self.inner.act(command)
        moving = max(abs(command.motor_velocity_mm_s), abs(command.arm_velocity_mm_s))
        self.log.append((self.clock.now(), moving, command.heater_duty))


class TwinBackend:
    """The twin itself: no MCU, no link; the controller is its only safety."""

    name = "twin"
    rgb_stall_s: float | None = None
    ir_stall_s: float | None = None

    def __init__(self) -> None:
        self._gripper: _Recorded | None = None

    def unsupported(self, fault: Fault) -> str | None:
        """Link faults: the twin has no MCU link."""
        return "no MCU link: the twin runs in the host's process" if fault.link else None

    def open(self, twin: GripperTwin, clock: VirtualClock) -> Gripper:
        """The twin, its commands logged."""
        twin.clock = clock
        self._gripper = _Recorded(twin, clock)
        return self._gripper

    def outputs(self) -> list[tuple[float, float, tuple[float, float]]]:
        """The commands the twin was given."""
        return [] if self._gripper is None else list(self._gripper.log)

    def sync(self, t_s: float) -> None:
        """Nothing runs on its own on the twin."""

    def inject(self, fault: Fault, gripper: Gripper) -> bool:
        """None: the twin's camera faults are the cell's (on the observations)."""
        return False

    def mcu_reason(self) -> str | None:
        """No MCU."""
        return None

    def close(self) -> None:
        """Close the twin."""
        if self._gripper is not None:
            self._gripper.close()


class _SeqTamper:
    """The host's transport with its frames' sequence numbers rewritten (fault injection)."""

    def __init__(self, inner: Any, rewrite: Callable[[int], int]) -> None:
        self.inner = inner
        self.rewrite = rewrite
        self._decoder = FrameDecoder()

    def write(self, data: bytes) -> None:
        """Send ``data`` with each whole frame's sequence number rewritten."""
        out = b""
        for item in self._decoder.feed(data + b"\x00"):
            if isinstance(item, Packet):
                out += encode_frame(item.message, self.rewrite(item.seq), leading_delimiter=True)
        self.inner.write(out or data)

    def read(self, timeout_s: float) -> bytes:
        """The inner transport's bytes."""
        data: bytes = self.inner.read(timeout_s)
        return data

    def close(self) -> None:
        """Close the inner transport."""
        self.inner.close()


class EmulatorBackend:
    """The twin behind the MCU emulator on a pseudo-terminal, in lockstep.

    Parameters
    ----------
    firmware : bool
        The compiled firmware in simavr as the MCU (column ``firmware``) instead of
        the Python MCU (column ``emulator``).
    """

    def __init__(self, firmware: bool = False) -> None:
        self.firmware = firmware
        self.name = "firmware" if firmware else "emulator"
        self._emu: Any = None
        self._gripper: Any = None
        self.rgb_stall_s: float | None = None
        self.ir_stall_s: float | None = None

    def unsupported(self, fault: Fault) -> str | None:
        """Every fault exists here; without avr-gcc or simavr there is no firmware."""
        if self.firmware:
            from relaxgrip.hardware.firmware_sim import toolchain_missing

            missing = toolchain_missing()
            if missing:
                return f"no firmware toolchain: {', '.join(missing)} missing"
        return None

    def open(self, twin: GripperTwin, clock: VirtualClock) -> Gripper:
        """An emulated MCU running ``twin``, and a serial gripper on its pty (reset)."""
        from relaxgrip.hardware.emulator import open_emulated_gripper

        gripper, emu = open_emulated_gripper(clock=clock, grace_s=0.5, twin=twin,
                                             firmware=self.firmware)
        self._emu, self._gripper = emu, gripper
        self.rgb_stall_s = gripper.rgb.stall_s if gripper.rgb is not None else None
        self.ir_stall_s = gripper.ir.stall_s if gripper.ir is not None else None
        gripper.reset()
        return gripper

    def outputs(self) -> list[tuple[float, float, tuple[float, float]]]:
        """The MCU's outputs at each change, from its own log (the firmware's pins)."""
        if self._emu is None:
            return []
        outputs: list[tuple[float, float, tuple[float, float]]] = self._emu.outputs()
        return outputs

    def sync(self, t_s: float) -> None:
        """Wait (wall clock) for the MCU thread to poll at ``t_s``."""
        if self._emu is not None and not self._emu.wait_applied(t_s, 5.0):
            raise RuntimeError(f"the emulated MCU did not run to {t_s:.3f} s")

    def inject(self, fault: Fault, gripper: Gripper) -> bool:
        """The link's and the cameras' faults, where a real rig has them."""
        from relaxgrip.hardware.frame_channel import KIND_IR, KIND_RGB

        emu, client = self._emu, self._gripper.client
        if fault.name == "host_silent":
            return False  # the cell's: the host sends nothing more
        if fault.name == "cable_cut":
            emu.disconnect()
        elif fault.name == "corrupt_frames":
            emu.tamper_tx = lambda d: d[:3] + bytes([d[3] ^ 0x55]) + d[4:] if len(d) > 4 else d
        elif fault.name == "truncated_frames":
            emu.tamper_tx = lambda d: d[: len(d) // 2]
        elif fault.name == "duplicate_seq":
            stuck = client._seq  # the next frame's: every one after it repeats it
            client.transport = _SeqTamper(client.transport, lambda seq: stuck)
        elif fault.name == "stale_seq":
            client.transport = _SeqTamper(client.transport, lambda seq: (seq - 1000) % 65536)
        elif fault.name == "rgb_stall":
            emu.publisher.muted.add(KIND_RGB)
        elif fault.name in ("ir_stale", "ir_missing"):  # the last frame again: no new frame
            emu.publisher.muted.add(KIND_IR)
        else:
            return False
        return True

    def mcu_reason(self) -> str | None:
        """The emulated MCU's latched trip faults."""
        from relaxgrip.hardware.gripper import fault_names
        from relaxgrip.hardware.protocol.codec import TRIP_FAULTS

        if self._emu is None:
            return None
        flags = self._emu.fault_flags & int(TRIP_FAULTS)
        if not flags:
            return None
        return f"the MCU switched its outputs off: {', '.join(sorted(fault_names(flags)))}"

    def close(self) -> None:
        """Close the gripper (which stops the emulator)."""
        if self._gripper is not None:
            self._gripper.close()


#: The columns: name -> a factory of a fresh backend for one cell.
BACKENDS: dict[str, Callable[[], FaultBackend]] = {
    "twin": TwinBackend,
    "emulator": EmulatorBackend,
    "firmware": lambda: EmulatorBackend(firmware=True),
}


@dataclass
class FaultCell:
    """One fault on one backend.

    Attributes
    ----------
    fault, backend : str
        The row and the column.
    unsupported : str or None
        Why the fault does not exist on the backend (then nothing was run).
    reaction_s : float
        From the fault to the safe state (s, virtual time; nan if never).
    allowance_s : float
        How long after the injection the fault became one (a camera's stall
        limit; 0 for most).
    reason : str
        What the system said (its first line).
    recording_complete : bool
        The cell's recording closed with its summary and reads strictly.
    ok : bool
        Safe within :data:`BUDGET_S`, a one-line reason, the recording complete.
    """

    fault: str
    backend: str
    unsupported: str | None = None
    reaction_s: float = math.nan
    allowance_s: float = 0.0
    reason: str = ""
    recording_complete: bool = False
    ok: bool = False

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form."""
        return {"fault": self.fault, "backend": self.backend, "unsupported": self.unsupported,
                "reaction_s": self.reaction_s, "allowance_s": self.allowance_s,
                "reason": self.reason, "recording_complete": self.recording_complete,
                "ok": self.ok}


@dataclass
class FaultMatrix:
    """Every cell, repeated runs per cell (seeds).

    Attributes
    ----------
    cells : list of FaultCell
    backends, faults : tuple of str
        The columns and the rows.
    seeds : tuple of int
        The twin seeds of the runs (one hold per seed).
    twin_version : str
        The twin the holds ran on.
    budget_s : float
        The reaction budget the cells were held to (s).
    """

    cells: list[FaultCell]
    backends: tuple[str, ...]
    faults: tuple[str, ...]
    seeds: tuple[int, ...]
    twin_version: str = TWIN_VERSION
    budget_s: float = BUDGET_S

    def runs(self, fault: str, backend: str) -> list[FaultCell]:
        """The runs of one cell."""
        return [c for c in self.cells if c.fault == fault and c.backend == backend]

    def summary(self, fault: str, backend: str) -> dict[str, Any]:
        """One cell over its runs: ``n/a``, or the median and maximum reaction and all ok."""
        runs = self.runs(fault, backend)
        if not runs or runs[0].unsupported is not None:
            return {"unsupported": runs[0].unsupported if runs else "not run"}
        times = [c.reaction_s for c in runs]
        finite = [t for t in times if math.isfinite(t)]
        return {"runs": len(runs), "ok": all(c.ok for c in runs),
                "median_s": statistics.median(finite) if finite else math.nan,
                "max_s": max(times) if all(math.isfinite(t) for t in times) else math.nan,
                "allowance_s": max(c.allowance_s for c in runs), "reason": runs[-1].reason}

    @property
    def passed(self) -> tuple[int, int]:
        """Cells that passed in every run, of the cells that exist."""
        cells = [self.summary(f, b) for f in self.faults for b in self.backends]
        real = [c for c in cells if "unsupported" not in c]
        return sum(1 for c in real if c["ok"]), len(real)

    def to_dict(self) -> dict[str, Any]:
        """The ``relaxgrip bench faults --json`` object."""
        ok, total = self.passed
        return {"twin_version": self.twin_version, "budget_s": self.budget_s,
                "seeds": list(self.seeds), "backends": list(self.backends),
                "passed": ok, "cells": total,
                "matrix": {f: {b: self.summary(f, b) for b in self.backends}
                           for f in self.faults},
                "runs": [c.to_dict() for c in self.cells]}


@dataclass
class _Hold:
    """The hold every cell of one seed starts from."""

    twin: GripperTwin
    controller: GraspController
    t_s: float
    seed: int


def _hold(models: ModelBundle, seed: int) -> _Hold:
    """Run the twin to half a second into the hold and keep a copy of it and its controller."""
    cfg = TwinConfig(initial_temp_c=HOLD_TEMP_C)
    clock = VirtualClock()
    twin = GripperTwin(cfg, seed=seed, clock=clock)
    controller = GraspController(cfg.rig, bundle_estimator("relax", models), heat=cfg.heat)
    kept: list[_Hold] = []

    def at_hold(obs: Observation, ctl: GraspController) -> bool:
        held = ctl.estimate.hold_s
        if math.isfinite(held) and held >= 0.5:
            kept.append(_Hold(copy.deepcopy(twin), copy.deepcopy(ctl), obs.t_s, seed))
            return True
        return False

    plan = GraspPlan(target_n=HOLD_TARGET_N, temp_c=HOLD_TEMP_C, hold_s=math.inf, release=False)
    run_loop(twin, controller, clock, plan, 120.0, on_step=at_hold)
    if not kept:
        raise InputError(f"seed {seed}: the hold the fault matrix starts from never began")
    return kept[0]


class _Absurd:
    """A force estimator that outputs :data:`ABSURD_FORCE_N` once switched on."""

    def __init__(self, inner: ForceEstimator) -> None:
        self.inner = inner
        self.on = False
        self.first_t_s: float | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def update(self, percept: Percept, motor_position_mm: float) -> ForceEstimate:
        """The inner estimate, or the absurd one."""
        est = self.inner.update(percept, motor_position_mm)
        if not self.on:
            return est
        if self.first_t_s is None:
            self.first_t_s = percept.t_s
        return replace(est, force_n=ABSURD_FORCE_N, f_icfn_n=ABSURD_FORCE_N)


class _HostView(_Passing):
    """What the host's loop sees and sends: observation faults, and a host that goes silent."""

    def __init__(self, inner: Gripper, clock: VirtualClock) -> None:
        super().__init__(inner, clock)
        self.change: Callable[[Observation], Observation] | None = None
        self.silent = False
        self.first_changed_s: float | None = None
        # The newest new frame seen: its seq, its stamp and the time it reached the host.
        self.last_rgb: tuple[int, float, float] | None = None
        self.last_ir: tuple[int, float, float] | None = None

    def observe(self) -> Observation:
        """The inner observation, through the fault (if any); frames' times kept."""
        obs = self.inner.observe()
        if self.change is not None:
            changed = self.change(obs)
            if changed is not obs and self.first_changed_s is None:
                self.first_changed_s = obs.t_s
            obs = changed
        for attr in ("rgb", "ir"):  # the newest new frame the host has seen, and when
            frame: Frame | None = getattr(obs, attr)
            last = getattr(self, f"last_{attr}")
            if frame is not None and (last is None or frame.seq != last[0]):
                setattr(self, f"last_{attr}", (frame.seq, frame.t_s, obs.t_s))
        return obs

    def act(self, command: Command) -> None:
        """Send ``command``, unless the host has gone silent."""
        if not self.silent:
            self.inner.act(command)


def _black(obs: Observation) -> Observation:
    if obs.rgb is None:
        return obs
    return replace(obs, rgb=Frame(obs.rgb.t_s, obs.rgb.seq, np.zeros_like(obs.rgb.image)))


def _frozen(attr: str) -> Callable[[Observation], Observation]:
    held: dict[str, Frame] = {}

    def change(obs: Observation) -> Observation:
        frame = getattr(obs, attr)
        if frame is None:
            return obs
        kept = held.setdefault(attr, frame)
        return replace(obs, rgb=kept) if attr == "rgb" else replace(obs, ir=kept)

    return change


def _no_ir(obs: Observation) -> Observation:
    return obs if obs.ir is None else replace(obs, ir=None)


def _hot(obs: Observation) -> Observation:
    if obs.ir is None:
        return obs
    image = np.asarray(obs.ir.image, dtype=np.float32) + np.float32(OVERHEAT_K)
    return replace(obs, ir=Frame(obs.ir.t_s, obs.ir.seq, image))


def _safe_since(outputs: Sequence[tuple[float, float, tuple[float, float]]]) -> float:
    """Since when the actuators have been off for good (nan if they are not off at the end)."""
    since = math.nan
    for t, moving, duty in outputs:
        off = moving == 0.0 and duty[0] == 0.0 and duty[1] == 0.0
        if not off:
            since = math.nan
        elif math.isnan(since):
            since = t
    return since


def _recording_complete(path: Path) -> bool:
    """Closed with its summary, every message read strictly, as many as the summary counts."""
    from mcap.reader import make_reader

    from relaxgrip.recording.reader import iter_messages

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        count = sum(1 for _ in iter_messages(path))
    except Exception:  # a recording that does not read is not complete
        return False
    return (summary is not None and summary.statistics is not None
            and summary.statistics.message_count == count > 0)


@contextmanager
def _signals_caught() -> Iterator[None]:
    """The stop signals stop the loop as on the command line (only the main thread can)."""
    with stop_signals(even_if_ignored=STOP_SIGNALS):
        yield


def _reason(exc: BaseException | None, controller: GraspController, t_from: float) -> str:
    if isinstance(exc, LoopInterrupted):
        return "interrupted: motor stopped, heaters off"
    if exc is not None:
        return str(exc)
    for event in controller.log.events:
        if event.t_s >= t_from - 1e-9 and event.kind.value not in ("contact", "hold_onset"):
            return f"{event.kind.value}: {event.detail}"
    return ""


def run_cell(hold: _Hold, fault: Fault, backend_name: str, workdir: Path) -> FaultCell:
    """One fault on one backend, from ``hold`` (see the module notes)."""
    from relaxgrip.recording import McapRecorder

    backend = BACKENDS[backend_name]()
    why = backend.unsupported(fault)
    if why is not None:
        return FaultCell(fault.name, backend_name, unsupported=why)
    signalled = next((s for s in STOP_SIGNALS if fault.name.startswith(s.name.lower() + "_")),
                     None)
    if signalled is not None and threading.current_thread() is not threading.main_thread():
        return FaultCell(fault.name, backend_name,
                         unsupported="signals reach the main thread only")
    twin = copy.deepcopy(hold.twin)
    controller = copy.deepcopy(hold.controller)
    clock = VirtualClock(hold.t_s)
    path = workdir / f"{fault.name}-{backend_name}-{hold.seed}.mcap"
    cell = FaultCell(fault.name, backend_name)
    try:
        host = _HostView(backend.open(twin, clock), clock)
        t_inject = clock.now() + LEAD_S
        absurd = _Absurd(controller.estimator)
        state: dict[str, Any] = {"injected": False, "signal_s": None}
        t_end = t_inject + _allowance_at_most(fault, backend, controller) + WATCH_S \
            + CONTROL_PERIOD_S
        error: BaseException | None = None

        def hook(obs: Observation, ctl: GraspController) -> bool:
            if not state["injected"] and obs.t_s >= t_inject - 1e-9:
                state["injected"] = True
                _inject(fault, backend, host, absurd, signalled)
                if fault.name == "host_silent":
                    return True
                if signalled is not None and fault.name.endswith("_hold"):
                    state["signal_s"] = obs.t_s
                    os.kill(os.getpid(), signalled)  # handled as this returns: the loop stops
            return obs.t_s >= t_end - 1e-9

        class SignallingRecorder(McapRecorder):
            """Sends the cell's signal from inside a write (which must not be cut)."""

            def step(self, obs: Observation, ctl: GraspController, command: Command) -> None:
                if (state["injected"] and signalled is not None and state["signal_s"] is None
                        and fault.name.endswith("_recording")):
                    with deferred():
                        state["signal_s"] = obs.t_s
                        os.kill(os.getpid(), signalled)
                        super().step(obs, ctl, command)
                    return
                super().step(obs, ctl, command)

        controller.estimator = absurd
        with _signals_caught() if signalled is not None else _nothing(), \
                SignallingRecorder(path) as recorder:
            try:
                run_loop(host, controller, clock, None, 30.0, recorder=recorder, on_step=hook)
            except (LoopInterrupted, InputError) as exc:  # interrupted; the gripper's fault
                error = exc
        t_ref = _reference(fault, backend, host, absurd, controller, t_inject,
                           state["signal_s"])
        cell.allowance_s = max(0.0, t_ref - t_inject)
        # The host is done (stopped, or failed): an MCU runs on; step its clock.
        end = max(t_end, t_ref + WATCH_S)
        while clock.now() < end - 1e-9:
            clock.sleep_until(min(end, clock.now() + STEP_S))
            backend.sync(clock.now())
        safe = _safe_since(backend.outputs())
        cell.reaction_s = max(0.0, safe - t_ref) if math.isfinite(safe) else math.nan
        cell.reason = (_reason(error, controller, t_ref) or backend.mcu_reason() or "")
        cell.reason = cell.reason.strip()
    finally:
        backend.close()
    cell.recording_complete = _recording_complete(path)
    path.unlink(missing_ok=True)
    cell.ok = (math.isfinite(cell.reaction_s) and cell.reaction_s <= BUDGET_S + 1e-9
               and bool(cell.reason) and "\n" not in cell.reason and cell.recording_complete)
    return cell


@contextmanager
def _nothing() -> Iterator[None]:
    yield


def _inject(fault: Fault, backend: FaultBackend, host: _HostView, absurd: _Absurd,
            signalled: signal.Signals | None) -> None:
    """Put ``fault`` in place (after the period that just ended; a signal is the cell's)."""
    name = fault.name
    if signalled is not None:
        return
    if backend.inject(fault, host.inner):
        return
    changes: dict[str, Callable[[Observation], Observation]] = {
        "marker_lost": _black, "over_temperature": _hot, "ir_stale": _frozen("ir"),
        "rgb_stall": _frozen("rgb"), "ir_missing": _no_ir}
    if name == "host_silent":
        host.silent = True
    elif name == "model_out_of_range":
        absurd.on = True
    elif name in changes:
        host.change = changes[name]
    else:
        raise InputError(f"the {backend.name} backend cannot inject {name}")


def _stall_limits(fault: Fault, backend: FaultBackend, controller: GraspController
                  ) -> float | None:
    """The shortest limit that makes a camera's silence a stall (s), for stall faults."""
    if fault.name == "rgb_stall":
        limits = [controller.config.rgb_stale_after_s, backend.rgb_stall_s]
    elif fault.name in ("ir_stale", "ir_missing"):
        limits = [controller.temperature.limits.stale_after_s, backend.ir_stall_s]
    else:
        return None
    return min(x for x in limits if x is not None)


def _allowance_at_most(fault: Fault, backend: FaultBackend, controller: GraspController
                       ) -> float:
    """How long after the injection the fault may take to become one (s)."""
    limit = _stall_limits(fault, backend, controller)
    if limit is not None:
        return limit + CONTROL_PERIOD_S
    if fault.name == "over_temperature":  # the next thermal frame: 1 Hz
        return 1.0 + CONTROL_PERIOD_S
    return CONTROL_PERIOD_S


def _reference(fault: Fault, backend: FaultBackend, host: _HostView, absurd: _Absurd,
               controller: GraspController, t_inject: float, signal_s: float | None) -> float:
    """When the fault became one: the time its reaction is timed from."""
    name = fault.name
    limit = _stall_limits(fault, backend, controller)
    if limit is not None:
        last = host.last_rgb if name == "rgb_stall" else host.last_ir
        # The newest frame the host saw (the one frozen, or the last before none came).
        return (t_inject if last is None else last[1]) + limit
    if name == "marker_lost" and host.first_changed_s is not None:
        return host.first_changed_s
    if name == "over_temperature" and host.last_ir is not None and host.last_ir[2] > t_inject:
        return host.last_ir[2]  # the first hot frame reached the host
    if name == "model_out_of_range" and absurd.first_t_s is not None:
        return absurd.first_t_s
    if signal_s is not None:
        return signal_s
    return t_inject


def run_fault_matrix(backends: Sequence[str] = tuple(BACKENDS),
                     faults: Sequence[str] = tuple(_BY_NAME), seeds: Sequence[int] = (0,),
                     models: ModelBundle | None = None,
                     on_cell: Callable[[FaultCell], None] | None = None) -> FaultMatrix:
    """Every fault on every backend, once per seed (one hold per seed).

    Parameters
    ----------
    backends, faults : sequence of str
        Columns and rows (names of :data:`BACKENDS` and :data:`FAULTS`).
    seeds : sequence of int
        Twin seeds: each is one hold, every cell run from it.
    models : ModelBundle, optional
        The force models (default: the shipped ones).
    on_cell : callable, optional
        Told of every cell as it is done (progress).

    Returns
    -------
    FaultMatrix

    Raises
    ------
    InputError
        An unknown backend or fault, no seed, a negative one.
    """
    for b in backends:
        if b not in BACKENDS:
            raise InputError(f"unknown backend {b!r}; known: {', '.join(BACKENDS)}")
    for f in faults:
        if f not in _BY_NAME:
            raise InputError(f"unknown fault {f!r}; known: {', '.join(_BY_NAME)}")
    if not seeds or min(seeds) < 0:
        raise InputError("the fault matrix needs one or more seeds >= 0")
    bundle = models if models is not None else load_default_models()
    cells: list[FaultCell] = []
    with tempfile.TemporaryDirectory(prefix="relaxgrip-faults-") as tmp:
        for seed in seeds:
            hold = _hold(bundle, seed)
            for f in faults:
                for b in backends:
                    cell = run_cell(hold, _BY_NAME[f], b, Path(tmp))
                    cells.append(cell)
                    if on_cell is not None:
                        on_cell(cell)
    return FaultMatrix(cells, tuple(backends), tuple(faults), tuple(seeds))
