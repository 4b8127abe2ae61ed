"""``relaxgrip hold --backend serial:RIG.toml`` end to end, the emulator process as the rig.

The emulator runs in its own process in wall-clock time, as a real gripper would: the hold
reaches it only through its rig file (pty, frame socket), has no truth, tares the rig's force
reference and is scored against it.  A stop signal, a lost link: motor stopped, heaters off,
recording closed complete.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from relaxgrip.hardware.hx711 import Hx711Config
from relaxgrip.recording.reader import iter_messages, iter_records
from tests.clitools import run_cli

DOCS = Path(__file__).resolve().parents[2] / "docs"
#: A short hold at a setpoint near the emulated room's: the fingers heat in seconds.
HOLD = ("--estimator", "fixed", "--temp-c", "28", "--target-n", "4")


def _rig(tmp_path: Path, force_ref: str = "") -> Path:
    text = (DOCS / "rig-emulator.toml").read_text(encoding="utf-8")
    text = (text.replace('"/tmp/relaxgrip-emulator/tty"', f'"{tmp_path / "tty"}"')
            .replace('"/tmp/relaxgrip-emulator/frames.sock"', f'"{tmp_path / "frames.sock"}"'))
    # A shared test machine may hold a period up past the firmware's 200 ms: a longer watchdog.
    # A shared test machine may hold a period up past the firmware's 200 ms: a longer watchdog
    # and camera stall limits.
    text = (text.replace("reply_timeout_ms = 100", "reply_timeout_ms = 500\nwatchdog_ms = 1000")
            .replace("stall_ms = 200 ", "stall_ms = 2000 "))
    path = tmp_path / "rig.toml"
    path.write_text(text + force_ref, encoding="utf-8")
    return path


@pytest.fixture
def emulator(tmp_path: Path) -> Iterator[subprocess.Popen[str]]:
    """``relaxgrip emulator`` on the test's rig file, stopped (by its id) at the end."""
    proc = subprocess.Popen([sys.executable, "-m", "relaxgrip", "emulator", "--rig",
                             str(_rig(tmp_path)), "--duration-s", "600"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60.0
    while not ((tmp_path / "tty").is_symlink() and (tmp_path / "frames.sock").exists()):
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, "the emulator did not start"
        time.sleep(0.1)
    yield proc
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)


def _recording(path: Path, proc: subprocess.Popen[str]) -> None:
    """Wait until the hold's recording has begun (the loop runs), then a few seconds more."""
    deadline = time.monotonic() + 120.0
    while not (path.exists() and path.stat().st_size > 0):
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, "the hold did not start recording"
        time.sleep(0.2)
    time.sleep(4.0)


def _complete(path: Path) -> None:
    """The recording reads to its end, summary included (it was closed, not cut)."""
    assert sum(1 for _ in iter_records(path)) > 0


def test_a_hold_on_a_serial_rig_is_scored_against_its_tared_load_cell(
        tmp_path: Path, emulator: subprocess.Popen[str]) -> None:
    # The MCU's HX711 channel, its zero left to the tare (each unit's differs).
    cell = Hx711Config()
    rig = _rig(tmp_path, f'\n[force_ref]\nsource = "mcu"\nscale = {1.0 / cell.counts_per_n!r}'
                         f'\noffset_n = 0.0\nrate_hz = {cell.rate_sps}\nnoise_n = 0.01\n')
    record = tmp_path / "hold.mcap"
    out = run_cli("hold", "--backend", f"serial:{rig}", *HOLD, "--duration-s", "3",
                  "--record", record, "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["reference"] == "force_ref"
    assert "no ground truth" in result["reference_note"]
    assert result["estimator"] == "fixed"
    assert result["twin_version"].startswith("emulator rig")
    assert 0.0 <= result["mae_n"] < 4.0
    assert 0.0 < result["onset_error_n"] + 4.0 < 8.0
    _complete(record)
    topics = {topic for topic, _, _ in iter_messages(record)}
    assert "/relaxgrip/truth" not in topics  # nothing of the twin's truth reaches the host
    forces = [f for topic, _, m in iter_messages(record) if topic == "/relaxgrip/force_ref"
              for f in m["force_n"]]
    assert len(forces) > 30  # tared: the open gripper reads 0 N
    assert abs(forces[0]) < 0.05
    assert max(forces) > 2.0
    data = tmp_path / "data"
    built = run_cli("dataset", "from-recordings", record, "--out", data, "--json")
    assert built.returncode == 0, built.stderr
    assert json.loads(built.stdout)["counts"]["icfn_samples"] > 0


def test_sigterm_mid_hold_stops_it_and_closes_the_recording(
        tmp_path: Path, emulator: subprocess.Popen[str]) -> None:
    record = tmp_path / "stopped.mcap"
    hold = subprocess.Popen([sys.executable, "-m", "relaxgrip", "hold", "--backend",
                             f"serial:{tmp_path / 'rig.toml'}", *HOLD, "--duration-s", "60",
                             "--record", str(record), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _recording(record, hold)
    hold.send_signal(signal.SIGTERM)
    stdout, stderr = hold.communicate(timeout=60)
    assert hold.returncode == 130, stderr
    assert json.loads(stdout)["interrupted"] is True
    _complete(record)
    assert emulator.poll() is None  # the emulator is still there: the host stopped cleanly


def test_a_lost_link_mid_hold_is_one_error_and_a_complete_recording(
        tmp_path: Path, emulator: subprocess.Popen[str]) -> None:
    record = tmp_path / "lost.mcap"
    hold = subprocess.Popen([sys.executable, "-m", "relaxgrip", "hold", "--backend",
                             f"serial:{tmp_path / 'rig.toml'}", *HOLD, "--duration-s", "60",
                             "--record", str(record)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _recording(record, hold)
    emulator.kill()  # the gripper's end of the link and its cameras go at once
    emulator.wait(timeout=30)
    _, stderr = hold.communicate(timeout=60)
    assert hold.returncode == 2, stderr
    lines = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, stderr
    assert "gripper stopped" in lines[0], stderr
    _complete(record)


def test_a_serial_backend_is_its_rig_file_s_gripper(tmp_path: Path) -> None:
    out = run_cli("hold", "--backend", f"serial:{tmp_path / 'none.toml'}")
    assert out.returncode == 2
    assert out.stderr.count("error:") == 1
    assert "none.toml" in out.stderr
    out = run_cli("hold", "--backend", f"serial:{_rig(tmp_path)}", "--rig",
                  DOCS / "rigs" / "lab-125mm.toml")
    assert out.returncode == 2
    assert "give one of them" in out.stderr
    out = run_cli("hold", "--backend", "serial:")
    assert out.returncode == 2
    assert "names the rig file after 'serial:'" in out.stderr
