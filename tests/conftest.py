"""Shared fixtures: the catalog of mechanism files."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MECHANISMS = ROOT / "mechanisms"


def mechanism_files() -> list[Path]:
    """Every mechanism in the catalog, sorted by name."""
    return sorted(MECHANISMS.glob("*.toml"))


@pytest.fixture
def eightbar_path() -> Path:
    return MECHANISMS / "eightbar.toml"
