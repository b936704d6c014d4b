"""The workspace on disk, owned by one class.

Layout (COLMAP's own, so its GUI and tools open it)::

    WS/
      images/            photos, hard-linked or copied from the source folder, never modified
      database.db        COLMAP database: cameras, keypoints, matches, two-view geometries
      sparse/0/          largest COLMAP binary model (sparse/1, ... for other models)
      dense/undistorted/ undistorted (and downscaled) images and PINHOLE model, COLMAP layout
      dense/fused.ply    dense coloured point cloud with normals
      mesh/mesh.ply      coloured mesh; mesh.obj and mesh.glb for Blender and the web
      logs/<step>.rrd    one Rerun recording per step
      run.json           config, package versions and timing of every step

A step is a function from a workspace to files in it. It is idempotent: it is skipped when its
output exists and its recorded fingerprint (its config plus its inputs' fingerprints) matches.
Outputs are written to a ``.partial`` sibling and renamed into place, so an interrupted step
never leaves a file that a later step would trust.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import platform
import re
import shutil
import stat
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

from recon.errors import UserError
from recon.sfm.images import IMAGE_SUFFIXES, scan_images

RUN_FORMAT = "mocap-workspace-v1"

_PACKAGES = (
    "mocap-recon", "pycolmap", "open3d", "numpy", "opencv-python-headless",
    "pymeshlab", "rerun-sdk", "scipy",
)


@functools.cache
def package_versions() -> dict[str, str]:
    """Versions of Python and of the packages a run depends on (read once per process)."""
    versions = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            versions[name] = "not installed"
    return versions


STEP_VERSIONS: dict[str, int] = {
    "track": 3,  # 2: poses in the rig's upright frame (pose.json's world_from_upright);
    # 3: 26 pose parameters (the spine's side bend and twist)
    "fit": 4,  # 2: fit.json is a pose file (frames, world_from_upright) that --init-pose reads;
    # 3: a limb fitted elsewhere fails the fit, and a skinned body fits clouds of unknown scale;
    # 4: 26 pose parameters, and a plane through the body is no longer taken for a floor
}
"""The version of each step's code (unlisted steps: 1). Bump a step's number when its outputs
change for the same settings (a new format or method): its results in existing workspaces are
then recomputed instead of reused, and so are those of the steps after it, whose upstream
fingerprint changes with it."""


def _versioned(name: str, step_fingerprint: str) -> str:
    version = STEP_VERSIONS.get(name, 1)
    return step_fingerprint if version == 1 else f"{step_fingerprint}.v{version}"


def fingerprint(*parts: Any) -> str:
    """Stable short hash of JSON-serialisable parts (configs and upstream fingerprints)."""
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def file_digest(path: Path | str) -> str:
    """Short hash of a file's content (16 hex digits of its SHA-256, as :func:`fingerprint`),
    for fingerprints of steps that read it. Read in 1 MiB chunks: inputs may be videos."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        while chunk := handle.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()[:16]


_SIGNED_SPAN = 1 << 20
"""Bytes read from each end of a file for its signature: the whole of a file up to 2 MiB."""
_SQLITE_MAGIC = b"SQLite format 3\x00"
_signature_memo: dict[tuple[str, int, int, int], str] = {}


def _file_signature(path: Path) -> str:
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns, st.st_ino)
    if (memo := _signature_memo.get(key)) is not None:
        return memo
    digest = hashlib.sha256(str(st.st_size).encode())
    with path.open("rb") as handle:
        head = handle.read(_SIGNED_SPAN)
        if head.startswith(_SQLITE_MAGIC):
            # SQLite bumps its file change counter (header bytes 24-27, and 92-95 with it) in
            # every write transaction, and COLMAP opens even a database it only reads with one:
            # the counter is not content.
            head = head[:24] + bytes(4) + head[28:92] + bytes(4) + head[96:]
        digest.update(head)
        if st.st_size > 2 * _SIGNED_SPAN:
            handle.seek(st.st_size - _SIGNED_SPAN)
        digest.update(handle.read(_SIGNED_SPAN))
    _signature_memo[key] = digest.hexdigest()[:16]
    return _signature_memo[key]


def output_signature(path: Path | str) -> str | None:
    """A cheap content signature of a step's output, recorded in run.json: per file its size
    and the SHA-256 of its first and last MiB (all of it up to 2 MiB); a folder's combines its
    files' relative names and signatures. None when ``path`` does not exist.

    Truncation, an append, a replaced or deleted file all change it; mtimes do not enter it, so
    a copied workspace (``cp -r``) keeps its steps. The hash of a file is remembered per process
    for its (size, mtime, inode), so checking an unchanged folder costs only ``stat`` calls.
    """
    path = Path(path)
    if path.is_file():
        return _file_signature(path)
    if not path.is_dir():
        return None
    digest = hashlib.sha256(b"folder")
    for file in sorted(p for p in path.rglob("*") if p.is_file()):
        digest.update(f"{file.relative_to(path).as_posix()}\0{_file_signature(file)}\0".encode())
    return digest.hexdigest()[:16]


def partial_path(target: Path) -> Path:
    """Temporary sibling of ``target`` that keeps its extension (``mesh.partial.ply``), so that
    writers choosing the format by extension (Open3D, OpenCV, matplotlib) work on it."""
    return target.with_name(f"{target.stem}.partial{target.suffix}")


def write_json_atomic(path: Path, data: Any) -> None:
    tmp = partial_path(path)
    tmp.write_text(json.dumps(data, indent=2, default=str) + "\n")
    os.replace(tmp, path)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


_SQLITE_SIDECARS = ("-wal", "-shm", "-journal")
"""SQLite's files beside a database (write-ahead log, its index, rollback journal): part of the
database. A stale one beside a fresh copy is replayed into it by SQLite, so they are removed and
moved together with the database (issue 23: a killed run's ``-wal`` corrupted the next copy)."""


def _sidecars(path: Path) -> list[Path]:
    return [path.with_name(path.name + suffix) for suffix in _SQLITE_SIDECARS]


def _remove_with_sidecars(path: Path) -> None:
    _remove(path)
    for sidecar in _sidecars(path):
        _remove(sidecar)


def current_umask() -> int:
    """The process's file-creation mask (read without changing it where Linux allows)."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)  # elsewhere the only way to read it is to set it, then restore it
    os.umask(mask)
    return mask


def output_mode(*, folder: bool = False) -> int:
    """Permission bits of a new output: what ``open()`` / ``mkdir()`` give under the umask
    (0644 / 0755 with the usual 022)."""
    return (0o777 if folder else 0o666) & ~current_umask()


def set_output_modes(path: Path) -> None:
    """Give ``path`` (and, for a folder, everything in it) the mode of a new output.

    Writers that go through `tempfile` (``mkstemp``, ``mkdtemp``) create 0600 / 0700 on
    purpose; renamed into place, such a file would be the one output others cannot read
    (issue 21: ``tracks/motion.bvh`` was 0600 while the rest was 0644). Symbolic links and
    hard-linked files (more than one link: the photos and videos a workspace links to its
    sources) are left alone: their mode is their source's, which is only read.
    """
    file_mode, folder_mode = output_mode(), output_mode(folder=True)

    def settle(item: str, wanted: int) -> None:
        st = os.lstat(item)
        if stat.S_ISLNK(st.st_mode) or (not stat.S_ISDIR(st.st_mode) and st.st_nlink > 1):
            return
        if stat.S_IMODE(st.st_mode) != wanted:
            # A mode that cannot be set (a file of another user) is no reason to lose the output.
            with contextlib.suppress(PermissionError):
                os.chmod(item, wanted)

    if not path.is_dir() or path.is_symlink():
        settle(str(path), file_mode)
        return
    settle(str(path), folder_mode)
    for folder, dirs, files in os.walk(path):  # symbolic links to folders are not followed
        for name in dirs:
            settle(os.path.join(folder, name), folder_mode)
        for name in files:
            settle(os.path.join(folder, name), file_mode)


@contextlib.contextmanager
def atomic_output(target: Path, *, seed_from: Path | None = None) -> Iterator[Path]:
    """Yield a temporary path next to ``target``; on success it replaces ``target``.

    ``seed_from`` copies an existing file first, for steps that update a file in place (the
    COLMAP database). On failure the temporary path is removed and ``target`` is untouched.
    SQLite's sidecar files (``-wal``, ``-shm``, ``-journal``) of the temporary path are removed
    with it, and travel with it on success, so a killed run's leftovers never reach a copy.
    Whatever wrote it, the output gets the mode of a new file (folder) under the umask
    (`set_output_modes`), so every output is equally readable.
    """
    tmp = partial_path(target)
    _remove_with_sidecars(tmp)
    if seed_from is not None:
        shutil.copy2(seed_from, tmp)
    try:
        yield tmp
    except BaseException:
        _remove_with_sidecars(tmp)
        raise
    if tmp.exists() and not tmp.is_symlink():
        set_output_modes(tmp)
    if tmp.is_dir():
        # A directory cannot be atomically swapped over a non-empty one: move the old one aside
        # first, so that at every instant either the old or the new model is complete.
        old = target.with_name(target.name + ".old")
        _remove(old)
        if target.exists():
            os.replace(target, old)
        os.replace(tmp, target)
        _remove(old)
    else:
        # The target's own sidecars belong to the file being replaced: drop them first.
        for sidecar in _sidecars(target):
            _remove(sidecar)
        os.replace(tmp, target)
        for tmp_sidecar, sidecar in zip(_sidecars(tmp), _sidecars(target), strict=True):
            if tmp_sidecar.exists():
                os.replace(tmp_sidecar, sidecar)


LOCK_NAME = ".mocap.lock"
"""The workspace lock file: it exists while a `mocap` process writes the workspace and holds
that process's PID and command (for the message another writer gets)."""

_held_locks: dict[Path, int] = {}
"""Workspaces this process has locked, by resolved path, and how many times (re-entrant)."""


@contextlib.contextmanager
def workspace_lock(root: Path | str, purpose: str) -> Iterator[None]:
    """Hold the workspace at ``root`` for writing; another process that tries is refused in
    one line (a :class:`UserError` naming the holder's PID and command), and so is a workspace
    that cannot be written (read-only).

    The lock is ``flock`` on ``root/.mocap.lock``: the kernel releases it when its process
    ends, kill -9 included, so a dead run never blocks the next one. The file is removed on
    release. Taking the lock sweeps away the temporaries killed runs left (partial files, their
    SQLite sidecars, scratch folders): no other run can be writing them. Re-entrant within a
    process. A folder made only to hold the lock is removed again when nothing else was
    written into it (bad input leaves no empty workspace behind).
    """
    root = Path(root)
    key = root.resolve()
    if key in _held_locks:
        _held_locks[key] += 1
        try:
            yield
        finally:
            _held_locks[key] -= 1
        return
    if root.exists() and not root.is_dir():
        yield  # not a workspace: the command says so in its own words
        return
    made = [parent for parent in (root, *root.parents) if not parent.exists()]
    try:
        root.mkdir(parents=True, exist_ok=True)
        handle = _locked_file(root / LOCK_NAME, root)
    except BaseException:
        _remove_made(made)
        raise
    try:
        handle.truncate(0)
        handle.write(f"pid {os.getpid()}: {purpose} (since "
                     f"{datetime.now().isoformat(timespec='seconds')})\n")
        handle.flush()
        _held_locks[key] = 1
        _sweep_temporaries(root)
        yield
    finally:
        _held_locks.pop(key, None)
        with contextlib.suppress(OSError):
            (root / LOCK_NAME).unlink()
        handle.close()  # releases the flock
        _remove_made(made)


def _locked_file(path: Path, root: Path) -> Any:
    import errno
    import fcntl

    while True:
        try:
            handle = path.open("a+")
        except OSError as exc:
            if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
                raise UserError(
                    f"workspace {root} is not writable ({exc.strerror}); a step writes its "
                    f"outputs there: copy it to a writable folder (cp -r) and run there"
                ) from None
            if exc.errno == errno.ENOSPC:
                raise UserError(f"no space left on the device of {root}") from None
            raise
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "another process"
            handle.close()
            raise UserError(
                f"workspace {root} is in use by another mocap run ({holder}); wait for it "
                f"to finish: two runs writing one workspace would mix their outputs"
            ) from None
        # The holder before us may have removed the file on release after we opened it: then
        # we hold a lock on a name that no longer exists. Lock the file that is there.
        try:
            if os.stat(path).st_ino == os.fstat(handle.fileno()).st_ino:
                return handle
        except FileNotFoundError:
            pass
        handle.close()


_INPUT_FOLDERS = ("images", "videos")
_TEMPORARY = re.compile(r"\.partial(\.|-|$)|\.old$|^\.dense-")
"""Names of temporaries: :func:`partial_path` files and folders with SQLite's sidecars, the
old folder :func:`atomic_output` swaps out, the dense step's scratch folders."""


def _sweep_temporaries(root: Path) -> list[Path]:
    """Remove what killed runs left in the workspace (in it and its output folders, never in
    the input folders): with the lock held, no other run can be writing them."""
    folders = [root, *(p for p in root.iterdir()
                       if p.is_dir() and not p.is_symlink() and p.name not in _INPUT_FOLDERS)]
    swept = [p for folder in folders for p in folder.iterdir() if _TEMPORARY.search(p.name)]
    for path in swept:
        _remove(path)
    return swept


def _remove_made(made: list[Path]) -> None:
    """Remove the folders in ``made`` (deepest first) that are empty."""
    for folder in made:
        with contextlib.suppress(OSError):
            folder.rmdir()


@dataclass(frozen=True)
class StepRecord:
    name: str
    fingerprint: str
    """What later steps chain their fingerprints on: this step's settings and inputs, and the
    content signatures of what it wrote."""
    seconds: float
    config: dict[str, Any]
    summary: dict[str, Any]


class Workspace:
    """Paths, run record and image import of one workspace folder."""

    def __init__(self, root: Path | str):
        self.root = Path(root)

    # Paths -------------------------------------------------------------------------------
    @property
    def images_dir(self) -> Path:
        return self.root / "images"

    @property
    def database_path(self) -> Path:
        return self.root / "database.db"

    @property
    def sparse_dir(self) -> Path:
        return self.root / "sparse"

    @property
    def model_dir(self) -> Path:
        """The largest sparse model, ``sparse/0``."""
        return self.sparse_dir / "0"

    @property
    def undistorted_dir(self) -> Path:
        """COLMAP's undistorted layout (images/, sparse/) of the largest model."""
        return self.root / "dense" / "undistorted"

    @property
    def dense_cloud_path(self) -> Path:
        return self.root / "dense" / "fused.ply"

    @property
    def mesh_dir(self) -> Path:
        return self.root / "mesh"

    @property
    def body_dir(self) -> Path:
        """The fitted body model (`mocap fit`)."""
        return self.root / "body"

    # Video (tracking) workspaces ----------------------------------------------------------
    @property
    def cameras_path(self) -> Path:
        """Calibrated cameras of a video workspace (`tracking.rig.cameras` JSON)."""
        return self.root / "cameras.json"

    @property
    def videos_dir(self) -> Path:
        """Input videos ``<camera name>.<ext>`` (links or copies, never modified)."""
        return self.root / "videos"

    @property
    def silhouettes_dir(self) -> Path:
        """Foreground masks ``<camera name>/<frame:06d>.png`` (0 or 255), frame 0-based."""
        return self.root / "silhouettes"

    @property
    def gt_dir(self) -> Path:
        """Ground truth of synthetic sequences: joints.csv and pose.json."""
        return self.root / "gt"

    @property
    def tracks_dir(self) -> Path:
        """`mocap track` output: joints.csv, pose.json, motion.bvh."""
        return self.root / "tracks"

    @property
    def kind(self) -> str | None:
        """Which pipeline applies: ``"video"`` with cameras.json (`mocap init-video`, `mocap
        synth`), else ``"photo"`` with images/ (`mocap init`), else None (not a workspace)."""
        if self.cameras_path.is_file():
            return "video"
        if self.images_dir.is_dir():
            return "photo"
        return None

    def kind_mismatch(self, kind: str) -> str | None:
        """Why this is not a ``kind`` workspace, or None when it is one, or is no workspace at
        all (a step on it then fails with the workspace's own message)."""
        mine = self.kind
        if mine is None or mine == kind:
            return None
        sign = "it has cameras.json" if mine == "video" else "no cameras.json"
        return f"not a {kind} workspace ({sign})"

    @classmethod
    def open_video(cls, root: Path | str) -> Workspace:
        """An existing video workspace; a one-line error when the folder is not one."""
        ws = cls(root)
        if ws.kind != "video":
            raise UserError(
                f"{ws.root} is not a video workspace (no cameras.json); create one with: "
                f"mocap init-video {ws.root} --videos DIR --calibration FILE, or mocap synth"
            )
        return ws

    @property
    def logs_dir(self) -> Path:
        return self.root / "logs"

    @property
    def run_json(self) -> Path:
        return self.root / "run.json"

    def log_path(self, step: str) -> Path:
        self.logs_dir.mkdir(parents=True, exist_ok=True)
        return self.logs_dir / f"{step}.rrd"

    def recordings(self) -> list[Path]:
        return sorted(self.logs_dir.glob("*.rrd")) if self.logs_dir.is_dir() else []

    # Creation ----------------------------------------------------------------------------
    @classmethod
    def open(cls, root: Path | str) -> Workspace:
        """An existing workspace; a one-line error when the folder is not one."""
        ws = cls(root)
        if ws.root.exists() and not ws.root.is_dir():
            raise UserError(f"workspace path {ws.root} is a file, not a folder")
        if not ws.images_dir.is_dir():
            raise UserError(
                f"{ws.root} is not a workspace (no images/ folder); "
                f"create one with: mocap init {ws.root} --images DIR"
            )
        return ws

    @classmethod
    def create(
        cls, root: Path | str, images: Path | str, *, copy: bool = False, overwrite: bool = False
    ) -> tuple[Workspace, list[str]]:
        """Make a workspace from a folder of photos; returns it and notes on skipped files.

        Photos are hard-linked when source and workspace share a file system, else copied
        (``copy=True`` always copies). Sources are only read, never modified. Images are found
        recursively and keep their relative paths as COLMAP image names.
        """
        ws = cls(root)
        if ws.root.exists() and not ws.root.is_dir():
            raise UserError(f"workspace path {ws.root} is a file, not a folder")
        source = Path(images)
        # A workspace inside the photo folder must not import its own files on a re-run.
        inside = source.resolve().is_relative_to(ws.root.resolve())
        found, notes = scan_images(source, exclude=ws.images_dir if inside else ws.root)
        if ws.images_dir.exists():
            existing = ws.image_names()
            if existing == [name for name, _ in found] and not overwrite:
                return ws, [*notes, f"{ws.images_dir} already holds these images; reused"]
            if not overwrite:
                raise UserError(
                    f"{ws.images_dir} already holds other images; "
                    "use a new workspace or --overwrite"
                )
        ws.root.mkdir(parents=True, exist_ok=True)
        with atomic_output(ws.images_dir) as tmp:
            tmp.mkdir()
            for name, src in found:
                dst = tmp / name
                dst.parent.mkdir(parents=True, exist_ok=True)
                if copy:
                    shutil.copy2(src, dst)
                else:
                    try:
                        os.link(src, dst)
                    except OSError:
                        shutil.copy2(src, dst)
        # New images invalidate everything derived from the old ones.
        for stale in (ws.database_path, ws.sparse_dir, ws.root / "dense", ws.mesh_dir,
                      ws.run_json):
            _remove(stale)
        ws._write_run({"format": RUN_FORMAT, "source_images": str(source.resolve()), "steps": {}})
        return ws, notes

    def branch(self, root: Path | str, steps: tuple[str, ...]) -> Workspace:
        """A workspace that shares this one's images and starts from its finished ``steps``.

        The database is copied (a branch may rewrite cameras), the images are a symlink, and the
        run records of ``steps`` are copied so that fingerprints chain as if the branch had run
        them. Used to try alternatives (for example intrinsic initialisers) on the same matches.
        """
        branch = Workspace(root)
        branch.root.mkdir(parents=True, exist_ok=True)
        if not branch.images_dir.exists():
            os.symlink(os.path.relpath(self.images_dir.resolve(), branch.root.resolve()),
                       branch.images_dir)
        run = self.read_run()
        missing = [name for name in steps if self.step(name) is None]
        if missing:
            raise UserError(f"{self.root}: step(s) {', '.join(missing)} not run yet")
        records = {name: run["steps"][name] for name in steps}
        mine = branch.read_run()
        if any(mine.get("steps", {}).get(n) != records[n] or branch.step(n) is None
               for n in steps):
            with atomic_output(branch.database_path, seed_from=self.database_path):
                pass
            signed = {rel: run["outputs"][rel] for rec in records.values()
                      for rel in rec["outputs"]}
            branch._write_run({"format": RUN_FORMAT, "branch_of": str(self.root),
                               "steps": records, "outputs": signed})
        return branch

    def image_names(self) -> list[str]:
        """COLMAP image names (paths relative to images/, with forward slashes), sorted."""
        if not self.images_dir.is_dir():
            return []
        return sorted(
            p.relative_to(self.images_dir).as_posix()
            for p in self.images_dir.rglob("*")
            if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES
        )

    # Run record --------------------------------------------------------------------------
    def read_run(self) -> dict[str, Any]:
        if not self.run_json.exists():
            return {"format": RUN_FORMAT, "steps": {}}
        try:
            return json.loads(self.run_json.read_text())
        except json.JSONDecodeError as exc:
            raise UserError(
                f"{self.run_json} is not valid JSON ({exc}); delete it to rerun"
            ) from None

    def _write_run(self, run: dict[str, Any]) -> None:
        run["versions"] = dict(package_versions())
        run["updated"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
        write_json_atomic(self.run_json, run)

    def step(self, name: str) -> StepRecord | None:
        """The record of step ``name`` when its outputs are as it left them, else None.

        A record is trusted only while every output it lists has the content signature last
        recorded for it (:func:`output_signature`): a truncated, edited or deleted output makes
        the step count as not run, so it is recomputed and the steps after it too (issue 23).
        """
        run = self.read_run()
        rec = run.get("steps", {}).get(name)
        if rec is None or self._changed(run, rec):
            return None
        return StepRecord(name, rec["content"], rec["seconds"], rec["config"], rec["summary"])

    def require_step(self, name: str, missing: str, rerun: str) -> StepRecord:
        """The trusted record of step ``name``, else a one-line error: ``missing`` when it has
        not run, or which of its outputs changed since it wrote them and ``rerun`` to redo it."""
        if (record := self.step(name)) is not None:
            return record
        if changed := self.changed_outputs(name):
            what = ("was recorded by an older mocap" if changed == [self.run_json.name]
                    else f"changed since it wrote {', '.join(changed)}")
            raise UserError(f"{self.root}: the {name} step {what}; run `{rerun}` again")
        raise UserError(f"{self.root}: {missing}")

    def changed_outputs(self, name: str) -> list[str]:
        """The outputs of step ``name`` that differ from what it recorded (workspace-relative
        names; a record from before signatures lists ``run.json``), for messages."""
        run = self.read_run()
        rec = run.get("steps", {}).get(name)
        return [] if rec is None else self._changed(run, rec)

    def _changed(self, run: dict[str, Any], rec: dict[str, Any]) -> list[str]:
        if "content" not in rec:
            return [self.run_json.name]  # recorded before outputs were signed: recompute
        signed = run.get("outputs", {})
        return [rel for rel in rec["outputs"]
                if output_signature(self._resolve(rel)) != signed.get(rel)]

    def _relative(self, path: Path) -> str:
        path = Path(path)
        if not path.is_absolute():
            path = Path.cwd() / path
        root = self.root if self.root.is_absolute() else Path.cwd() / self.root
        try:
            return path.relative_to(root).as_posix()
        except ValueError:
            return str(path)

    def _resolve(self, rel: str) -> Path:
        return Path(rel) if Path(rel).is_absolute() else self.root / rel

    def is_done(self, name: str, step_fingerprint: str, *outputs: Path) -> bool:
        """Whether step ``name`` ran with this fingerprint and left ``outputs`` (every one of
        them signed by its record, and unchanged since)."""
        run = self.read_run()
        rec = run.get("steps", {}).get(name)
        return (
            rec is not None
            and rec["fingerprint"] == _versioned(name, step_fingerprint)
            and not self._changed(run, rec)
            and all(self._relative(p) in rec["outputs"] for p in outputs)
        )

    def reusable(self, name: str, step_fingerprint: str, *outputs: Path,
                 overwrite: bool = False) -> StepRecord | None:
        """The record of step ``name`` when its result can be reused as it is, else None."""
        if overwrite or not self.is_done(name, step_fingerprint, *outputs):
            return None
        return self.step(name)

    def record_step(
        self,
        name: str,
        step_fingerprint: str,
        *,
        outputs: Sequence[Path] = (),
        updated: Sequence[Path] = (),
        config: dict[str, Any],
        seconds: float,
        summary: dict[str, Any] | None = None,
    ) -> StepRecord:
        """Record a finished step: its fingerprint, settings, time, summary, and the content
        signature of each file or folder it wrote (which must exist).

        ``outputs`` were written anew, ``updated`` were changed in place (the COLMAP database,
        by matching and intrinsics). Other steps' records of the same files lose their content
        with them, so they are dropped: every other record of a new output, and the records of
        an updated one made after this step's previous record (they worked on the output this
        step has just replaced; none when it has none). The steps before it keep theirs: an
        update builds on them.
        """
        step_fingerprint = _versioned(name, step_fingerprint)
        run = self.read_run()
        steps = run.setdefault("steps", {})
        signed = run.setdefault("outputs", {})
        # An updating step run for the first time built on every record there is.
        previous = steps.get(name, {}).get("sequence", float("inf"))
        sequence = 1 + max((rec.get("sequence", -1) for rec in steps.values()), default=-1)
        names = []
        for path, fresh in [(p, True) for p in outputs] + [(p, False) for p in updated]:
            signature = output_signature(path)
            if signature is None:
                raise FileNotFoundError(f"step {name}: its output {path} does not exist")
            rel = self._relative(path)
            names.append(rel)
            signed[rel] = signature
            for other in [n for n, rec in steps.items() if n != name
                          and rel in rec.get("outputs", ())
                          and (fresh or rec.get("sequence", -1) > previous)]:
                del steps[other]
        # What the steps after it chain on: its settings and what it wrote, so that a step
        # recomputed to other content (COLMAP's matching is not deterministic) is not built on
        # by results of the old content.
        content = fingerprint(step_fingerprint, {rel: signed[rel] for rel in names})
        steps[name] = {
            "fingerprint": step_fingerprint,
            "content": content,
            "seconds": round(seconds, 3),
            "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "config": config,
            "summary": summary or {},
            "outputs": names,
            "sequence": sequence,
        }
        self._write_run(run)
        return StepRecord(name, content, seconds, config, summary or {})


class Timer:
    seconds: float = 0.0
    """The block's wall time once it has run (0 before)."""

    def __enter__(self) -> Timer:
        self.start = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.seconds = time.perf_counter() - self.start
