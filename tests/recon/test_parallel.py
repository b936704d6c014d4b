"""`recon.parallel.fork_map`: the jobs' results in order, computed in forked processes; and
`Beside`: one job in a forked process while this one goes on."""

from __future__ import annotations

import os
import time

import pytest

from recon.errors import UserError
from recon.parallel import Beside, available_cores, fork_map, workers_for


def test_fork_map_returns_the_jobs_results_in_order_from_other_processes():
    state = {"touched": 0}

    def job(index: int) -> tuple[int, int]:
        state["touched"] += 1  # a child's copy: the parent's state stays as it was
        return index * index, os.getpid()

    results = fork_map(job, 7, 2)
    assert [square for square, _ in results] == [i * i for i in range(7)]
    assert {pid for _, pid in results} - {os.getpid()} == {pid for _, pid in results}
    assert state["touched"] == 0
    # One worker: in this process, one job after another, side effects kept.
    assert fork_map(job, 3, 1) == [(0, os.getpid()), (1, os.getpid()), (4, os.getpid())]
    assert state["touched"] == 3


def test_a_job_that_fails_raises_in_the_caller_and_a_child_does_not_fork_again():
    def job(index: int) -> int:
        if index == 2:
            raise ValueError("job 2 failed")
        return index

    with pytest.raises(ValueError, match="job 2 failed"):
        fork_map(job, 4, 2)

    def nested(index: int) -> list[int]:  # in a child: the inner map runs there, in turn
        return [pid for pid in fork_map(lambda _: os.getpid(), 2, 2)]

    for pids in fork_map(nested, 2, 2):
        assert len(set(pids)) == 1 and pids[0] != os.getpid()



def test_a_job_beside_runs_in_another_process_while_this_one_goes_on():
    state = {"touched": 0}

    def job() -> tuple[int, int, list[int]]:
        state["touched"] += 1  # the child's copy
        time.sleep(1.0)
        # In the child, a map runs there, in turn: it does not fork again.
        return os.getpid(), state["touched"], fork_map(lambda _: os.getpid(), 2, 2)

    started = time.perf_counter()
    beside = Beside(job, 2)
    assert time.perf_counter() - started < 0.8 and not beside.done()  # not waited for
    state["touched"] = 10  # after the fork: the job does not see it
    pid, touched, mapped = beside.result()
    assert pid != os.getpid() and touched == 1 and mapped == [pid, pid]
    assert beside.done() and beside.result()[0] == pid and state["touched"] == 10
    # One worker: here, at once.
    here = Beside(job, 1)
    assert here.done() and here.result()[:2] == (os.getpid(), 11)


def test_a_job_beside_with_pools_maps_in_processes_of_its_own_and_cancel_ends_them(tmp_path):
    def job() -> tuple[int, list[int]]:
        return os.getpid(), fork_map(lambda _: os.getpid(), 2, 2)

    pid, mapped = Beside(job, 2, pools=True).result()
    # (in the pool's processes: which of them takes which job is the pool's)
    assert pid != os.getpid() and pid not in mapped and os.getpid() not in mapped

    def stuck(index: int) -> None:
        (tmp_path / f"{os.getpid()}.pid").touch()
        time.sleep(60)

    beside = Beside(lambda: fork_map(stuck, 2, 2), 2, pools=True)
    deadline = time.monotonic() + 30
    while len(list(tmp_path.glob("*.pid"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    pool = [int(p.stem) for p in tmp_path.glob("*.pid")]
    assert len(pool) == 2
    started = time.perf_counter()
    beside.cancel()
    assert time.perf_counter() - started < 10 and beside.done()
    with pytest.raises(RuntimeError, match="cancelled"):
        beside.result()
    deadline = time.monotonic() + 10
    while any(_alive(p) for p in pool) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_alive(p) for p in pool)  # the child's pool ended with it
    # The pool's children die of the SIGTERM that ends a map's pool, whatever the child
    # beside them does with one (a handler there, run by a child still forking, was ignored,
    # and the pool waited for it for ever: `_enter_child`).
    import signal

    defaults = Beside(lambda: fork_map(
        lambda _: signal.getsignal(signal.SIGTERM) == signal.SIG_DFL, 2, 2), 2, pools=True)
    assert defaults.result() == [True, True]

    def deaf() -> None:  # a job the SIGTERM does not end (as one that ignored its SystemExit)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        time.sleep(60)

    beside = Beside(deaf, 2, pools=True)
    time.sleep(0.5)
    started = time.perf_counter()
    beside.cancel()  # killed after 10 s
    assert time.perf_counter() - started < 20 and not _alive(beside._process.pid)
    done = Beside(lambda: 7, 2, pools=True)
    assert done.result() == 7
    done.cancel()  # ended: nothing to cancel
    assert done.result() == 7


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.parametrize("workers", [1, 2])
def test_a_job_beside_that_fails_raises_in_result(workers):
    def job() -> int:
        raise ValueError("the job beside failed")

    beside = Beside(job, workers)
    with pytest.raises(ValueError, match="the job beside failed"):
        beside.result()

def test_workers_setting(monkeypatch: pytest.MonkeyPatch):
    monkeypatch.delenv("MOCAP_WORKERS", raising=False)
    assert workers_for(0) == available_cores() >= 1
    assert workers_for(3) == 3
    with pytest.raises(ValueError, match="workers"):
        workers_for(-1)
    monkeypatch.setenv("MOCAP_WORKERS", "1")  # as `make test` sets it
    assert workers_for(0) == 1
    assert workers_for(2) == 2  # a setting given wins
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv("MOCAP_WORKERS", bad)
        with pytest.raises(UserError, match="MOCAP_WORKERS"):
            workers_for(0)


def test_a_daemon_process_runs_the_jobs_itself():
    # A Dask worker (`mocap batch`) is a daemon, which may not have children.
    import multiprocessing

    def in_daemon(queue) -> None:
        queue.put(fork_map(lambda _: os.getpid(), 3, 2) == [os.getpid()] * 3)

    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=in_daemon, args=(queue,), daemon=True)
    child.start()
    assert queue.get(timeout=30)
    child.join(timeout=30)


def test_single_blas_thread_limits_openblas_and_restores_it():
    import numpy as np  # noqa: F401  (loads numpy's OpenBLAS)
    from threadpoolctl import threadpool_info

    from recon.parallel import single_blas_thread

    def blas_threads() -> list[int]:
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    before = blas_threads()
    assert before, "numpy's BLAS is not visible to threadpoolctl"
    with single_blas_thread():
        assert blas_threads() == [1] * len(before)
    assert blas_threads() == before
