"""Every option's value, checked by one parser that the command line, the files and the environment share.

    parse_size("2G")                          # 2147483648 (--memory-budget, VLOOP_MEMORY_BUDGET, [solver])
    OPTIONS["workers"].parse("2")             # 2
    OPTIONS["scheduler"].parse("host:8786")   # "tcp://host:8786"

A value that does not parse is one :class:`OptionError` naming the option (as the user wrote it:
``--workers``, ``VLOOP_MEMORY_BUDGET``, ``memory_budget``) and the accepted values; the CLI prints it as
one line and exits with code 2. Numbers must be finite and in range (nan, inf, 10**400, 1e308 where it
makes no sense, a string, a bool and a nested list are refused); counts are integers.
"""

from __future__ import annotations

import errno
import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import VloopError
from ..runner import parse_address


class OptionError(VloopError, ValueError):
    """An option's value is not one it accepts (the message names the option and what it accepts)."""


def show(value: Any, limit: int = 60) -> str:
    """A short, safe repr of a user value for a message (deep nesting, huge strings, control characters)."""
    try:
        text = repr(value)
    except (RecursionError, ValueError):
        text = f"<{type(value).__name__} nested too deeply>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _refuse(where: str, what: str, value: Any) -> OptionError:
    return OptionError(f"{where}: must be {what}, got {show(value, 40)}", entry=where.lstrip("-").replace("-", "_"))


# ---------------------------------------------------------------- sizes

_UNITS = {"": 1, "B": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([KMGT]?)(?:I?B)?\s*$", re.IGNORECASE)
MAX_SIZE = 1 << 60  # 1 EiB: more than any machine has


def parse_size(value: Any, where: str = "memory budget") -> int:
    """Bytes from a number of bytes or a text such as "2G", "500 MB", "1.5GiB" (K/M/G/T: powers of 1024);
    1 byte to 1 EiB. OptionError (a ValueError) naming ``where``."""
    what = "a size such as 2G, 500M or a number of bytes (1 byte to 1 EiB)"
    if isinstance(value, bool):
        raise _refuse(where, what, value)
    if isinstance(value, int | float):
        try:
            number, unit = float(value), ""
        except OverflowError:  # an integer too large for a float
            number, unit = math.inf, ""
    elif isinstance(value, str):
        m = _SIZE.match(value)
        if not m:
            raise _refuse(where, what, value)
        number, unit = float(m.group(1)), m.group(2).upper()
    else:
        raise _refuse(where, what, value)
    try:
        size = number * _UNITS[unit]
    except OverflowError:
        size = math.inf
    if not math.isfinite(size) or size < 1 or size > MAX_SIZE:
        raise _refuse(where, what, value)
    return int(size)


# ---------------------------------------------------------------- numbers


def integer(value: Any, where: str, lo: int, hi: int) -> int:
    """An integer in [lo, hi], from an int or its decimal text (a float, even 2.0, is not a count)."""
    what = f"an integer from {lo:,} to {hi:,}"
    if isinstance(value, bool):
        raise _refuse(where, what, value)
    if isinstance(value, str):
        text = value.strip()
        if not re.fullmatch(r"[+-]?[0-9]{1,30}", text):
            raise _refuse(where, what, value)
        value = int(text)
    if not isinstance(value, int) or not lo <= value <= hi:
        raise _refuse(where, what, value)
    return value


def real(value: Any, where: str, lo: float, hi: float, *, open_low: bool = False) -> float:
    """A finite number in [lo, hi] (or (lo, hi] with ``open_low``), from a number or its text."""
    what = f"a number {'above' if open_low else 'from'} {lo:g}{'' if open_low else ' to ' + format(hi, 'g')}"
    if open_low:
        what += f" and at most {hi:g}"
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise _refuse(where, what, value)
    try:
        x = float(value.strip() if isinstance(value, str) else value)
    except (ValueError, OverflowError):
        raise _refuse(where, what, value) from None
    if not math.isfinite(x) or x > hi or x < lo or (open_low and x == lo):
        raise _refuse(where, what, value)
    return x + 0.0


def choice_list(value: Any, where: str, choices: Sequence[str]) -> tuple[str, ...]:
    """A comma-separated, non-empty list of distinct names from ``choices``."""
    what = "a comma-separated list of " + ", ".join(choices)
    if not isinstance(value, str):
        raise _refuse(where, what, value)
    names = [n.strip() for n in value.split(",")]
    if not value.strip() or any(not n for n in names):
        raise _refuse(where, what + " (none may be empty)", value)
    unknown = [n for n in names if n not in choices]
    if unknown:
        raise OptionError(f"{where}: unknown {show(unknown[0], 40)} (known: {', '.join(choices)})", entry=where)
    if len(set(names)) != len(names):
        raise _refuse(where, what + " (each once)", value)
    return tuple(names)


# ---------------------------------------------------------------- names and places


def describe_os_error(exc: OSError) -> str:
    """A short reason for an OSError (``permission denied``, ``no space left on device``...)."""
    if exc.errno == errno.ENOSPC:
        return "no space left on device"
    if exc.errno == errno.EDQUOT:
        return "disk quota exceeded"
    return (exc.strerror or type(exc).__name__).lower()


def check_folder(folder: str | Path, where: str = "--out") -> Path:
    """Refuse, before any work, an output folder that could not be written: an existing file of that name, a file
    where one of its parents should be, a nearest existing parent not writable (nothing is created)."""
    folder = Path(folder)
    if "\x00" in str(folder):
        raise OptionError(f"{where}: {str(folder)!r}: a path cannot contain a NUL character", entry="out")
    try:
        return _check_folder(folder, where)
    except OSError as exc:  # a name too long, a loop of links
        raise OptionError(f"{where}: output folder {folder}: {describe_os_error(exc)}", entry="out") from None


def _check_folder(folder: Path, where: str) -> Path:
    if folder.exists() and not folder.is_dir():
        raise OptionError(f"{where}: output folder {folder}: exists and is not a folder", entry="out")
    parent = folder
    while not parent.exists():
        if parent.parent == parent:
            break
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise OptionError(f"{where}: output folder {folder}: {parent} is a file, not a folder", entry="out")
    if parent.exists() and not os.access(parent, os.W_OK | os.X_OK):
        raise OptionError(f"{where}: output folder {folder}: permission denied (in {parent})", entry="out")
    return folder


def check_file(path: str | Path, where: str = "--out") -> Path:
    """Refuse, before any work, an output file that could not be written (a folder of that name, its folder)."""
    path = Path(path)
    try:
        is_dir = path.is_dir()
    except OSError as exc:
        raise OptionError(f"{where}: output file {path}: {describe_os_error(exc)}", entry="out") from None
    if is_dir:
        raise OptionError(f"{where}: output file {path}: is a folder", entry="out")
    check_folder(path.parent if str(path.parent) else ".", where)
    return path


def folder(value: Any, where: str = "--out") -> str:
    """An output folder's path: non-empty text without NUL characters, a folder that can be written (checked
    before any work: not an existing file, no file in its way, its nearest existing parent writable)."""
    if not isinstance(value, str) or not value.strip() or "\x00" in value or len(value) > 4096:
        raise _refuse(where, "a folder path (not empty, no NUL character)", value)
    check_folder(value, where)
    return value


def out_file(value: Any, where: str = "--out") -> str:
    """An output file's path (checked before any work like :func:`folder`: not a folder, its folder writable)."""
    if not isinstance(value, str) or not value.strip() or "\x00" in value or len(value) > 4096:
        raise _refuse(where, "a file path (not empty, no NUL character)", value)
    check_file(value, where)
    return value


def folder_path(value: Any, where: str = "folder") -> Path:
    """An output folder given to a Python function (text or a Path), checked as ``--out`` is."""
    return Path(folder(str(value) if isinstance(value, Path) else value, where))


def instance(value: Any, where: str, kind: type | tuple[type, ...], what: str) -> Any:
    """``value`` if it is a ``kind``, else OptionError naming ``where`` and ``what`` it must be."""
    if not isinstance(value, kind):
        raise OptionError(f"{where}: must be {what}, got {show(value, 40)}", entry=where)
    return value


def file_path(value: Any, where: str = "FILE") -> str:
    """An input file's path: non-empty text without NUL characters (whether it exists is the reader's check)."""
    if not isinstance(value, str) or not value.strip() or "\x00" in value or len(value) > 4096:
        raise _refuse(where, "a file path (not empty, no NUL character)", value)
    return value


def switch(value: Any, where: str) -> bool:
    """An on/off environment setting: 1 or 0 (an empty value is the default: on)."""
    if value in ("", "1", 1, True):
        return True
    if value in ("0", 0, False):
        return False
    raise _refuse(where, "0 or 1", value)


# ---------------------------------------------------------------- the table


@dataclass(frozen=True)
class Option:
    """One option: the parser of its value (text or a value read from a file) and what it accepts."""

    name: str
    parse: Callable[[Any], Any]
    accepts: str


MAX_WORKERS = 256  # a local cluster larger than this is a typo, not a plan
MAX_CORPUS = 1_000_000
MAX_START = 10**8
MAX_TIMEOUT = 7 * 86400.0  # s: a task that may run a week is not hung

OPTIONS: dict[str, Option] = {
    o.name: o
    for o in (
        Option("memory-budget", lambda v: parse_size(v, "--memory-budget"), "a size: 2G, 500M, bytes"),
        Option("workers", lambda v: integer(v, "--workers", 1, MAX_WORKERS), f"1 to {MAX_WORKERS}"),
        Option("scheduler", parse_address, "tcp://HOST:PORT"),
        Option("timeout", lambda v: real(v, "--timeout", 0.0, MAX_TIMEOUT, open_low=True), "seconds > 0"),
        Option("seed", lambda v: integer(v, "--seed", 0, 2**63 - 1), "0 to 2**63 - 1"),
        Option("n", lambda v: integer(v, "--n", 1, MAX_CORPUS), f"1 to {MAX_CORPUS}"),
        Option("corpus", lambda v: integer(v, "--corpus", 1, MAX_CORPUS), f"1 to {MAX_CORPUS}"),
        Option("start", lambda v: integer(v, "--start", 0, MAX_START), f"0 to {MAX_START}"),
        Option("limit-fraction", lambda v: real(v, "--limit-fraction", 0.0, 1.0), "0 to 1"),
        Option("minimize-tries", lambda v: integer(v, "--minimize-tries", 0, 10_000), "0 to 10000"),
        Option("out", folder, "a folder"),
        Option("out-file", out_file, "a file"),
        Option("previous", lambda v: file_path(v, "--previous"), "a summary.json"),
        Option("file", file_path, "a file"),
        Option("cs", lambda v: real(v, "--flywheel-for", 0.0, 2.0, open_low=True), "a number above 0, at most 2"),
    )
}


# ---------------------------------------------------------------- the environment

ENVIRONMENT: dict[str, Callable[[str], Any]] = {
    "VLOOP_MEMORY_BUDGET": lambda v: parse_size(v, "VLOOP_MEMORY_BUDGET"),
    "VLOOP_KEEP_HEAP": lambda v: switch(v, "VLOOP_KEEP_HEAP"),
}


def check_environment(environ: Any = None) -> None:
    """Every VLOOP_* environment variable vloop reads, parsed (OptionError naming the first bad one)."""
    import os

    env = os.environ if environ is None else environ
    for name, parse in ENVIRONMENT.items():
        if env.get(name):
            parse(env[name])
