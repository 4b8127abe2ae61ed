"""``check-rig`` and ``hold --backend``: bad input is one line and exit 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "relaxgrip", *args], capture_output=True,
                          text=True, timeout=120, check=False)


def test_check_rig_bad_file_and_missing_device(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text((DOCS / "rig-example.toml").read_text(encoding="utf-8")
                   .replace("fps = 30.0", "fps = -1.0"), encoding="utf-8")
    out = _run("check-rig", str(bad))
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0
    assert "[rgb] fps must be > 0" in out.stderr
    if Path("/dev/ttyACM0").exists():  # a real MCU is plugged in: nothing is missing
        return
    out = _run("check-rig", str(DOCS / "rig-example.toml"))
    assert out.returncode == 2
    assert "cannot open serial port /dev/ttyACM0" in out.stderr


def test_hold_rejects_an_unknown_backend() -> None:
    out = _run("hold", "--backend", "robot", "--duration-s", "10")
    assert out.returncode == 2
    assert "--backend must be twin or emulator, got 'robot'" in out.stderr
