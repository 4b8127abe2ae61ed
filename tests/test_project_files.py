"""The files a user of the package expects beside the code: licence, citation, version."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from tests.clitools import run_main

ROOT = Path(__file__).resolve().parents[1]


def test_the_license_is_the_mit_text_the_package_declares() -> None:
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert declared["project"]["license"] == {"text": "MIT"}
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License\n")
    assert "Permission is hereby granted, free of charge" in text
    assert 'THE SOFTWARE IS PROVIDED "AS IS"' in text


def test_the_citation_cites_the_paper_and_the_package_s_version() -> None:
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0"
    assert cff["version"] == declared["project"]["version"]
    paper = cff["preferred-citation"]
    assert paper["title"].startswith("Relaxation-Aware Multimodal Sensing of Soft Gripper")
    assert [a["family-names"] for a in paper["authors"]] == ["Wang", "Wu", "Zheng", "Dong"]


def test_version_prints_the_installed_version(monkeypatch, capsys) -> None:
    from relaxgrip import __version__

    code, out, _ = run_main(["--version"], monkeypatch, capsys)
    assert (code, out) == (0, f"relaxgrip {__version__}\n")
