"""``relaxgrip emulator`` and ``relaxgrip check-rig``: the MCU emulator and a rig's self-check."""

from __future__ import annotations

import contextlib
import os
import signal
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from relaxgrip.cli._app import app, console, emit_json, float_option, int_option
from relaxgrip.errors import InputError
from relaxgrip.interrupts import stop_signals

if TYPE_CHECKING:
    from relaxgrip.perception.rig_check import RigCheck

#: The longest ``--duration-s``: a day. The emulator is a bench tool; a longer run is a typo
#: (1e308, inf), and leaving ``--duration-s`` out runs it until it is stopped.
MAX_DURATION_S = 86_400.0

@app.command("emulator")
def emulator(
    rig: Annotated[Path | None, typer.Option(
        "--rig", help="Rig file whose geometry the twin takes; its [serial] port becomes a "
                      "link to the pty and its [emulator] socket the frame channel.",
        show_default=False)] = None,
    seed: Annotated[int | None, int_option(
        "--seed", help="Twin seed (default: the rig file's, else 0).", show_default=False)
    ] = None,
    duration_s: Annotated[float | None, float_option(
        "--duration-s", help="Stop after this long, at most a day (default: until Ctrl-C).",
        show_default=False)] = None,
    mcu: Annotated[str, typer.Option(
        "--mcu", help="python (the protocol's state machine) or firmware (the compiled "
                      "firmware in simavr).")] = "python",
) -> None:
    """Run the twin behind a pseudo-terminal as an emulated MCU, in wall-clock time."""
    from relaxgrip.clock import WallClock
    from relaxgrip.hardware.emulator import (
        EMULATOR_DIR,
        McuEmulator,
        check_parent_dir,
    )
    from relaxgrip.hardware.rig_file import load_rig
    from relaxgrip.hardware.rig_twin import twin_config_for_rig
    from relaxgrip.twin import TwinConfig

    if seed is not None and seed < 0:
        raise InputError(f"--seed must be >= 0, got {seed}")
    if mcu not in ("python", "firmware"):
        raise InputError(f"--mcu must be python or firmware, got {mcu!r}")
    if duration_s is not None and not 0 < duration_s <= MAX_DURATION_S:
        raise InputError(f"--duration-s must be > 0 and at most {MAX_DURATION_S:g} s (a day), "
                         f"got {duration_s}")
    spec = load_rig(rig) if rig is not None else None
    config = twin_config_for_rig(spec) if spec is not None else TwinConfig()
    socket_path = (spec.emulator.socket if spec is not None and spec.emulator is not None
                   else str(EMULATOR_DIR / "frames.sock"))
    port = Path(spec.serial.port) if spec is not None else None
    # The default folder is made here (and removed when left empty); any other must exist
    # (listen() checks the socket's before it makes anything).
    make_dir = (EMULATOR_DIR in (Path(socket_path).parent, port and port.parent)
                and not os.path.lexists(EMULATOR_DIR))
    if port is not None and not (make_dir and port.parent == EMULATOR_DIR):
        check_parent_dir(port, "[serial] port")
    run_seed = seed if seed is not None else (
        spec.emulator.seed if spec is not None and spec.emulator is not None else 0)
    emu = McuEmulator(config, run_seed, WallClock(), firmware=mcu == "firmware")
    link: Path | None = None
    # Stopped as Ctrl-C does, its link and socket removed: by ``kill``, a closed terminal
    # (unless ``nohup`` ignores it: that stays), and Ctrl-C also where the shell started
    # it with SIGINT ignored (``&``).
    with stop_signals(even_if_ignored=(signal.SIGINT, signal.SIGTERM)) as caught:
        try:
            if make_dir:
                EMULATOR_DIR.mkdir()
            emu.listen(socket_path)
            if port is not None:
                link = _link_port(port, emu.port)
            emu.start()
            # One line each, however long the paths: scripts read the port from here.
            console.print(f"port: {emu.port}" + (f" (linked from {link})" if link else ""),
                          highlight=False, soft_wrap=True)
            console.print(f"frames: {socket_path}", highlight=False, soft_wrap=True)
            what = "firmware in simavr" if emu.firmware is not None else "Python MCU"
            console.print(f"seed {run_seed}; {what}; watchdog "
                          f"{emu.mcu_config.watchdog_default_ms} ms; Ctrl-C stops",
                          highlight=False)
            deadline = None if duration_s is None else time.monotonic() + duration_s
            with contextlib.suppress(KeyboardInterrupt):
                while deadline is None or time.monotonic() < deadline:
                    time.sleep(0.1)
                    if emu.error is not None:
                        raise InputError(f"emulator stopped: {emu.error}")
        except KeyboardInterrupt:  # stopped while starting: cleaned up below, like a timed stop
            pass
        finally:
            for sig in caught:  # a second signal must not cut the clean-up short
                signal.signal(sig, signal.SIG_IGN)
            emu.stop()
            if link is not None and link.is_symlink():
                link.unlink()
            if make_dir:
                with contextlib.suppress(OSError):  # not empty: someone else's files are there
                    EMULATOR_DIR.rmdir()


def _link_port(link: Path, port: str) -> Path:
    """Make ``link`` point at the emulator's ``port``; only an old emulator's link is replaced."""
    if link.is_symlink():
        if not os.readlink(link).startswith("/dev/pts/"):
            raise InputError(f"[serial] port {link} is a link to {os.readlink(link)}, not to "
                             "an emulator's pseudo-terminal: the emulator will not replace it")
    elif link.exists():
        raise InputError(f"[serial] port {link} exists and is not a link: "
                         "the emulator will not replace it")
    try:
        with contextlib.suppress(FileNotFoundError):
            link.unlink()
        os.symlink(port, link)
    except OSError as exc:
        raise InputError(f"[serial] port {link}: cannot link it to the emulator's "
                         f"pseudo-terminal: {exc.strerror or exc}") from None
    return link


@app.command("check-rig")
def check_rig_command(
    rig: Annotated[Path, typer.Argument(help="Rig file (TOML).")],
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Load a rig file, handshake with its MCU, grab a frame per camera, find the marker.

    Exits 1 when the marker the rig file names is not on the RGB frame.
    """
    from relaxgrip.hardware.rig_file import load_rig
    from relaxgrip.perception.rig_check import check_rig

    spec = load_rig(rig)
    result = check_rig(spec)
    if json_out:
        emit_json(result.to_dict())
    else:
        _print_rig_check(result)
    if not result.marker_found:
        raise typer.Exit(1)


def _print_rig_check(result: RigCheck) -> None:
    table = Table(title=f"rig {result.rig}")
    table.add_column("item")
    table.add_column("found")
    ir_min, ir_mean, ir_max = result.ir_temp_c
    rows = [
        ("serial port", result.port),
        ("firmware", result.firmware_id),
        ("MCU watchdog", f"{result.watchdog_ms} ms"),
        ("MCU velocity limit", f"{result.max_velocity_mm_s:g} mm/s"),
        ("MCU faults", ", ".join(result.fault_flags) or "none"),
        ("RGB frame", "x".join(str(n) for n in result.rgb_shape)),
        ("thermal frame", "x".join(str(n) for n in result.ir_shape)),
        ("thermal min / mean / max", f"{ir_min:.1f} / {ir_mean:.1f} / {ir_max:.1f} °C"),
        (f"marker id {result.marker_id}", "found" if result.marker_found else
         "NOT FOUND" + (f" (the frame shows id {', '.join(map(str, result.marker_ids_seen))}: "
                        "check [marker] id in the rig file)" if result.marker_ids_seen else "")),
    ]
    if result.marker_found:
        rows += [("marker distance", f"{result.marker_distance_mm:.1f} mm"),
                 ("marker vs rig file", f"{result.marker_offset_mm:.1f} mm off"),
                 ("reprojection", f"{result.reprojection_px:.2f} px")]
    for item, found in rows:
        table.add_row(item, found)
    console.print(table)
