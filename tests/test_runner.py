"""vloop.runner: every task's value or failure, in order; a crash or a hang is that task's failure only."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests import runner_tasks
from vloop.runner import RunnerError, TaskOutcome, local_worker_name, run_tasks


def test_in_process_values_errors_and_timeouts_in_item_order():
    seen: list[int] = []
    outs = run_tasks(
        runner_tasks.swallowing, [2, "boom", "hang", 3], timeout=0.5, on_done=lambda o: seen.append(o.index)
    )
    assert [o.index for o in outs] == [0, 1, 2, 3] and seen == [0, 1, 2, 3]
    assert (outs[0].value, outs[0].error) == (4, "") and outs[0].ok
    assert outs[1].value == "swallowed"  # the task's own except: its result
    # the hang is interrupted although the task catches every Exception (TaskTimeout is a BaseException)
    assert not outs[2].ok and outs[2].error == "task timed out after 0.5 s" and 0.45 < outs[2].seconds < 5
    assert outs[3].value == 9
    assert all(o.worker == local_worker_name() for o in outs)


def test_in_process_exception_becomes_the_tasks_error():
    (out,) = run_tasks(runner_tasks.square, ["boom"])
    assert out == TaskOutcome(0, None, "RuntimeError: boom", out.seconds, local_worker_name())


@pytest.mark.parametrize(
    "kw, what",
    [
        ({"workers": 0}, "workers must be a positive integer"),
        ({"workers": 2, "scheduler": "tcp://127.0.0.1:1"}, "not both"),
        ({"timeout": 0}, "timeout must be a positive number"),
        ({"timeout": float("nan")}, "timeout must be a positive number"),
        ({"timeout": float("inf")}, "timeout must be a positive number"),
        ({"workers": 10**6}, "at most"),
    ],
)
def test_bad_options_are_one_clear_error(kw, what):
    with pytest.raises(RunnerError, match=what):
        run_tasks(runner_tasks.square, [1], **kw)


def test_unreachable_scheduler_is_a_clear_error(monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr("vloop.runner.CONNECT_TIMEOUT", 2.0)
    with pytest.raises(RunnerError, match=re.escape("cannot reach the Dask scheduler at tcp://127.0.0.1:9")):
        run_tasks(runner_tasks.square, [1], scheduler="tcp://127.0.0.1:9")


def test_local_cluster_survives_a_crash_and_a_hang():
    """2 worker processes: one task kills its process, one never returns; every other task still runs."""
    pytest.importorskip("distributed")
    items = [1, 2, "crash", 3, "hang", 4, "boom", 5, 6, 7]
    outs = run_tasks(runner_tasks.square, items, workers=2, timeout=3)
    by = {i: o for i, o in enumerate(outs)}
    assert [o.index for o in outs] == list(range(len(items)))
    for i, x in enumerate(items):
        if isinstance(x, int):
            assert by[i].ok and by[i].value == x * x, by[i]
            assert by[i].worker.split(":")[0] in ("0", "1")  # LocalCluster names its workers 0, 1
    assert "worker process running it died" in by[2].error
    assert by[4].error.startswith("task timed out after 3 s") and by[4].seconds >= 3
    assert by[6].error == "RuntimeError: boom"
    assert len({o.worker for o in outs if o.ok}) >= 2  # both processes took work


def test_import_vloop_does_not_import_dask():
    code = "import sys, vloop, vloop.runner, validators.corpus; print(any(m.split('.')[0] in ('dask', 'distributed') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_a_running_scheduler_by_its_address():
    """scheduler=ADDRESS: the tasks run on that cluster's workers; the client does not shut it down."""
    pytest.importorskip("distributed")
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        outs = run_tasks(runner_tasks.square, [3, "boom", 4], scheduler=cluster.scheduler_address)
        assert [(o.value, o.error) for o in outs] == [(9, ""), (None, "RuntimeError: boom"), (16, "")]
        assert {o.worker for o in outs} == {f"0:{next(iter(cluster.scheduler_info['workers']))}"}
        assert run_tasks(runner_tasks.square, [5], scheduler=cluster.scheduler_address)[0].value == 25
