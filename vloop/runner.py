"""Run many independent tasks: in this process, on a local Dask cluster, or on a Dask scheduler.

    outcomes = run_tasks(fn, items)                               # in this process, one after the other
    outcomes = run_tasks(fn, items, workers=2)                    # dask.distributed.LocalCluster, 2 processes
    outcomes = run_tasks(fn, items, scheduler="tcp://host:8786")  # a running Dask scheduler

Every item becomes one task ``fn(item)``; :class:`TaskOutcome` records its value or the error text,
the seconds it took and the worker that ran it, in the order of ``items``. A task that raises, that
kills its worker process (a crash in compiled code) or that runs longer than ``timeout`` seconds
becomes that task's failure, and the run goes on with the others:

* in this process, an exception is caught; a timeout interrupts the task with SIGALRM (POSIX, main
  thread; a task stuck inside compiled code is interrupted when it returns to Python); a crash of
  the process cannot be survived — use workers for code that may crash;
* on Dask, each worker process runs one task at a time (LocalCluster: one thread per worker); the client
  keeps one task in flight per worker thread, so no task waits behind another that may crash its worker,
  and starts a task's clock when the scheduler shows it processing on a worker. A task past its timeout is
  cancelled and its worker process restarted by its nanny (the only way to stop a stuck thread); a task
  whose worker dies is not
  retried on our own cluster (``distributed.scheduler.allowed-failures`` = 0: a crash is a result,
  not bad luck) and is reported with the worker's death.

Dask is imported only when a cluster is asked for (``pip install 'vloop[dask]'``), never by
``import vloop``. The progress bar (tqdm) goes to stderr and is silent when stderr is not a terminal.
``fn`` and the items must be picklable for Dask (a module-level function, plain data).
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import signal
import socket
import sys
import threading
import time
import uuid
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from .errors import VloopError

POLL = 0.2  # s between checks of running tasks for a timeout
# Tasks in flight per worker thread. One: a task waiting behind another on the same worker would die with it if
# that one crashes the process (two in flight gained within the noise of a loaded 2-core machine).
IN_FLIGHT = 1
MAX_LOCAL_WORKERS = 256  # a LocalCluster larger than this is a typo, not a plan
CONNECT_TIMEOUT = 10.0  # s for Dask to reach a scheduler that answered check_scheduler
REACH_TIMEOUT = 3.0  # s for a TCP connection to the scheduler's port (check_scheduler)


class RunnerError(VloopError):
    """The runner cannot start (Dask missing, scheduler unreachable, bad options)."""


class TaskTimeout(BaseException):
    """Raised inside an in-process task that ran past its timeout."""


@dataclass
class TaskOutcome:
    """One task: its value, or the error text (empty on success); seconds [s] it ran; the worker."""

    index: int
    value: Any = None
    error: str = ""
    seconds: float = 0.0
    worker: str = ""

    @property
    def ok(self) -> bool:
        return not self.error


_HOST = re.compile(r"[A-Za-z0-9][A-Za-z0-9.-]{0,252}|\[[0-9A-Fa-f:.]{2,45}\]")
SCHEMES = ("tcp", "tls")


def parse_address(value: Any, where: str = "--scheduler") -> str:
    """A Dask scheduler's address ``[tcp://|tls://]HOST:PORT`` (the port is required), as ``SCHEME://HOST:PORT``;
    RunnerError naming ``where`` otherwise."""
    text = value.strip() if isinstance(value, str) and len(value) <= 300 else ""
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    host, colon, port = rest.rpartition(":")
    ok = scheme in SCHEMES and colon and _HOST.fullmatch(host) and re.fullmatch(r"[0-9]{1,5}", port)
    if not ok or not 1 <= int(port) <= 65535:
        shown = repr(value)[:40]
        raise RunnerError(
            f"{where}: must be a Dask scheduler address such as tcp://host:8786 (with its port, 1 to 65535), "
            f"got {shown}",
            entry="scheduler",
        )
    return f"{scheme}://{host}:{int(port)}"


def check_scheduler(address: str, timeout: float = REACH_TIMEOUT) -> None:
    """Refuse (RunnerError, one line) a scheduler address that does not parse, whose port does not accept a
    connection within ``timeout`` seconds, or (tcp) that sends no Dask handshake in that time — before any work,
    instead of Dask's wait (forever, for a server that is not a scheduler) and its traceback."""
    addr = parse_address(address)
    scheme, rest = addr.split("://", 1)
    host, port = rest.rsplit(":", 1)
    try:
        conn = socket.create_connection((host.strip("[]"), int(port)), timeout=timeout)
    except OSError as exc:
        why = "no answer" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc)).lower()
        raise RunnerError(
            f"--scheduler {address}: cannot reach a Dask scheduler at {addr} ({why} within {timeout:g} s); "
            "start one (dask scheduler) or use --workers N",
            entry="scheduler",
        ) from None
    with conn:
        try:
            greeted = scheme != "tcp" or bool(conn.recv(1))  # a Dask scheduler sends its handshake at once
        except OSError:
            greeted = False
    if not greeted:
        raise RunnerError(
            f"--scheduler {address}: {addr} accepts connections but is not a Dask scheduler (no handshake within "
            f"{timeout:g} s)",
            entry="scheduler",
        )


def local_worker_name() -> str:
    """The name an in-process task records: ``local:HOST:PID``."""
    return f"local:{socket.gethostname()}:{os.getpid()}"


def _call(fn: Callable[[Any], Any], item: Any) -> tuple[Any, str, float, str]:
    """Run one task where it lands: (value, error text, seconds, worker name). Never raises an Exception."""
    worker = local_worker_name()
    if "distributed" in sys.modules:  # a Dask worker has it loaded; never import it here (slow, and not needed)
        from distributed import get_worker

        with contextlib.suppress(ValueError):
            w = get_worker()
            name = str(w.name) if w.name is not None else ""
            worker = f"{name}:{w.address}" if name and name != w.address else w.address
    t0 = time.perf_counter()
    try:
        return fn(item), "", time.perf_counter() - t0, worker
    except Exception as exc:  # the task's failure is its result
        return None, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0, worker


@contextlib.contextmanager
def _alarm(seconds: float | None) -> Iterator[None]:
    """Raise TaskTimeout in the main thread after ``seconds`` (no-op elsewhere or without a timeout)."""
    usable = seconds and hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
    if not usable:
        yield
        return

    def ring(signum: int, frame: Any) -> None:
        raise TaskTimeout(f"timed out after {seconds:g} s")

    old = signal.signal(signal.SIGALRM, ring)
    signal.setitimer(signal.ITIMER_REAL, float(seconds))
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)


def _bar(total: int, progress: bool | None, label: str) -> Any:
    """A tqdm bar on stderr (None when off, not a terminal, or tqdm is missing)."""
    show = sys.stderr.isatty() if progress is None else progress
    if not show:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=label, unit="task", file=sys.stderr, dynamic_ncols=True, leave=False)


def run_tasks(
    fn: Callable[[Any], Any],
    items: Iterable[Any],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    timeout: float | None = None,
    progress: bool | None = None,
    on_done: Callable[[TaskOutcome], None] | None = None,
    label: str = "tasks",
) -> list[TaskOutcome]:
    """Run ``fn(item)`` for every item and return the outcomes in item order (see the module docstring).

    ``scheduler``: address of a Dask scheduler; ``workers``: start a LocalCluster of that many worker
    processes (one thread each); neither: run in this process. ``timeout`` [s] per task. ``progress``:
    None = a bar when stderr is a terminal. ``on_done(outcome)`` is called in this process as each task
    finishes (any order); it may replace ``outcome.value`` (e.g. by a summary) to keep memory bounded.
    """
    items = list(items)
    if scheduler and workers:
        raise RunnerError("give either a scheduler address or a number of local workers, not both", entry="runner")
    if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool) or workers < 1):
        raise RunnerError(f"workers must be a positive integer, got {workers!r}", entry="workers")
    if workers is not None and workers > MAX_LOCAL_WORKERS:
        raise RunnerError(f"workers: at most {MAX_LOCAL_WORKERS} local processes, got {workers}", entry="workers")
    if timeout is not None and not (isinstance(timeout, int | float) and 0 < timeout < float("inf")):
        raise RunnerError(f"timeout must be a positive number of seconds, got {timeout!r}", entry="timeout")
    bar = _bar(len(items), progress, label)
    try:
        if scheduler or workers:
            with _client(scheduler, workers) as client:
                return _run_dask(client, fn, items, timeout, bar, on_done)
        return _run_here(fn, items, timeout, bar, on_done)
    finally:
        if bar is not None:
            bar.close()


def _finish(out: TaskOutcome, outcomes: list[TaskOutcome | None], bar: Any, on_done: Any) -> None:
    outcomes[out.index] = out
    if on_done is not None:
        on_done(out)
    if bar is not None:
        bar.update(1)


def _run_here(
    fn: Callable[[Any], Any], items: Sequence[Any], timeout: float | None, bar: Any, on_done: Any
) -> list[TaskOutcome]:
    outcomes: list[TaskOutcome | None] = [None] * len(items)
    for i, item in enumerate(items):
        t0 = time.perf_counter()
        try:
            with _alarm(timeout):
                value, error, seconds, worker = _call(fn, item)
        except TaskTimeout as exc:
            value, error, seconds, worker = None, f"task {exc}", time.perf_counter() - t0, local_worker_name()
        _finish(TaskOutcome(i, value, error, seconds, worker), outcomes, bar, on_done)
    return outcomes  # type: ignore[return-value]


# ---------------------------------------------------------------- Dask


@contextlib.contextmanager
def _client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A distributed Client on ``scheduler``, or on a LocalCluster of ``workers`` processes we own."""
    try:
        import dask
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise RunnerError(
            f"Dask is not installed ({exc}); install the extra: pip install 'vloop[dask]'", entry="runner"
        ) from None
    import logging

    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise RunnerError(f"cannot reach the Dask scheduler at {scheduler}: {exc}", entry="scheduler") from None
        try:
            yield client
        finally:
            client.close()
        return
    # allowed-failures 0: a task that kills its worker is not retried; worker-saturation 1.0: a worker is given
    # one task per thread, the rest wait on the scheduler, so "processing" means running (the timeout's clock)
    settings = {"distributed.scheduler.allowed-failures": 0, "distributed.scheduler.worker-saturation": 1.0}
    warnings.filterwarnings("ignore", message=r"Port \d+ is already in use", category=UserWarning)
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()  # started later (by the cluster's thread) it would unblock SIGINT there
    held = _hold_interrupts()
    try:
        with dask.config.set(settings):
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,
            )
    except BaseException:
        _release_interrupts(held)
        raise
    try:
        _release_interrupts(held)  # a Ctrl-C held while the cluster started is raised here (the cluster is closed)
        client = Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        held = _hold_interrupts()  # a second Ctrl-C waits until the workers are gone
        try:
            cluster.close()
        finally:
            _release_interrupts(held)


def _hold_interrupts() -> Any:
    """Block SIGINT in this thread (a Ctrl-C waits, pending) and return the previous signal mask.

    A terminal sends Ctrl-C to the whole process group: the workers, started while it is blocked, inherit the
    mask (every thread and process they start does) and never see it — no KeyboardInterrupt traceback from a
    worker process; this process alone handles it, and closes the cluster."""
    if not hasattr(signal, "pthread_sigmask"):
        return None
    return signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


def _release_interrupts(mask: Any) -> None:
    if mask is not None:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _stop_hung(client: Any, fut: Any) -> str:
    """Cancel a hung task and restart the worker process stuck in it; returns that worker's address."""
    addr = ""
    with contextlib.suppress(Exception):
        addr = next((w for w, keys in client.processing().items() if fut.key in keys), "")
    with contextlib.suppress(Exception):
        client.cancel([fut], force=True)
    if addr:
        with contextlib.suppress(Exception):  # a worker without a nanny cannot be restarted: it stays busy
            client.restart_workers([addr], timeout=60, raise_for_error=False)
    return addr


def _outcome_of(fut: Any, index: int, started: float) -> TaskOutcome:
    """The outcome of a finished future (the task's own result, or why the worker gave none)."""
    elapsed = time.monotonic() - started
    if fut.status == "finished":
        try:
            value, error, seconds, worker = fut.result()
            return TaskOutcome(index, value, error, seconds, worker)
        except Exception as exc:  # the result could not be deserialized
            return TaskOutcome(index, None, f"{type(exc).__name__}: {exc}", elapsed)
    try:
        exc = fut.exception(timeout=5)
    except Exception as err:
        exc = err
    name = type(exc).__name__
    if name == "KilledWorker":
        msg = f"the worker process running it died (crash or killed): {exc}"
    elif fut.status == "cancelled":
        msg = "cancelled"
    else:
        msg = f"{name}: {exc}"
    return TaskOutcome(index, None, msg, elapsed)


def _run_dask(
    client: Any, fn: Callable[[Any], Any], items: Sequence[Any], timeout: float | None, bar: Any, on_done: Any
) -> list[TaskOutcome]:
    outcomes: list[TaskOutcome | None] = [None] * len(items)
    pending = deque(enumerate(items))
    running: dict[Any, _Running] = {}
    tag = uuid.uuid4().hex[:8]
    wake = threading.Event()  # set from the client's event loop whenever a task finishes
    slots, checked = 0, -math.inf  # scheduler calls cost the client CPU: ask at most every POLL seconds
    while pending or running:
        now = time.monotonic()
        if now - checked >= POLL:
            slots, checked = IN_FLIGHT * max(1, sum(client.nthreads().values())), now
            if timeout:
                _expire(client, running, timeout, outcomes, bar, on_done)
        while pending and len(running) < slots:
            i, item = pending.popleft()
            fut = client.submit(_call, fn, item, key=f"vloop-task-{tag}-{i}", pure=False, retries=0)
            fut.add_done_callback(lambda _f: wake.set())
            running[fut] = _Running(i, time.monotonic())
        wake.wait(POLL)
        wake.clear()
        for fut in [f for f in running if f.done()]:
            r = running.pop(fut)
            _finish(_outcome_of(fut, r.index, r.submitted), outcomes, bar, on_done)
    return outcomes  # type: ignore[return-value]


@dataclass
class _Running:
    """A submitted task: its item index, when it was submitted, and when a worker was seen running it."""

    index: int
    submitted: float
    started: float | None = None


def _expire(client: Any, running: dict[Any, _Running], timeout: float, outcomes: list, bar: Any, on_done: Any) -> None:
    """Start each task's clock when the scheduler shows it on a worker; time out those past ``timeout``."""
    now = time.monotonic()
    if any(r.started is None for r in running.values()):
        try:
            busy = {k for keys in client.processing().values() for k in keys}
        except Exception:  # the scheduler did not answer: count from submission
            busy = {f.key for f in running}
        for fut, r in running.items():
            if r.started is None and fut.key in busy:
                r.started = now
    for fut, r in list(running.items()):
        if r.started is not None and now - r.started > timeout and not fut.done():
            running.pop(fut)
            addr = _stop_hung(client, fut)
            where = f" on worker {addr} (restarted)" if addr else ""
            out = TaskOutcome(r.index, None, f"task timed out after {timeout:g} s{where}", now - r.started, addr)
            _finish(out, outcomes, bar, on_done)
