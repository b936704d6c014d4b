"""`mocap batch`: many workspaces' pipelines as Dask tasks, on one machine or on a cluster.

Scaling out is Dask's job (``dask.distributed``), which users already run on Kubernetes, HPC
schedulers and the cloud; this module only describes the work as tasks:

* each workspace's steps (``sfm`` → ``dense`` → ``mesh`` for a photo workspace,
  ``silhouettes`` → ``track`` for a video workspace, one with cameras.json) are a chain of
  tasks, one per step; chains of different workspaces (sequences) are independent and run side
  by side; tracking, sequential in time, stays one task per sequence; a step that does not
  apply to a workspace is skipped with its reason (a synthetic workspace's silhouettes are
  given), which fails nothing;
* within a ``silhouettes`` task, each camera's background model is a task of its own, then
  each run of about a dozen of a camera's frames (decoding, classification, masks) is one, the
  models sent once to the workers as :func:`map_ordered`'s shared argument
  (:func:`tracking.silhouettes.step.cameras_mapped_by`), submitted from the worker;
* within a ``dense`` task, the stereo pairs of the cpu-stereo backend are tasks of their own
  (:func:`recon.dense.backends.stereo_pairs_mapped_by`), submitted from the worker;
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

import contextlib
import enum
import importlib
import sys
import time
import traceback
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from recon.errors import UserError

if TYPE_CHECKING:
    from distributed import Client, Future

    from recon.dense.step import DenseConfig
    from recon.mesh.step import MeshConfig
    from recon.sfm.pipeline import SfMConfig
    from tracking.silhouettes.step import SilhouettesConfig
    from tracking.track.step import TrackStepConfig
    from tracking.track.tracker import TrackConfig


class BatchStep(enum.StrEnum):
    SFM = "sfm"
    DENSE = "dense"
    MESH = "mesh"
    SILHOUETTES = "silhouettes"
    TRACK = "track"


ALL_STEPS: tuple[BatchStep, ...] = tuple(BatchStep)
PHOTO_STEPS: tuple[BatchStep, ...] = (BatchStep.SFM, BatchStep.DENSE, BatchStep.MESH)
"""The steps of a photo workspace (`mocap init`), and its default."""
VIDEO_STEPS: tuple[BatchStep, ...] = (BatchStep.SILHOUETTES, BatchStep.TRACK)
"""The steps of a video workspace (one with cameras.json), and its default."""


def parse_steps(text: str | None) -> tuple[BatchStep, ...] | None:
    """``"sfm,dense,mesh"`` → steps in pipeline order (the order given does not matter);
    None → None: each workspace's own steps (photo or video)."""
    if text is None:
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in {s.value for s in BatchStep}]
    if unknown or not names:
        raise UserError(
            f"--steps {text!r}: choose from {', '.join(ALL_STEPS)} (comma-separated)"
        )
    return tuple(s for s in ALL_STEPS if s in names)


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
    steps: tuple[BatchStep, ...] | None = field(
        default=None,
        metadata={"help": "steps to run, comma-separated: sfm,dense,mesh (photo workspaces), "
                  "silhouettes,track (video workspaces); default: all of a workspace's kind"},
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
    step: BatchStep
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
            figure = _figure(s)
            parts.append(f"{s.step} {s.seconds:.1f}s" + (f" {figure}" if figure else "")
                         + (" (reused)" if s.status is StepStatus.REUSED else ""))
        return f"{self.workspace}  " + "  ".join(parts)


def _figure(outcome: StepOutcome) -> str:
    summary = outcome.summary
    if outcome.step is BatchStep.SFM and "registered" in summary:
        return f"[{summary['registered']}/{summary['images']} images, {summary['points']} points]"
    if outcome.step is BatchStep.DENSE and "points" in summary:
        return f"[{summary['points']} points]"
    if outcome.step is BatchStep.MESH and "faces" in summary:
        return f"[{summary['faces']} faces]"
    if outcome.step is BatchStep.SILHOUETTES and "cameras" in summary:
        return f"[{len(summary['cameras'])} cameras x {summary['processed']} frames]"
    if outcome.step is BatchStep.TRACK and "tracked" in summary:
        return f"[{summary['tracked']}/{summary['frames']} frames tracked]"
    return ""


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

    sfm: Any
    dense: Any
    mesh: Any
    silhouettes: Any
    track_step: Any
    track: Any
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
def _run_step(root: Path, step: BatchStep, settings: _Settings) -> StepOutcome:
    """One step of one workspace, through the workspace contract; raises on failure."""
    from recon.dense.step import densify
    from recon.mesh.step import make_mesh
    from recon.sfm.pipeline import STEPS
    from recon.workspace import Timer, Workspace

    if step in VIDEO_STEPS:
        return _run_video_step(root, step, settings)
    ws = Workspace.open(root)
    with Timer() as timer:
        if step is BatchStep.SFM:
            # `run_sfm` without its deferred recordings: they would overlap mapping only to use
            # a core that a batch keeps busy anyway, and their read of the database, right as
            # mapping opens it, can fail with "database is locked" in a warm worker process
            # (seen 1 in 32 workspaces under load; a fresh process is slowed by importing rerun).
            reused = True
            for name, sfm_step in STEPS:
                before = ws.step(name)
                record = sfm_step(ws, settings.sfm, overwrite=settings.overwrite, recordings=None)
                reused = reused and before == record
            summary = record.summary
        else:
            name = step.value
            before = ws.step(name)
            if step is BatchStep.DENSE:
                record = densify(ws, settings.dense, overwrite=settings.overwrite)
            else:
                record = make_mesh(ws, settings.mesh, overwrite=settings.overwrite)
            reused = before is not None and before == record
            summary = record.summary
    status = StepStatus.REUSED if reused else StepStatus.DONE
    return StepOutcome(step, status, timer.seconds, dict(summary))


def _run_video_step(root: Path, step: BatchStep, settings: _Settings) -> StepOutcome:
    """``silhouettes`` or ``track`` of one video workspace; raises on failure."""
    from recon.workspace import Timer, Workspace
    from tracking.silhouettes.step import make_silhouettes
    from tracking.track.step import track_workspace

    ws = Workspace.open_video(root)
    with Timer() as timer:
        if step is BatchStep.SILHOUETTES:
            before = ws.step("silhouettes")
            record = make_silhouettes(ws, settings.silhouettes, overwrite=settings.overwrite)
            reused = before is not None and before == record
            summary = dict(record.summary)
        else:
            summary = track_workspace(ws, settings.track_step, settings.track,
                                      overwrite=settings.overwrite, progress=False)
            reused = bool(summary.pop("up_to_date", False))
    status = StepStatus.REUSED if reused else StepStatus.DONE
    return StepOutcome(step, status, timer.seconds, summary)


def _kind(root: Path) -> str | None:
    """``"video"`` (cameras.json), ``"photo"`` (images/), or None: not a workspace (its steps
    then fail with the workspace's own message)."""
    if (root / "cameras.json").is_file():
        return "video"
    if (root / "images").is_dir():
        return "photo"
    return None


def _not_applicable(root: Path, step: BatchStep) -> str | None:
    """Why ``step`` does not apply to the workspace at ``root``, or None when it does."""
    kind = _kind(root)
    if kind == "video" and step in PHOTO_STEPS:
        return "not a photo workspace (it has cameras.json)"
    if kind == "photo" and step in VIDEO_STEPS:
        return "not a video workspace (no cameras.json)"
    if (step is BatchStep.SILHOUETTES and kind == "video" and not (root / "videos").is_dir()
            and (root / "run.json").is_file()):
        from recon.workspace import Workspace

        if Workspace(root).step("synth") is not None:
            return "silhouettes given (synthetic)"
    return None


def _steps_for(root: Path, steps: Sequence[BatchStep] | None) -> tuple[BatchStep, ...]:
    """The steps to run on one workspace: ``steps`` in pipeline order, or by default those of
    its kind (a folder that is no workspace gets the photo steps, which say so)."""
    if steps is None:
        return VIDEO_STEPS if _kind(root) == "video" else PHOTO_STEPS
    return _ordered(steps)


def _failed(step: BatchStep, exc: BaseException, seconds: float) -> StepOutcome:
    from plugins.registry import PluginError

    if isinstance(exc, (UserError, PluginError)):
        return StepOutcome(step, StepStatus.FAILED, seconds, error=str(exc))
    detail = "".join(traceback.format_exception(exc))
    return StepOutcome(step, StepStatus.FAILED, seconds,
                       error=f"{type(exc).__name__}: {exc}", detail=detail)


def _guarded_step(root: Path, step: BatchStep, settings: _Settings) -> StepOutcome:
    start = time.perf_counter()
    try:
        if (reason := _not_applicable(root, step)) is not None:
            return StepOutcome(step, StepStatus.SKIPPED, reason=reason)
        return _run_step(root, step, settings)
    except Exception as exc:  # one workspace's failure must not stop the batch
        return _failed(step, exc, time.perf_counter() - start)


def run_workspace(
    workspace: Path | str,
    steps: Sequence[BatchStep] | None = None,
    sfm: SfMConfig | None = None,
    dense: DenseConfig | None = None,
    mesh: MeshConfig | None = None,
    *,
    overwrite: bool = False,
    silhouettes: SilhouettesConfig | None = None,
    track_step: TrackStepConfig | None = None,
    track: TrackConfig | None = None,
) -> WorkspaceResult:
    """The steps of one workspace in this process, one after the other: what a batch task
    chain does, and the serial reference its results are compared with. ``steps`` None: those
    of the workspace's kind (:data:`PHOTO_STEPS` or :data:`VIDEO_STEPS`)."""
    settings = _settings(sfm, dense, mesh, overwrite=overwrite, pair_tasks=False,
                         silhouettes=silhouettes, track_step=track_step, track=track)
    root = Path(workspace)
    outcomes: list[StepOutcome] = []
    for step in _steps_for(root, steps):
        if outcomes and not outcomes[-1].ok:
            outcomes.append(StepOutcome(step, StepStatus.SKIPPED))
        else:
            outcomes.append(_guarded_step(root, step, settings))
    return WorkspaceResult(root, tuple(outcomes))


def _ordered(steps: Sequence[BatchStep]) -> tuple[BatchStep, ...]:
    return tuple(s for s in ALL_STEPS if s in set(steps))


def _settings(sfm: Any, dense: Any, mesh: Any, *, overwrite: bool, pair_tasks: bool,
              silhouettes: Any = None, track_step: Any = None, track: Any = None) -> _Settings:
    import pycolmap

    from recon.dense.step import DenseConfig
    from recon.mesh.step import MeshConfig
    from recon.sfm.pipeline import SfMConfig
    from tracking.silhouettes.step import SilhouettesConfig
    from tracking.track.step import TrackStepConfig
    from tracking.track.tracker import TrackConfig

    return _Settings(sfm=sfm or SfMConfig(), dense=dense or DenseConfig(),
                     mesh=mesh or MeshConfig(), silhouettes=silhouettes or SilhouettesConfig(),
                     track_step=track_step or TrackStepConfig(), track=track or TrackConfig(),
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


def _step_task(root: str, step: BatchStep, settings: _Settings,
               upstream: StepOutcome | None) -> StepOutcome:
    """A Dask task: one step of one workspace, skipped when the step before it did not
    succeed. Returns its outcome and never raises for the workspace's own errors."""
    import pycolmap

    from recon.dense.backends import stereo_pairs_mapped_by
    from tracking.silhouettes.step import cameras_mapped_by

    if upstream is not None and not upstream.ok:
        return StepOutcome(step, StepStatus.SKIPPED)
    pycolmap.logging.minloglevel = settings.colmap_log_level
    with contextlib.ExitStack() as stack:
        if step is BatchStep.DENSE and settings.pair_tasks:
            stack.enter_context(stereo_pairs_mapped_by(_map_on_this_cluster))
        if step is BatchStep.SILHOUETTES and settings.pair_tasks:
            stack.enter_context(cameras_mapped_by(_map_on_this_cluster))
        return _guarded_step(Path(root), step, settings)


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
    sfm: SfMConfig | None = None,
    dense: DenseConfig | None = None,
    mesh: MeshConfig | None = None,
    *,
    overwrite: bool = False,
    client: Client | None = None,
    echo: Callable[[str], None] | None = None,
    silhouettes: SilhouettesConfig | None = None,
    track_step: TrackStepConfig | None = None,
    track: TrackConfig | None = None,
) -> BatchReport:
    """Run ``config.steps`` of every workspace as Dask tasks; returns one result per workspace.

    ``client`` uses an existing Dask client; otherwise one is made from ``config`` (see
    :func:`connect`). ``echo`` receives the scheduler and dashboard lines as soon as they are
    known. A failed workspace is reported in its result; the others go on.
    """
    config = config or BatchConfig()
    roots = [Path(w) for w in workspaces]
    if not roots:
        raise UserError("no workspaces given")
    resolved = [r.resolve() for r in roots]
    if len(set(resolved)) < len(resolved):
        twice = sorted({str(r) for r in roots if resolved.count(r.resolve()) > 1})
        raise UserError(f"workspace given twice: {', '.join(twice)}")
    settings = _settings(sfm, dense, mesh, overwrite=overwrite, pair_tasks=config.pair_tasks,
                         silhouettes=silhouettes, track_step=track_step, track=track)
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
        steps = [_steps_for(root, config.steps) for root in resolved]
        outcomes = _submit_and_wait(client, roots, resolved, steps, settings)
        seconds = time.perf_counter() - start
    results = tuple(WorkspaceResult(root, tuple(steps)) for root, steps in zip(
        roots, outcomes, strict=True))
    return BatchReport(results, seconds, scheduler=str(info.get("address")),
                       dashboard=dashboard, workers=workers)


def _submit_and_wait(
    client: Client, roots: list[Path], resolved: list[Path],
    steps_of: list[tuple[BatchStep, ...]], settings: _Settings,
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
            chain.append(client.submit(_step_task, str(root), step, settings, upstream,
                                       key=key, pure=False))
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


def _outcome(future: Future, step: BatchStep, before: list[Future]) -> StepOutcome:
    """A finished task's outcome; a task that erred (its worker died, say) failed, and the
    steps after it, which erred because it did, were skipped."""
    if future.status != "error":
        return future.result()
    if any(f.status == "error" for f in before):
        return StepOutcome(step, StepStatus.SKIPPED)
    return _failed(step, future.exception(), 0.0)
