"""Independent CPU-bound jobs on this machine's cores, in forked processes.

The jobs of a step that share large read-only state (a frame's silhouettes, pyramids and
compiled renderers) are run by `fork_map`: the children inherit that state from the fork,
copy-on-write, and only the jobs' indices and results cross a pipe. Processes rather than
threads: the jobs are numpy and Python between short compiled calls, which the GIL would
serialise, and an idle child blocks on its pipe instead of spinning (OpenMP's threads spin
between calls, measured 3.5 times slower per evaluation than one thread each when two such
processes share 2 cores; session 27).

BLAS: OpenBLAS starts a thread per core for the products numpy hands it, which then spin between
calls; the tracker's products are small (an outline system's 26 columns, a skinning matrix), so
`single_blas_thread` runs it, and `fork_map`'s children, on one. Measured (session 28, `mocap
track --init-pose` of the suite's walk, 30 frames): alone, 31.9-34.9 s and 45-48 s of CPU with
OpenBLAS's threads against 28.2-32.1 s and 28-31 s with one; two such runs side by side (as in
`make test`, or a forked start's children), 50.5-56.2 s against 33.4-37.6 s.
"""

from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import os
import signal
from collections.abc import Callable
from typing import Any, Generic, TypeVar

T = TypeVar("T")

# The job of the pool being forked: a child inherits it (nothing is pickled but indices and
# results). One pool at a time per process; a child does not fork again.
_job: Callable[[int], object] | None = None
_in_child = False


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity, which containers and ``taskset``
    restrict), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def workers_for(setting: int) -> int:
    """The processes a ``--workers`` setting asks for: 0 means the environment's
    ``MOCAP_WORKERS`` when set (as ``OMP_NUM_THREADS`` sets OpenMP's threads: `make test` sets
    1, its two test processes already busy on the 2 cores), else `available_cores`."""
    if setting < 0:
        raise ValueError(f"workers must be >= 0, got {setting}")
    if setting:
        return setting
    value = os.environ.get("MOCAP_WORKERS", "").strip()
    if value:
        if not value.isdigit() or int(value) < 1:
            from recon.errors import UserError

            raise UserError(f"MOCAP_WORKERS={value!r}: expected a whole number >= 1 (the "
                            "processes of --workers 0), or unset it")
        return int(value)
    return available_cores()


def settings_of(config: Any) -> dict[str, Any]:
    """A config dataclass's fields that a step's fingerprint holds: all but ``workers``, which
    changes the speed, not the result (a step is not run again for it)."""
    return {k: v for k, v in dataclasses.asdict(config).items() if k != "workers"}


def fork_map(job: Callable[[int], T], count: int, workers: int) -> list[T]:
    """``[job(0), ..., job(count - 1)]``, computed by up to `workers` forked processes (in
    order, one job at a time each, the next to the first idle one); in this process when one
    worker is asked for, there is one job, fork is unavailable (not on POSIX), or this
    process is itself a `fork_map` child or a daemon (a Dask worker of `mocap batch`, which
    may not have children). `job` must not depend on side effects of the other
    jobs: each child's changes to its copy of the state are lost, so return what the parent
    needs. An exception in a job is raised here."""
    workers = min(workers, count)
    if (workers <= 1 or _in_child or multiprocessing.current_process().daemon
            or "fork" not in multiprocessing.get_all_start_methods()):
        return [job(i) for i in range(count)]
    global _job
    _job = job
    try:
        with multiprocessing.get_context("fork").Pool(workers, initializer=_enter_child) as pool:
            return pool.map(_run, range(count), chunksize=1)
    finally:
        _job = None


class Beside(Generic[T]):
    """``job()`` computed in a forked process beside this one, which goes on meanwhile: `done`
    says whether it has ended, `result` waits for it (and raises what it raised), `cancel`
    ends it unwaited. Computed here, at once, where `fork_map` would not fork: one worker
    asked for, no fork, or this process a `fork_map` child or a daemon. `job` sees this
    process's state as it was at the fork, so it must not depend on what this process does
    after it; it returns what this process needs (its other changes are lost with the child).

    pools: the child may run `fork_map`s of its own (with the workers they ask for; it is then
    no daemon, in a process group of its own with its pool, which `cancel` ends): for a job
    that is itself side by side work (a tracker's start search) beside work on one core. Else
    a map in the child runs there, in turn."""

    def __init__(self, job: Callable[[], T], workers: int, *, pools: bool = False) -> None:
        self._outcome: tuple[bool, Any] | None = None
        self._process: Any = None
        self._pools = pools
        if (workers <= 1 or _in_child or multiprocessing.current_process().daemon
                or "fork" not in multiprocessing.get_all_start_methods()):
            try:
                self._outcome = (True, job())
            except Exception as exc:  # raised by `result`, as from the child
                self._outcome = (False, exc)
            return
        context = multiprocessing.get_context("fork")
        self._receive, send = context.Pipe(duplex=False)
        # daemon: ended with this process (and, as a `fork_map` child, forking no further);
        # with pools, a daemon may not fork: `cancel` ends it.
        self._process = context.Process(target=_send_outcome, args=(job, send, pools),
                                         daemon=not pools)  # fmt: skip
        self._process.start()
        if pools:  # (the child sets it too: whichever runs first)
            with contextlib.suppress(OSError):
                os.setpgid(self._process.pid, self._process.pid)
        send.close()

    def done(self) -> bool:
        """Whether `result` would return without waiting."""
        return self._outcome is not None or self._receive.poll()

    def result(self) -> T:
        """The job's result, once it has ended."""
        if self._outcome is None:
            try:
                self._outcome = self._receive.recv()
            except EOFError:  # the child died without a word (killed)
                self._outcome = (False, RuntimeError(
                    f"a process beside this one ended without a result (exit code "
                    f"{self._process.exitcode})"))
            finally:
                self._process.join()
                self._receive.close()
        ok, value = self._outcome
        if not ok:
            raise value
        return value

    def cancel(self) -> None:
        """Ends the job unwaited (its child and the child's pool) if it has not ended; its
        `result` is then an error. Nothing where it has ended or ran here."""
        if self._outcome is not None:
            return
        if not self._pools:
            self._process.terminate()
        else:
            # Its pool's children die at once (`_enter_child`), and it leaves by SystemExit,
            # its pools reaped; where that does not end it in 10 s (a handler that ran where
            # exceptions are ignored), all are killed.
            for sig, wait_s in ((signal.SIGTERM, 10.0), (signal.SIGKILL, None)):
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self._process.pid, sig)
                self._process.join(wait_s)
                if not self._process.is_alive():
                    break
        self._process.join()
        self._receive.close()
        self._outcome = (False, RuntimeError("the process beside this one was cancelled"))


def _send_outcome(job: Callable[[], object], send: Any, pools: bool = False) -> None:
    """A `Beside` child: the job run as `fork_map`'s children run theirs (with `pools`, free
    to run maps of its own, which a termination ends: `Beside.cancel`), its outcome sent."""
    if pools:
        with contextlib.suppress(OSError):
            os.setpgid(0, 0)  # (`Beside.cancel` ends the group)

        def ended(*_: object) -> None:
            raise SystemExit(1)  # a map's pool is ended by its context on the way out

        signal.signal(signal.SIGTERM, ended)
        single_blas_thread()
    else:
        _enter_child()
    try:
        outcome: tuple[bool, object] = (True, job())
    except Exception as exc:
        outcome = (False, exc)
    try:
        send.send(outcome)
    except Exception as exc:  # an outcome that does not pickle
        send.send((False, RuntimeError(f"{type(exc).__name__}: {exc}")))
    send.close()


def single_blas_thread() -> contextlib.AbstractContextManager[object]:
    """A context in which numpy's and scipy's BLAS (OpenBLAS) use one thread (module
    docstring); as it was on leaving."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


def _enter_child() -> None:
    global _in_child
    _in_child = True
    # A map's pool ends its idle children with SIGTERM: they die at once, whatever handler
    # the process that forked them had. A `Beside` with pools has one (raising SystemExit):
    # a child that the SIGTERM met while forking ran it in `threading._after_fork`, which
    # ignores exceptions, and it then waited on the pool's lock for ever, and the pool for it
    # (about one map in a thousand; 2 of 10 tracks of session 48's 60 fps runs hung).
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    single_blas_thread()  # for the child's life: it ends with the map


def _run(index: int) -> object:
    assert _job is not None
    return _job(index)
