"""Shared fixtures: the catalog of mechanism files."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
MECHANISMS = ROOT / "mechanisms"


def mechanism_files() -> list[Path]:
    """Every mechanism in the catalog, sorted by name."""
    return sorted(MECHANISMS.glob("*.toml"))


@pytest.fixture
def eightbar_path() -> Path:
    return MECHANISMS / "eightbar.toml"


def plant(monkeypatch: pytest.MonkeyPatch, name: str, change: Callable[[Any, Any], Any]) -> None:
    """Replace the registered engine ``name`` (in this process) by one whose every Result (a stopped run's
    partial one too) passes through ``change(mechanism, result)``: a fault put there on purpose."""
    from validators import engines

    class Planted(engines.Engine):
        real = engines.ENGINES[name]

        def applies(self, mech: Any) -> bool:
            return self.real.applies(mech)

        def solve(self, mech: Any, times: Any = None, **options: Any) -> Any:
            return change(mech, self.real.solve(mech, times, **options))

        def run(self, mech: Any) -> Any:
            try:
                res = self.real.run(mech)
            except Exception as exc:  # a run that stops keeps its samples, changed the same way
                if getattr(exc, "partial", None) is not None and len(exc.partial):
                    exc.partial = change(mech, exc.partial)
                raise
            return change(mech, res)

    Planted.name = name
    monkeypatch.setitem(engines.ENGINES, name, Planted())
