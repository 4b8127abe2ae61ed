"""``relaxgrip characterize``: the JSON contract, the paper's ranges, the figure, bad flags."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from relaxgrip.twin import TWIN_VERSION
from tests.clitools import assert_one_error_line, run_cli, run_main


def test_json_is_one_object_with_the_paper_figures(tmp_path: Path) -> None:
    png = tmp_path / "deform.png"
    proc = run_cli("characterize", "--json", "--plot", png)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1
    out = json.loads(lines[0])
    assert out["twin_version"] == TWIN_VERSION
    assert set(out["k80_drop_pct"]) == {"2", "4", "6", "8"}
    assert set(out["z80_ratio"]) == {"2", "4", "6", "8"}
    assert all(35.0 <= v <= 45.0 for v in out["k80_drop_pct"].values())
    assert all(1.6 <= v <= 1.7 for v in out["z80_ratio"].values())
    assert out["area_8n_mm2"]["27"] == pytest.approx(361.0, abs=20.0)
    assert out["area_8n_mm2"]["60"] == pytest.approx(626.0, abs=35.0)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_table_names_every_load(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run_main(["characterize"], monkeypatch, capsys)
    assert code == 0
    assert "k80 drop" in out
    assert "paper:" in out


@pytest.mark.parametrize(
    ("suffix", "expected"),
    [("deform.txt", "unsupported plot format"), ("no/dir.png", "does not exist"),
     ("a-dir.png", "is a directory; name the figure file to write")],
)
def test_bad_plot_path(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    suffix: str,
    expected: str,
) -> None:
    (tmp_path / "a-dir.png").mkdir()
    code, out, err = run_main(["characterize", "--plot", tmp_path / suffix], monkeypatch, capsys)
    assert_one_error_line(code, out, err, expected)
    assert not (tmp_path / suffix).is_file()
