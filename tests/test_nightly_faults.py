"""A nightly survives its faults: a main process interrupted (SIGKILL, Ctrl-C) resumes from disk without redoing
finished mechanisms, and a real Dask cluster (scheduler and workers as separate processes, tcp on 127.0.0.1) that
loses a worker mid-run validates every mechanism exactly once. Either way the summary equals an uninterrupted
run's (every number, verdict and message; not the timings, workers or folders)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
N, SEED = 6, 2026
FAST = "vloop,analytic"
TIMING = {"seconds", "task_seconds", "cpu_seconds", "worker", "created", "runner", "file", "folder", "command"}


def _env() -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    env.pop("PYTEST_CURRENT_TEST", None)
    return env


def _validate(out: Path, *extra: str, engines: str = FAST) -> subprocess.Popen:
    args = ["validate", "--corpus", str(N), "--seed", str(SEED), "--engines", engines, "--no-report"]
    args += ["--minimize-tries", "0", "--out", str(out), *extra]
    return subprocess.Popen(
        [sys.executable, "-m", "vloop.cli", *args],
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def _finish(proc: subprocess.Popen, timeout: float = 600) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def _comparable(obj):
    """A summary without what differs between two runs of the same thing: timings, workers, folders."""
    if isinstance(obj, dict):
        return {k: _comparable(v) for k, v in obj.items() if k not in TIMING}
    if isinstance(obj, list):
        return [_comparable(v) for v in obj]
    return obj


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def _files(folder: Path) -> list[Path]:
    return sorted(folder.glob("family=*/[0-9]*.parquet"))


def _wait_for(folder: Path, count: int, proc: subprocess.Popen, seconds: float = 300) -> None:
    t0 = time.monotonic()
    while len(_files(folder)) < count:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < seconds, "no progress"
        time.sleep(0.05)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("whole")
    code, _, err = _finish(_validate(out))
    assert code == 0, err
    summary = _summary(out)
    assert summary["counts"]["mechanisms"] == N
    return summary


@pytest.mark.parametrize(
    "how", [signal.SIGKILL, pytest.param(signal.SIGINT, marks=pytest.mark.slow)], ids=["SIGKILL", "Ctrl-C"]
)
def test_an_interrupted_nightly_resumes_from_disk(how, uninterrupted, tmp_path):
    out = tmp_path / "night"
    proc = _validate(out)
    work = out / ".vloop-run" / "comparisons"
    _wait_for(work, 2, proc)
    os.killpg(proc.pid, how)  # the main process (and, in-process, its tasks): as a terminal's Ctrl-C or a kill -9
    code, _, err = _finish(proc, timeout=60)
    assert code != 0
    if how == signal.SIGINT:  # the user is told what is kept and how to go on
        assert code == 130 and "the same command with --resume continues from them" in err, err
        assert "Traceback" not in err
    kept = {p.name: p.stat().st_mtime_ns for p in _files(work)}
    assert len(kept) >= 2 and not (out / "summary.json").exists()  # nothing published, the work kept
    code, _, err = _finish(_validate(out, "--resume"))
    assert code == 0, err
    assert f"resuming: {len(kept)} of {N} mechanisms already validated" in err
    published = out / "comparisons"
    assert {p.name: p.stat().st_mtime_ns for p in _files(published) if p.name in kept} == kept  # not redone
    assert len(_files(published)) == N and not (out / ".vloop-run").exists()
    assert _comparable(_summary(out)) == _comparable(uninterrupted)


def test_resume_refuses_another_run(tmp_path):
    out = tmp_path / "night"
    proc = _validate(out)
    _wait_for(out / ".vloop-run" / "comparisons", 1, proc)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=60)
    code, _, err = _finish(_validate(out, "--resume", engines="vloop,pinocchio"))
    assert code == 2 and "--resume: the interrupted run in" in err and "its engines differ" in err
    assert err.count("\n") == 1 and "Traceback" not in err


# ---------------------------------------------------------------- a real cluster that loses a worker


def _start(cmd: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(cmd, env=_env(), stdout=log.open("w"), stderr=subprocess.STDOUT, start_new_session=True)


@pytest.mark.slow
def test_a_cluster_that_loses_a_worker_validates_every_mechanism_once(uninterrupted, tmp_path):
    """`dask scheduler` and two `dask worker` processes on tcp://127.0.0.1; one worker (its nanny too) killed as
    soon as the first mechanism is in the dataset. The scheduler gives its task to the other worker: every mechanism
    is in the dataset once, and the summary is the uninterrupted one's."""
    pytest.importorskip("distributed")
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    sched_file = tmp_path / "scheduler.json"
    procs = [_start([*dask, "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
                     str(sched_file)], tmp_path / "scheduler.log")]  # fmt: skip
    try:
        t0 = time.monotonic()
        while not sched_file.exists():
            assert time.monotonic() - t0 < 60, (tmp_path / "scheduler.log").read_text()
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        worker = [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--nworkers", "1"]
        worker += ["--host", "127.0.0.1", "--no-dashboard", "--memory-limit", "0"]
        procs += [_start([*worker, "--name", f"w{k}"], tmp_path / f"w{k}.log") for k in (1, 2)]
        from distributed import Client

        with Client(address, timeout=60) as c:
            c.wait_for_workers(2, timeout=120)
        out = tmp_path / "night"
        proc = _validate(out, "--scheduler", address)
        _wait_for(out / ".vloop-run" / "comparisons", 1, proc)
        os.killpg(procs[1].pid, signal.SIGKILL)  # worker w1 and its nanny, mid-run
        code, _, err = _finish(proc)
        assert code == 0, err
        files = _files(out / "comparisons")
        assert sorted(int(p.stem) for p in files) == list(range(N))  # each task's file once
        summary = _summary(out)
        assert len({m["name"] for m in summary["mechanisms"]}) == N == len(summary["mechanisms"])
        assert _comparable(summary) == _comparable(uninterrupted)
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=30)
