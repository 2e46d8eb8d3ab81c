"""Writing output safely: one module every command uses.

Rules (docs/cli.md, "Output files"):

* **Inside the output folder.** The default folder is ``out/<safe name>``; a mechanism's
  ``name`` is free text, so the folder name is derived from it (:func:`safe_folder_name`)
  and can never climb out of ``out/``.
* **Atomic.** Every file is written to a temporary file in the folder it goes to and renamed
  into place (:func:`atomic_write`), so a crash, Ctrl-C or a full disk never leaves a truncated
  file that looks complete.
* **One run's files together.** :class:`OutputSet` stages a run's files in a private folder
  inside the output folder and renames them all into place while holding a lock on the folder,
  so two runs into the same ``--out`` leave one run's complete set, never a mix.
* **Errors name the path.** Any failure to write (an existing file where a folder should be,
  permission denied, disk full, a folder that cannot be created) is an :class:`OutputError`
  naming the path (CLI exit code 2).
"""

from __future__ import annotations

import contextlib
import fnmatch
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from ..errors import VloopError
from .options import check_file, check_folder, describe_os_error  # noqa: F401  (re-exported: one place for them)

DEFAULT_ROOT = Path("out")
_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")
MAX_FOLDER_NAME = 64


class OutputError(VloopError):
    """An output file or folder cannot be written (the message names it)."""


def safe_folder_name(name: str) -> str:
    """A folder name derived from free text: letters, digits, ``_ . -`` only, no leading dot,
    at most 64 characters; ``"mechanism"`` when nothing is left."""
    text = _UNSAFE.sub("_", name.replace("\x00", "")).strip("._-")[:MAX_FOLDER_NAME]
    return text or "mechanism"


def default_folder(name: str, root: str | Path = DEFAULT_ROOT) -> Path:
    """``out/<safe name>``: always a direct child of ``root``."""
    return Path(root) / safe_folder_name(name)


def plain_name(name: str) -> str:
    """A file name inside the output folder: no folder part, not "." or "..", not the staging area's."""
    bad = not name or "/" in name or "\\" in name or "\x00" in name or name in (".", "..")
    if bad or name.startswith(".vloop-stage-"):
        raise OutputError(f"{name!r} is not a plain file name: every output stays inside its folder", entry="out")
    return name


def ensure_folder(folder: str | Path) -> Path:
    """Create ``folder`` (and parents) or raise OutputError naming it."""
    folder = Path(folder)
    if "\x00" in str(folder):
        raise OutputError(f"output folder {str(folder)!r}: a path cannot contain a NUL character", entry="out")
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"output folder {folder}: exists and is not a folder", entry="out")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create the output folder {folder}: {describe_os_error(exc)}", entry="out") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"output folder {folder}: permission denied", entry="out")
    return folder


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", **open_kw: Any) -> Iterator[IO[Any]]:
    """Open a temporary file next to ``path``; on success rename it onto ``path``.

    On any exception (KeyboardInterrupt included) the temporary file is removed and ``path``
    is left as it was. OSErrors become OutputError naming ``path``.
    """
    path = Path(path)
    ensure_folder(path.parent)
    if path.is_dir():
        raise OutputError(f"cannot write {path}: a folder of that name is in the way", entry="out")
    if "b" not in mode:
        open_kw.setdefault("encoding", "utf-8")
        open_kw.setdefault("newline", "")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes it private (0600); a published file follows the umask
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {describe_os_error(exc)}", entry="out") from None
    try:
        with os.fdopen(fd, mode, **open_kw) as fh:
            yield fh
            fh.flush()
        os.replace(tmp, path)
    except OSError as exc:
        _unlink_quietly(tmp)
        raise OutputError(f"cannot write {path}: {describe_os_error(exc)}", entry="out") from None
    except BaseException:
        _unlink_quietly(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) atomically."""
    with atomic_write(path) as fh:
        fh.write(text)
    return Path(path)


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` atomically."""
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def _unlink_quietly(path: str | Path) -> None:
    with contextlib.suppress(OSError):
        os.unlink(path)


class OutputSet:
    """A run's output files (and folders), published together.

        with OutputSet(folder, owns=("report.html", "viewer")) as out:
            result.to_csv(out.stage / "results.csv")       # any writer, into the private staging folder
            out.write_text("notes.txt", "...")
        # on leaving without an exception: every staged entry renamed into folder, under a folder lock

    If the block raises (Ctrl-C included), nothing staged is published and the stage is removed,
    so the folder keeps the previous run's complete set (or nothing). Publishing is one step for a
    user: Ctrl-C during the renames is held until they are done (the new set is then complete, and the
    interrupt is raised after). ``owns`` names the entries (files or folders, ``fnmatch`` patterns) this
    kind of set may hold: those of the previous set that the new one does not have are removed, so the
    folder never holds a new summary beside an old report. A set whose names vary (NAME_1.toml, ...) keeps a
    ``record`` (a hidden file listing what it published): the next set of its kind removes those it does not
    have, and nothing else. ``published`` lists the paths. Staged names are plain file names (never a path).
    """

    def __init__(self, folder: str | Path, owns: Iterable[str] = (), record: str | None = None) -> None:
        self.folder = ensure_folder(folder)
        self.owns = tuple(owns)
        self.record = record
        self.published: list[Path] = []
        try:
            self.stage = Path(tempfile.mkdtemp(prefix=".vloop-stage-", dir=self.folder))
        except OSError as exc:
            raise OutputError(f"cannot write to {self.folder}: {describe_os_error(exc)}", entry="out") from None

    def path(self, name: str) -> Path:
        """Where a file is staged (for writers that want a path, e.g. matplotlib or pyarrow)."""
        return self.stage / plain_name(name)

    def write(self, name: str, fill: Callable[[IO[Any]], None], binary: bool = False) -> Path:
        """Stage ``name`` by calling ``fill(file_object)``."""
        text = {} if binary else {"encoding": "utf-8", "newline": ""}
        plain_name(name)
        try:
            with open(self.stage / name, "wb" if binary else "w", **text) as fh:
                fill(fh)
        except OSError as exc:
            raise OutputError(f"cannot write {self.folder / name}: {describe_os_error(exc)}", entry="out") from None
        return self.folder / name

    def write_text(self, name: str, text: str) -> Path:
        return self.write(name, lambda fh: fh.write(text))

    def final(self, path: str | Path) -> Path:
        """Where a staged path will be once published (a path outside the stage is returned as it is)."""
        path = Path(path)
        try:
            return self.folder / path.relative_to(self.stage)
        except ValueError:
            return path

    def publish(self) -> list[Path]:
        """Rename every staged entry into the folder (a staged folder replaces one of its name), and remove
        the previous set's entries this one does not have, holding an exclusive lock on the folder."""
        import fcntl

        names = sorted(p.name for p in self.stage.iterdir())
        for name in names:
            if (self.folder / name).is_dir() and not (self.stage / name).is_dir():
                self.discard()
                raise OutputError(
                    f"cannot write {self.folder / name}: a folder of that name is in the way", entry="out"
                )
        try:
            fd = os.open(self.folder, os.O_RDONLY)  # the folder itself is the lock: no lock file left behind
            try:
                fcntl.flock(fd, fcntl.LOCK_EX)
                with interrupts_held():
                    self._rename(names)
            finally:
                os.close(fd)  # closing releases the lock
        except OSError as exc:
            raise OutputError(f"cannot write to {self.folder}: {describe_os_error(exc)}", entry="out") from None
        finally:
            self.discard()
        return self.published

    def _rename(self, names: list[str]) -> None:
        old = [self.stage / f".old-{n}" for n in names]
        for name, aside in zip(names, old, strict=True):
            target = self.folder / name
            if (self.stage / name).is_dir() and target.is_dir():
                os.replace(target, aside)  # a folder cannot replace a non-empty one: move the old one aside first
            os.replace(self.stage / name, target)
            self.published.append(target)
        previous = self._recorded()
        for entry in self.folder.iterdir():
            ours = entry.name in previous or any(fnmatch.fnmatchcase(entry.name, p) for p in self.owns)
            if entry.name not in names and ours and not entry.name.startswith(".vloop-stage-"):
                _remove(entry)
        if self.record is not None:  # what this set holds, so that the next set of its kind removes what it lacks
            write_text(self.folder / self.record, "".join(f"{n}\n" for n in names))

    def _recorded(self) -> set[str]:
        """The entries the previous set of this kind published (its record), plain names only."""
        if self.record is None:
            return set()
        try:
            lines = (self.folder / self.record).read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError):
            return set()
        out = set()
        for n in lines:
            with contextlib.suppress(OutputError):
                out.add(plain_name(n))
        return out - {self.record}

    def discard(self) -> None:
        shutil.rmtree(self.stage, ignore_errors=True)

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.publish()
        else:
            self.discard()


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Hold SIGINT (Ctrl-C) until the block is done, then raise KeyboardInterrupt if one came (main thread only)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: came.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old if old is not None else signal.default_int_handler)
    if came:
        raise KeyboardInterrupt
