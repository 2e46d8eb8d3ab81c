"""Memory budget of a run: estimate what a run needs before solving it, and refuse what does not fit.

The budget (bytes) is, first found: ``--memory-budget`` on the command line (or the ``memory_budget``
option of :func:`vloop.solve`), the environment variable ``VLOOP_MEMORY_BUDGET``, the file's
``[solver] memory_budget``, else half the memory available to this process: the smaller of the
machine's available memory (``MemAvailable``) and the address space left under a limit
(``ulimit -v``, ``RLIMIT_AS``). Sizes are bytes or text such as ``"2G"``, ``"500 MB"``, ``"1.5GiB"``
(K/M/G/T are powers of 1024).

The estimate (:func:`estimate`) counts samples × columns × 8 bytes × copies for the results kept in
memory, plus the solver's working set for one chunk of rows (per row: every angle's e^{jθ}, θ, ω, α,
every slider's s, ṡ, s̈, the inputs, the Newton blocks' Jacobians), plus the time grid itself. A run
streamed to disk (``vloop run``) keeps no results in memory: its need does not grow with the run
beyond the time grid (8 bytes per sample).
"""

from __future__ import annotations

import math
import os
import re
import resource
import time
from dataclasses import dataclass
from typing import Any

from ..errors import VloopError

ENV = "VLOOP_MEMORY_BUDGET"
DEFAULT_FRACTION = 0.5  # of the memory available to the process
IN_MEMORY_COPIES = 2  # a solve() keeps the chunks and their joined copy at once
HEALTH_BYTES = 26  # per sample: residual, cond, branch (8 bytes each), two 1-byte flags
_UNITS = {"": 1, "B": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
_SIZE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([KMGT]?)(?:I?B)?\s*$", re.IGNORECASE)


class MemoryBudgetError(VloopError):
    """A run would need more memory than its budget (the message says how much, the budget and what to do)."""


def parse_size(value: Any, where: str = "memory budget") -> int:
    """Bytes from a number of bytes or a text such as "2G", "500 MB", "1.5GiB"; ValueError naming ``where``."""
    if isinstance(value, bool):
        raise ValueError(f"{where}: must be a size such as 2G or 500M, got {value!r}")
    if isinstance(value, int | float):
        try:
            number, unit = float(value), ""
        except OverflowError:  # an integer too large for a float
            number, unit = math.inf, ""
    elif isinstance(value, str):
        m = _SIZE.match(value)
        if not m:
            raise ValueError(f"{where}: must be a size such as 2G, 500M or a number of bytes, got {value[:40]!r}")
        number, unit = float(m.group(1)), m.group(2).upper()
    else:
        raise ValueError(f"{where}: must be a size such as 2G or 500M, got {type(value).__name__}")
    try:
        size = number * _UNITS[unit]
    except OverflowError:
        size = math.inf
    if not math.isfinite(size) or size < 1 or size > 1 << 60:
        raise ValueError(f"{where}: {str(value)[:40]} is not a usable size (1 byte to 1 EiB)")
    return int(size)


def fmt_size(n: float) -> str:
    """A byte count for people: 1.5 GB, 320 MB (powers of 1024)."""
    for unit, size in (("TB", 1 << 40), ("GB", 1 << 30), ("MB", 1 << 20), ("kB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"


_SEEN: list[float] = []  # (monotonic time, bytes) of the last reading


SEEN_FOR = 0.5  # seconds a reading of the available memory is reused (it costs as much as a small solve)


def available_memory() -> int:
    """Bytes this process can still use: the machine's available memory, less under an address-space cap."""
    now = time.monotonic()
    if _SEEN and now - _SEEN[0] < SEEN_FOR:
        return int(_SEEN[1])
    _SEEN[:] = [now, float(_read_available())]
    return int(_SEEN[1])


def _read_available() -> int:
    avail = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            avail = 1 << 30
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        avail = min(avail, max(soft - _address_space_used(), 0))
    return int(avail)


def _address_space_used() -> int:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def budget(explicit: Any = None, options: dict | None = None) -> tuple[int, str]:
    """(bytes, where the number comes from): explicit > VLOOP_MEMORY_BUDGET > [solver] memory_budget > default."""
    if explicit is not None:
        return parse_size(explicit, "--memory-budget"), "--memory-budget"
    env = os.environ.get(ENV)
    if env:
        try:
            return parse_size(env, ENV), ENV
        except ValueError as exc:
            raise MemoryBudgetError(str(exc), entry="memory_budget") from None
    if options and options.get("memory_budget") is not None:
        return int(options["memory_budget"]), "[solver] memory_budget"
    return int(DEFAULT_FRACTION * available_memory()), "half the memory available"


@dataclass(frozen=True)
class Estimate:
    """What a run needs [bytes] and how that number is made."""

    total: int
    samples: int
    columns: int
    copies: int
    working: int  # the solver's working set for one chunk
    grid: int  # the time grid

    def explain(self) -> str:
        kept = (
            f"{self.samples:,} samples × {self.columns} columns × 8 bytes × {self.copies} copies"
            if self.copies
            else "no results kept in memory (streamed)"
        )
        return f"{kept}, plus {fmt_size(self.working)} of solver working set and {fmt_size(self.grid)} of time grid"


def columns(sys: Any) -> int:
    """Output columns of a compiled system: t, θ/ω/α per link, six per point, three per slider."""
    return 1 + 3 * len(sys.link_outputs) + 6 * len(sys.point_names) + 3 * len(sys.slider_names)


def row_bytes(sys: Any) -> int:
    """The solver's state per internal row [bytes], with room for its temporaries."""
    na, ns, nd = sys.n_angles, len(sys.slider_names), len(sys.mechanism.drivers)
    state = 16 * (na + 1) + 8 * na + 16 * (na + 1) + 24 * (ns + 1) + 24 * nd + 8
    newton = sum(8 * 2 * (2 * len(b.loops)) * len(b.unknowns) for b in sys.blocks if b.kind == "newton")
    points = 48 * len(sys.point_names)  # positions, velocities, accelerations as complex numbers
    return 3 * (state + newton + points) + 8 * columns(sys)


def estimate(sys: Any, samples: int, streamed: bool, chunk_rows: int) -> Estimate:
    """Bytes a run of ``samples`` requested samples needs (results in memory unless ``streamed``)."""
    cols = columns(sys)
    copies = 0 if streamed else IN_MEMORY_COPIES
    kept = samples * (cols * 8 + HEALTH_BYTES) * copies
    rows = min(samples, chunk_rows)
    working = rows * row_bytes(sys) + (2 * rows * (cols * 8 + HEALTH_BYTES) if streamed else 0)
    grid = 8 * samples
    return Estimate(kept + working + grid, samples, cols, copies, working, grid)


LAST: list[str] = []  # the last check, for the message if memory runs out all the same


def out_of_memory() -> str:
    """The message for a MemoryError: what was estimated and allowed (the estimate was exceeded)."""
    said = f" (estimated {LAST[-1]})" if LAST else ""
    return (
        f"out of memory{said}: lower the memory budget (--memory-budget, {ENV}) so that vloop refuses such a run "
        "before it starts, use a larger step or a shorter run"
    )


def check(sys: Any, samples: int, streamed: bool, chunk_rows: int, explicit: Any = None) -> Estimate:
    """Refuse (MemoryBudgetError) a run whose estimate exceeds the budget; returns the estimate."""
    est = estimate(sys, samples, streamed, chunk_rows)
    limit, source = budget(explicit, sys.mechanism.options)
    LAST[:] = [f"{fmt_size(est.total)} for {sys.mechanism.name}, budget {fmt_size(limit)} ({source})"]
    if est.total > limit:
        way = (
            "use a larger [time] step or a shorter run, or raise the budget"
            if streamed
            else "use a larger [time] step or a shorter run, `vloop run` (it streams the results to disk in chunks; "
            "--format parquet is the most compact), or raise the budget"
        )
        raise MemoryBudgetError(
            f"{sys.mechanism.name}: this run needs about {fmt_size(est.total)} of memory ({est.explain()}), "
            f"more than the memory budget of {fmt_size(limit)} ({source}); {way} "
            f"(--memory-budget, {ENV} or [solver] memory_budget)",
            entry="time",
        )
    return est


# ---------------------------------------------------------------- the allocator

HEAP_ENV = "VLOOP_KEEP_HEAP"
MMAP_THRESHOLD = 32 << 20  # glibc's largest: arrays up to this size come from the heap, not a fresh mapping
TRIM_THRESHOLD = 128 << 20  # freed memory kept at the top of the heap (not returned to the OS) up to this size
_HEAP: list[bool] = []


def keep_heap() -> bool:
    """Ask glibc's malloc (once per process) to keep freed memory for reuse: numpy's temporaries of a few
    hundred kB are otherwise returned to the OS when freed and page-faulted in again at the next allocation —
    measured at ~960 page faults and ~45 % of the time of a 4,800-sample eight-bar solve. The process then
    keeps up to TRIM_THRESHOLD of freed heap. Skipped where the allocator is not glibc's, where the user set
    glibc's MALLOC_*_ environment variables, or with VLOOP_KEEP_HEAP=0. Returns whether it is in effect."""
    if _HEAP:
        return _HEAP[0]
    _HEAP.append(False)
    if os.environ.get(HEAP_ENV, "1") == "0" or any(k.startswith("MALLOC_") for k in os.environ):
        return False
    try:
        import ctypes

        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return False
        libc = ctypes.CDLL(None)
        m_trim, m_mmap = -1, -3  # <malloc.h>: M_TRIM_THRESHOLD, M_MMAP_THRESHOLD
        _HEAP[0] = bool(libc.mallopt(m_mmap, MMAP_THRESHOLD)) and bool(libc.mallopt(m_trim, TRIM_THRESHOLD))
    except (OSError, AttributeError, ValueError):
        pass
    return _HEAP[0]
