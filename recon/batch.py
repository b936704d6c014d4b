"""`mocap batch`: many workspaces' pipelines as Dask tasks, on one machine or on a cluster.

Scaling out is Dask's job (``dask.distributed``), which users already run on Kubernetes, HPC
schedulers and the cloud; this module only describes the work as tasks:

* the steps are plugins (kind ``step``, entry-point group ``mocap.steps``,
  :class:`plugins.protocols.BatchStep`), each of one workspace kind (:attr:`Workspace.kind
  <recon.workspace.Workspace.kind>`): ``sfm`` → ``dense`` → ``mesh`` for a photo workspace
  (:mod:`recon.batch_steps`), ``silhouettes`` → ``track`` for a video workspace, one with
  cameras.json (registered by the tracking package). A kind's pipeline is the chain of its
  steps, each after the one it ``follows``, so a new pipeline, or a step at the end of one, is
  a matter of registering entry points;
* each workspace's steps are a chain of tasks, one per step; chains of different workspaces
  (sequences) are independent and run side by side; a step that does not apply to a workspace
  is skipped with its reason (another kind's step; a synthetic workspace's silhouettes are
  given), which fails nothing;
* within a step's task, the step may fan its independent items out as tasks of their own
  (:meth:`BatchStep.fan_out <plugins.protocols.BatchStep.fan_out>`, with
  :func:`map_ordered` submitted from the worker): ``dense`` its stereo pairs
  (:func:`recon.dense.backends.stereo_pairs_mapped_by`); ``silhouettes`` each camera's
  background model, then each run of about a dozen of a camera's frames (decoding,
  classification, masks), the models sent once to the workers as :func:`map_ordered`'s shared
  argument; tracking, sequential in time, stays one task per sequence;
* :func:`map_ordered` gives the same per-item fan-out to other code, serially when there is no
  client.

A task never raises for a workspace's own failure: it returns a failed :class:`StepOutcome`,
the workspace's later steps are skipped and the other workspaces go on. A re-run resumes
through the workspace contract (:mod:`recon.workspace`): finished steps whose fingerprint
matches are reused. Every fan-out returns results in input order, so the outputs are those of a
serial run (:func:`run_workspace`).

Workers read and write the workspaces themselves: on a cluster the workspaces must be on a
file system every worker sees at the same path (paths are made absolute before submission).
"""

from __future__ import annotations

import argparse
import contextlib
import enum
import importlib
import sys
import time
import traceback
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from recon.configs import add_config_arguments
from recon.errors import UserError

if TYPE_CHECKING:
    from distributed import Client, Future

    from plugins.protocols import BatchStep
    from plugins.registry import PluginError

DEFAULT_KIND = "photo"
"""The pipeline of a folder that is no workspace: its first step says what is missing."""


@dataclass(frozen=True)
class Steps:
    """The registered batch steps that load, in pipeline order (kinds: photo first, then by
    name; within a kind, each after the step it follows), and those that do not."""

    steps: dict[str, BatchStep]
    broken: dict[str, PluginError]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.steps)

    def of_kind(self, kind: str) -> tuple[str, ...]:
        """The pipeline of a workspace kind: its steps in order."""
        return tuple(n for n, s in self.steps.items() if s.workspace == kind)

    def kinds(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(s.workspace for s in self.steps.values()))

    def ordered(self, names: Sequence[str]) -> tuple[str, ...]:
        """``names`` in pipeline order; a one-line error for an unknown or broken step."""
        for name in names:
            if name in self.broken:
                raise self.broken[name]
        unknown = [n for n in names if n not in self.steps]
        if unknown:
            raise UserError(f"unknown batch step(s) {', '.join(unknown)}; steps: "
                            f"{', '.join(self.names)}")
        return tuple(n for n in self.steps if n in set(names))


def registered_steps() -> Steps:
    """Every batch step of the entry-point group ``mocap.steps``, loaded and ordered."""
    from plugins.registry import PluginError, instantiate, load_all

    classes, broken = load_all("step")
    loaded: dict[str, BatchStep] = {}
    for name, cls in classes.items():
        try:
            loaded[name] = instantiate("step", name, cls)
        except PluginError as exc:
            broken[name] = exc
    kinds = sorted({s.workspace for s in loaded.values()}, key=lambda k: (k != DEFAULT_KIND, k))
    order: list[str] = []

    def place(name: str, seen: tuple[str, ...] = ()) -> None:
        follows = loaded[name].follows
        if (follows in loaded and loaded[follows].workspace == loaded[name].workspace
                and follows not in seen):
            place(follows, (*seen, name))
        if name not in order:
            order.append(name)

    for kind in kinds:
        for name in sorted(n for n, s in loaded.items() if s.workspace == kind):
            place(name)
    return Steps({n: loaded[n] for n in order}, broken)


def parse_steps(text: str | None, steps: Steps | None = None) -> tuple[str, ...] | None:
    """``"sfm,dense,mesh"`` → step names in pipeline order (the order given does not matter);
    None → None: each workspace's own steps (those of its kind)."""
    if text is None:
        return None
    steps = steps or registered_steps()
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in steps.steps and n not in steps.broken]
    if unknown or not names:
        raise UserError(
            f"--steps {text!r}: choose from {', '.join(steps.names)} (comma-separated)"
        )
    return steps.ordered(names)


def add_step_arguments(parser: argparse.ArgumentParser, steps: Steps | None = None) -> None:
    """``--steps`` and every step's flags, for ``mocap batch``."""
    steps = steps or registered_steps()
    pipelines = ", ".join(f"{','.join(steps.of_kind(k))} ({k} workspaces)" for k in steps.kinds())
    parser.add_argument("--steps", dest="batch_steps", default=None, metavar="STEPS",
                        help=f"steps to run, comma-separated: {pipelines}; a step that does not "
                        "apply to a workspace is skipped (default: all steps of each "
                        "workspace's kind)")
    parser.add_argument("--overwrite", action="store_true", help="recompute every step")
    add_config_arguments(parser, BatchConfig, exclude=("steps",))
    for name, step in steps.steps.items():
        try:
            step.add_arguments(parser)
        except Exception as exc:  # a third-party step's flags may clash with another's
            from plugins.registry import PluginError

            raise PluginError(f"step plugin {name!r} cannot add its flags: {exc}") from exc


def step_settings(args: argparse.Namespace, steps: Steps | None = None) -> dict[str, Any]:
    """Each step's settings from ``mocap batch``'s flags."""
    steps = steps or registered_steps()
    return {name: step.settings(args) for name, step in steps.steps.items()}


@dataclass(frozen=True, kw_only=True)
class BatchConfig:
    """Where the tasks run and which steps. Field help is the CLI's help."""

    scheduler: str | None = field(
        default=None,
        metadata={
            "help": "address of a running Dask scheduler (tcp://HOST:8786) or its scheduler "
            "file (*.json); default: start a LocalCluster sized to this machine",
            "metavar": "ADDRESS",
        },
    )
    steps: tuple[str, ...] | None = field(
        default=None,
        metadata={"help": "steps to run, by name (`mocap plugins` lists them); default: all "
                  "of a workspace's kind"},
    )
    workers: int | None = field(
        default=None,
        metadata={"help": "worker processes of the LocalCluster (default: sized to the "
                  "machine; ignored with --scheduler)"},
    )
    threads_per_worker: int | None = field(
        default=None,
        metadata={"help": "task threads per LocalCluster worker (ignored with --scheduler)"},
    )
    pair_tasks: bool = field(
        default=True,
        metadata={"help": "run the dense stereo pairs, and the silhouettes (a task per "
                  "camera's background model, then per run of about 12 of a camera's frames), "
                  "of a workspace as tasks of their own (--no-pair-tasks: inside its step's "
                  "task)"},
    )

    def __post_init__(self) -> None:
        if self.steps is not None and not self.steps:
            raise UserError("no steps to run; give --steps sfm,dense,mesh or a part of it")
        for name in ("workers", "threads_per_worker"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise UserError(f"--{name.replace('_', '-')} must be at least 1, got {value}")


class StepStatus(enum.StrEnum):
    DONE = "done"
    REUSED = "reused"
    FAILED = "failed"
    SKIPPED = "skipped"


@dataclass(frozen=True)
class StepOutcome:
    step: str
    status: StepStatus
    seconds: float = 0.0
    summary: dict[str, Any] = field(default_factory=dict)
    """The step's record summary in run.json (mapping's for ``sfm``)."""
    error: str | None = None
    """One line, for a failed step: the UserError's message, else ``Type: message``."""
    detail: str | None = None
    """The traceback of an unexpected error (not a UserError)."""
    reason: str | None = None
    """Why a step was skipped although nothing failed (it does not apply to the workspace)."""
    figure: str = ""
    """The step's short figure of its result for the report line (``[120 faces]``)."""

    @property
    def ok(self) -> bool:
        """Done, reused, or skipped for a reason (not because an earlier step failed)."""
        return (self.status in (StepStatus.DONE, StepStatus.REUSED)
                or (self.status is StepStatus.SKIPPED and self.reason is not None))


@dataclass(frozen=True)
class WorkspaceResult:
    workspace: Path
    steps: tuple[StepOutcome, ...]

    @property
    def ok(self) -> bool:
        return all(s.ok for s in self.steps)

    @property
    def failure(self) -> StepOutcome | None:
        return next((s for s in self.steps if s.status is StepStatus.FAILED), None)

    def line(self) -> str:
        if (failed := self.failure) is not None:
            return f"{self.workspace}  FAILED at {failed.step}: {failed.error}"
        parts = []
        for s in self.steps:
            if s.status is StepStatus.SKIPPED:
                parts.append(f"{s.step} skipped ({s.reason})")
                continue
            parts.append(f"{s.step} {s.seconds:.1f}s" + (f" {s.figure}" if s.figure else "")
                         + (" (reused)" if s.status is StepStatus.REUSED else ""))
        return f"{self.workspace}  " + "  ".join(parts)


@dataclass(frozen=True)
class BatchReport:
    results: tuple[WorkspaceResult, ...]
    seconds: float
    scheduler: str | None = None
    """Scheduler address, or None for a serial run."""
    dashboard: str | None = None
    workers: int = 0

    @property
    def failed(self) -> tuple[WorkspaceResult, ...]:
        return tuple(r for r in self.results if not r.ok)

    def lines(self) -> list[str]:
        ok = len(self.results) - len(self.failed)
        return [
            *(r.line() for r in self.results),
            f"done        {ok} of {len(self.results)} workspaces in {self.seconds:.1f} s"
            + (f" ({len(self.failed)} failed)" if self.failed else ""),
        ]


@dataclass(frozen=True)
class _Settings:
    """What every step task of a batch needs; small and picklable."""

    steps: dict[str, Any]
    """Each step's settings, by name."""
    overwrite: bool
    pair_tasks: bool
    colmap_log_level: int


# Generic ordered fan-out ----------------------------------------------------------------------
def map_ordered(client: Client | None, fn: Callable[..., Any], items: Sequence[Any],
                *shared: Any, priority: int = 0) -> list[Any]:
    """``[fn(item, *shared) for item in items]``, as Dask tasks when ``client`` is given.

    Results come back in input order whatever order the tasks finish in, so a caller that
    merges them is as deterministic as the serial loop (``client=None``). ``shared`` arguments
    (camera views, background models) are scattered once, not shipped with every task; items
    go with their task, so keep them small (indices, or one frame each). ``priority`` is
    Dask's: higher runs first among ready tasks.
    """
    items = list(items)
    if client is None:
        return [fn(item, *shared) for item in items]
    if not items:
        return []
    shared_futures = client.scatter(list(shared), hash=False) if shared else []
    futures = client.map(fn, items, *([f] * len(items) for f in shared_futures), pure=False,
                         priority=priority)
    try:
        return client.gather(futures)
    except BaseException:
        client.cancel(futures)
        raise


def _map_on_this_cluster(fn: Callable[..., Any], items: Sequence[Any], *shared: Any) -> list[Any]:
    """:func:`map_ordered` from inside a task, on the cluster that runs it.

    ``worker_client`` secedes the calling task from the worker's thread pool only while it
    waits, so its tasks (stereo pairs; silhouettes: background models, then runs of frames,
    two calls) can run on the same worker without a deadlock. They go before other
    workspaces' waiting steps: a started step finishes first and frees its memory.
    """
    from distributed import worker_client

    with worker_client() as client:
        return map_ordered(client, fn, items, *shared, priority=1)


# One workspace ------------------------------------------------------------------------------------
def _run_step(root: Path, name: str, step: BatchStep, settings: _Settings) -> StepOutcome:
    """One step of one workspace, through the workspace contract; raises on failure."""
    from recon.workspace import Timer

    with Timer() as timer:
        result = step.run(root, settings.steps[name], overwrite=settings.overwrite)
    status = StepStatus.REUSED if result.reused else StepStatus.DONE
    return StepOutcome(name, status, timer.seconds, dict(result.summary),
                       figure=step.figure(result.summary))


def _not_applicable(root: Path, step: BatchStep) -> str | None:
    """Why ``step`` does not apply to the workspace at ``root``, or None when it does."""
    from recon.workspace import Workspace

    ws = Workspace(root)
    if (mismatch := ws.kind_mismatch(step.workspace)) is not None:
        return mismatch
    return step.skip_reason(root) if ws.kind == step.workspace else None


def _steps_for(root: Path, steps: Sequence[str] | None, registered: Steps) -> tuple[str, ...]:
    """The steps to run on one workspace: ``steps`` in pipeline order, or by default those of
    its kind (a folder that is no workspace gets the photo steps, which say so)."""
    from recon.workspace import Workspace

    if steps is None:
        return registered.of_kind(Workspace(root).kind or DEFAULT_KIND)
    return registered.ordered(steps)


def _failed(step: str, exc: BaseException, seconds: float) -> StepOutcome:
    from plugins.registry import PluginError

    if isinstance(exc, (UserError, PluginError)):
        return StepOutcome(step, StepStatus.FAILED, seconds, error=str(exc))
    detail = "".join(traceback.format_exception(exc))
    return StepOutcome(step, StepStatus.FAILED, seconds,
                       error=f"{type(exc).__name__}: {exc}", detail=detail)


def _guarded_step(root: Path, name: str, step: BatchStep, settings: _Settings) -> StepOutcome:
    from recon.workspace import workspace_lock

    start = time.perf_counter()
    try:
        if (reason := _not_applicable(root, step)) is not None:
            return StepOutcome(name, StepStatus.SKIPPED, reason=reason)
        with workspace_lock(root, f"mocap batch, step {name}"):
            return _run_step(root, name, step, settings)
    except Exception as exc:  # one workspace's failure must not stop the batch
        return _failed(name, exc, time.perf_counter() - start)


def run_workspace(
    workspace: Path | str,
    steps: Sequence[str] | None = None,
    settings: Mapping[str, Any] | None = None,
    *,
    overwrite: bool = False,
) -> WorkspaceResult:
    """The steps of one workspace in this process, one after the other: what a batch task
    chain does, and the serial reference its results are compared with. ``steps`` None: those
    of the workspace's kind. ``settings``: settings by step name (``{"sfm": SfMConfig(...)}``);
    a step left out runs with its defaults."""
    registered = registered_steps()
    batch = _settings(settings, registered, overwrite=overwrite, pair_tasks=False)
    root = Path(workspace)
    outcomes: list[StepOutcome] = []
    for name in _steps_for(root, steps, registered):
        if outcomes and not outcomes[-1].ok:
            outcomes.append(StepOutcome(name, StepStatus.SKIPPED))
        else:
            outcomes.append(_guarded_step(root, name, registered.steps[name], batch))
    return WorkspaceResult(root, tuple(outcomes))


def _settings(settings: Mapping[str, Any] | None, registered: Steps, *, overwrite: bool,
              pair_tasks: bool) -> _Settings:
    import pycolmap

    given = dict(settings or {})
    unknown = sorted(set(given) - set(registered.steps))
    if unknown:
        raise UserError(f"settings of unknown batch step(s) {', '.join(unknown)}; steps: "
                        f"{', '.join(registered.names)}")
    return _Settings(
        steps={name: given[name] if given.get(name) is not None else step.settings(None)
               for name, step in registered.steps.items()},
        overwrite=overwrite, pair_tasks=pair_tasks,
        colmap_log_level=int(pycolmap.logging.minloglevel))


# The Dask side ----------------------------------------------------------------------------------
class _NotATerminal:
    """stderr of a worker as the step bars see it: not a terminal, so they stay off (tqdm's
    ``disable=None``). A worker's bars would interleave with the batch bar on the console."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def isatty(self) -> bool:
        return False

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def _prepare_worker(nthreads: int) -> None:
    """Once per worker process, on its main thread (a WorkerPlugin's setup runs there).

    Open3D and pymeshlab imported for the first time together on a task thread corrupt the
    heap: the process aborts in pymeshlab's ``PluginManager`` destructor when it exits
    (measured with open3d 0.20 and pymeshlab 2025.7; either one alone, or both imported on
    the main thread first, is fine). It also takes the imports out of the first task's time.
    OpenCV's thread pool is sized to the worker's task threads: a LocalCluster already has a
    worker per core, and more threads per worker would only compete (stereo results do not
    depend on it).
    """
    importlib.import_module("recon.mesh.meshing")  # open3d and pymeshlab
    importlib.import_module("pycolmap")
    importlib.import_module("cv2").setNumThreads(max(1, nthreads))
    if not isinstance(sys.stderr, _NotATerminal):
        sys.stderr = _NotATerminal(sys.stderr)


def _worker_plugin() -> Any:
    from distributed.diagnostics.plugin import WorkerPlugin

    class MocapWorkerSetup(WorkerPlugin):
        name = "mocap-worker-setup"

        def setup(self, worker: Any) -> None:
            _prepare_worker(worker.state.nthreads)

    return MocapWorkerSetup()


def _step_task(root: str, name: str, step: BatchStep, settings: _Settings,
               upstream: StepOutcome | None) -> StepOutcome:
    """A Dask task: one step of one workspace, skipped when the step before it did not
    succeed. Returns its outcome and never raises for the workspace's own errors."""
    import pycolmap

    if upstream is not None and not upstream.ok:
        return StepOutcome(name, StepStatus.SKIPPED)
    pycolmap.logging.minloglevel = settings.colmap_log_level
    with contextlib.ExitStack() as stack:
        if settings.pair_tasks:
            stack.enter_context(step.fan_out(_map_on_this_cluster))
        return _guarded_step(Path(root), name, step, settings)


def _worker_versions() -> dict[str, str]:
    from recon.workspace import package_versions

    return package_versions()


@contextlib.contextmanager
def connect(config: BatchConfig) -> Iterator[Client]:
    """A client of ``config.scheduler``, or of a LocalCluster (processes on loopback) sized to
    this machine or to ``config.workers`` x ``config.threads_per_worker``."""
    from distributed import Client, LocalCluster

    if config.scheduler is None:
        with LocalCluster(n_workers=config.workers, threads_per_worker=config.threads_per_worker,
                          processes=True, host="127.0.0.1") as cluster, Client(cluster) as client:
            yield client
        return
    target = config.scheduler
    kwargs: dict[str, Any] = (
        {"scheduler_file": target} if target.endswith(".json") else {"address": target}
    )
    if "scheduler_file" in kwargs and not Path(target).is_file():
        raise UserError(f"--scheduler {target}: no such scheduler file")
    try:
        client = Client(**kwargs, timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise UserError(f"cannot reach the Dask scheduler at {target}: {exc}") from None
    with client:
        yield client


def _dashboard(client: Client) -> str | None:
    """The dashboard link when the scheduler serves one (it needs bokeh installed there)."""
    if "dashboard" not in client.scheduler_info().get("services", {}):
        return None
    # Without bokeh the scheduler still serves a page at that address, saying to install it.
    scheduler = client.get_versions(packages=["bokeh"]).get("scheduler") or {}
    return client.dashboard_link if scheduler.get("packages", {}).get("bokeh") else None


def _check_workers(client: Client) -> list[str]:
    """Workers that cannot import this package would fail every task: say so up front. Other
    versions of the libraries that compute are worth a note (results may differ)."""
    if not client.scheduler_info().get("workers"):
        return []  # none yet (an adaptive cluster starts them on demand)
    try:
        versions = client.run(_worker_versions)
    except Exception as exc:
        raise UserError(
            f"the Dask workers cannot run mocap tasks ({type(exc).__name__}: {exc}); install "
            "mocap-recon, the same version as here, in every worker's environment"
        ) from None
    from recon.workspace import package_versions

    mine = package_versions()
    notes = []
    for worker, theirs in sorted(versions.items()):
        differ = [f"{k} {theirs.get(k)}" for k in ("mocap-recon", "pycolmap", "open3d",
                                                   "opencv-python-headless", "pymeshlab")
                  if theirs.get(k) != mine.get(k)]
        if differ:
            notes.append(f"note        worker {worker} has {', '.join(differ)}: results may "
                         "differ from a run on this machine")
    return notes


def run_batch(
    workspaces: Sequence[Path | str],
    config: BatchConfig | None = None,
    settings: Mapping[str, Any] | None = None,
    *,
    overwrite: bool = False,
    client: Client | None = None,
    echo: Callable[[str], None] | None = None,
) -> BatchReport:
    """Run ``config.steps`` of every workspace as Dask tasks; returns one result per workspace.

    ``settings``: settings by step name, as for :func:`run_workspace`. ``client`` uses an
    existing Dask client; otherwise one is made from ``config`` (see :func:`connect`). ``echo``
    receives the scheduler and dashboard lines as soon as they are known. A failed workspace is
    reported in its result; the others go on.
    """
    config = config or BatchConfig()
    roots = [Path(w) for w in workspaces]
    if not roots:
        raise UserError("no workspaces given")
    resolved = [r.resolve() for r in roots]
    if len(set(resolved)) < len(resolved):
        twice = sorted({str(r) for r in roots if resolved.count(r.resolve()) > 1})
        raise UserError(f"workspace given twice: {', '.join(twice)}")
    registered = registered_steps()
    batch = _settings(settings, registered, overwrite=overwrite, pair_tasks=config.pair_tasks)
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(connect(config))
        notes = _check_workers(client)
        client.register_plugin(_worker_plugin())
        info = client.scheduler_info()
        dashboard = _dashboard(client)
        workers = len(info.get("workers", {}))
        if echo is not None:
            threads = sum(w.get("nthreads", 0) for w in info.get("workers", {}).values())
            echo(f"scheduler   {info.get('address')}  ({workers} workers, {threads} threads)")
            echo(f"dashboard   {dashboard}" if dashboard else
                 "dashboard   none (install bokeh where the scheduler runs to get one)")
            for note in notes:
                echo(note)
        start = time.perf_counter()
        steps = [_steps_for(root, config.steps, registered) for root in resolved]
        outcomes = _submit_and_wait(client, roots, resolved, steps, registered, batch)
        seconds = time.perf_counter() - start
    results = tuple(WorkspaceResult(root, tuple(steps)) for root, steps in zip(
        roots, outcomes, strict=True))
    return BatchReport(results, seconds, scheduler=str(info.get("address")),
                       dashboard=dashboard, workers=workers)


def _submit_and_wait(
    client: Client, roots: list[Path], resolved: list[Path],
    steps_of: list[tuple[str, ...]], registered: Steps, settings: _Settings,
) -> list[list[StepOutcome]]:
    from distributed import as_completed

    from recon.progress import bar

    run = uuid.uuid4().hex[:8]
    chains: list[list[Future]] = []
    for index, (root, steps) in enumerate(zip(resolved, steps_of, strict=True)):
        chain: list[Future] = []
        for step in steps:
            upstream = chain[-1] if chain else None
            # Readable keys: the dashboard's task stream shows step and workspace.
            key = f"mocap-{step}-{index}-{root.name}-{run}"
            chain.append(client.submit(_step_task, str(root), step, registered.steps[step],
                                       settings, upstream, key=key, pure=False))
        chains.append(chain)
    where = {f.key: (i, k) for i, chain in enumerate(chains) for k, f in enumerate(chain)}
    progress = bar(len(where), "batch", "step")
    failed = 0
    for future in as_completed([f for chain in chains for f in chain]):
        i, k = where[future.key]
        failed += _is_failure(future, chains[i][k - 1] if k else None)
        progress.set_postfix_str(f"{roots[i].name} {steps_of[i][k]}"
                                 + (f", {failed} failed" if failed else ""))
        progress.update(1)
    progress.close()
    return [[_outcome(future, steps[k], chain[:k]) for k, future in enumerate(chain)]
            for chain, steps in zip(chains, steps_of, strict=True)]


def _is_failure(future: Future, upstream: Future | None) -> bool:
    """Whether this finished task is where its workspace failed (not a step skipped after)."""
    if future.status == "error":
        return upstream is None or upstream.status != "error"
    return future.result().status is StepStatus.FAILED


def _outcome(future: Future, step: str, before: list[Future]) -> StepOutcome:
    """A finished task's outcome; a task that erred (its worker died, say) failed, and the
    steps after it, which erred because it did, were skipped."""
    if future.status != "error":
        return future.result()
    if any(f.status == "error" for f in before):
        return StepOutcome(step, StepStatus.SKIPPED)
    return _failed(step, future.exception(), 0.0)
