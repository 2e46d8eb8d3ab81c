"""Files the studio may touch: only inside the folder it was started on (no ``..``, no absolute path, no symlink that
leads out), with the suffixes of what it reads and writes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

SUFFIXES = {".toml", ".svg", ".pdf", ".dxf", ".html"}


class JailError(ValueError):
    """A path the studio will not touch (the message says why)."""


def inside(root: Path | None, rel: Any, suffixes: set[str] | frozenset[str] = frozenset(SUFFIXES)) -> Path:
    """``root / rel`` resolved (symlinks followed), refused unless it stays inside ``root`` with a known suffix."""
    if root is None:
        raise JailError("this studio was started without a folder: it reads and writes no file")
    if not isinstance(rel, str) or not rel or len(rel) > 255 or "\x00" in rel:
        raise JailError("a file name inside the studio's folder is needed")
    given = Path(rel)
    if given.is_absolute() or ".." in given.parts or given.drive:
        raise JailError(f"{rel[:80]!r}: give a path inside the studio's folder, without '..'")
    base = root.resolve()
    path = (base / given).resolve()
    if not path.is_relative_to(base) or path == base:
        raise JailError(f"{rel[:80]!r} leads outside the studio's folder")
    if path.suffix.lower() not in suffixes:
        raise JailError(f"{rel[:80]!r}: the studio reads and writes {', '.join(sorted(suffixes))} files only")
    if not path.parent.is_dir():
        raise JailError(f"{rel[:80]!r}: no such folder inside the studio's folder")
    return path


def listing(root: Path | None, limit: int = 500) -> list[str]:
    """The mechanism files under ``root`` (relative paths; symlinks that lead out left out)."""
    if root is None:
        return []
    base = root.resolve()
    out = []
    for p in sorted(base.rglob("*.toml")):
        if len(out) >= limit:
            break
        if p.resolve().is_relative_to(base) and not any(part.startswith(".") for part in p.relative_to(base).parts):
            out.append(p.relative_to(base).as_posix())
    return out
