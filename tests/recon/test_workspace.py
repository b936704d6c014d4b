from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import sqlite3
import stat
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from recon import workspace as workspace_module
from recon.errors import UserError
from recon.workspace import Workspace, atomic_output, file_digest, fingerprint


def _photos(folder: Path, count: int = 3, size: tuple[int, int] = (64, 48)) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    paths = []
    for i in range(count):
        path = folder / f"p{i}.png"
        Image.fromarray(rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)).save(path)
        paths.append(path)
    return paths


def _digest(path: Path) -> tuple[str, float]:
    return hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime


def test_create_links_images_and_never_touches_sources(tmp_path):
    src = tmp_path / "photos"
    photos = _photos(src)
    (src / "notes.txt").write_text("not an image")
    (src / "sub").mkdir()
    _photos(src / "sub", count=1)
    before = {p: _digest(p) for p in photos}

    ws, notes = Workspace.create(tmp_path / "ws", src)

    assert ws.image_names() == ["p0.png", "p1.png", "p2.png", "sub/p0.png"]
    assert any("notes.txt" in n for n in notes)
    # Same inode when hard-linked: nothing was re-encoded.
    assert os.path.samefile(ws.images_dir / "p0.png", src / "p0.png")
    assert {p: _digest(p) for p in photos} == before
    run = json.loads(ws.run_json.read_text())
    assert run["format"] == "mocap-workspace-v1" and "pycolmap" in run["versions"]


def test_create_again_with_same_images_reuses(tmp_path):
    src = tmp_path / "photos"
    _photos(src)
    ws, _ = Workspace.create(tmp_path / "ws", src)
    ws.database_path.write_bytes(b"db")
    ws.record_step("features", "abc", outputs=[ws.database_path], config={}, seconds=1.0)
    ws, notes = Workspace.create(tmp_path / "ws", src)
    assert any("reused" in n for n in notes)
    assert ws.step("features") is not None  # derived state kept


def test_workspace_inside_the_photo_folder_does_not_import_itself(tmp_path):
    src = tmp_path / "photos"
    _photos(src)
    Workspace.create(src / "ws", src)
    ws, _ = Workspace.create(src / "ws", src)
    assert ws.image_names() == ["p0.png", "p1.png", "p2.png"]


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        (lambda d: None, "no images in"),
        (lambda d: _photos(d, count=1), "only one image"),
        (lambda d: (_photos(d), (d / "bad.jpg").write_bytes(b"\xff\xd8garbage")), "bad.jpg"),
    ],
)
def test_bad_folders_raise_one_line_errors(tmp_path, setup, message):
    src = tmp_path / "photos"
    src.mkdir()
    setup(src)
    with pytest.raises(UserError, match=message) as info:
        Workspace.create(tmp_path / "ws", src)
    assert "\n" not in str(info.value)
    assert not (tmp_path / "ws" / "images").exists()


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
def test_truncated_image_is_reported(tmp_path, suffix):
    src = tmp_path / "photos"
    photos = _photos(src, size=(256, 256))
    cut = src / f"cut{suffix}"
    Image.open(photos[0]).save(cut)
    data = cut.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(UserError, match=cut.name):
        Workspace.create(tmp_path / "ws", src)


def test_workspace_path_that_is_a_file(tmp_path):
    src = tmp_path / "photos"
    _photos(src)
    (tmp_path / "ws").write_text("x")
    with pytest.raises(UserError, match="is a file"):
        Workspace.create(tmp_path / "ws", src)
    with pytest.raises(UserError, match="is a file"):
        Workspace.open(tmp_path / "ws")


def test_open_requires_a_workspace(tmp_path):
    with pytest.raises(UserError, match="not a workspace"):
        Workspace.open(tmp_path)


def test_atomic_output_keeps_the_old_file_when_the_step_fails(tmp_path):
    target = tmp_path / "model"
    target.mkdir()
    (target / "cameras.bin").write_text("old")
    with pytest.raises(RuntimeError), atomic_output(target) as tmp:
        tmp.mkdir()
        (tmp / "cameras.bin").write_text("half")
        raise RuntimeError("interrupted")
    assert (target / "cameras.bin").read_text() == "old"
    assert not (tmp_path / "model.partial").exists()
    with atomic_output(target) as tmp:
        tmp.mkdir()
        (tmp / "cameras.bin").write_text("new")
    assert (target / "cameras.bin").read_text() == "new"


@pytest.fixture
def umask_022():
    """The usual umask, whatever the test runner's is (restored after)."""
    old = os.umask(0o022)
    yield
    os.umask(old)


def test_atomic_output_gives_every_output_the_mode_of_a_new_file(tmp_path, umask_022):
    """A writer that creates its file through tempfile (0600) or a folder through mkdtemp
    (0700) still delivers the mode open()/mkdir() give: 0644 / 0755 under umask 022."""
    plain, private, folder = tmp_path / "a.txt", tmp_path / "b.bvh", tmp_path / "model"
    with atomic_output(plain) as tmp:
        tmp.write_text("plain")
    with atomic_output(private) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)  # as mkstemp does
        os.write(fd, b"private")
        os.close(fd)
    with atomic_output(folder) as tmp:
        tmp.mkdir(mode=0o700)
        (tmp / "sub").mkdir(mode=0o700)
        (tmp / "sub" / "points.bin").write_bytes(b"x")
        os.chmod(tmp / "sub" / "points.bin", 0o600)
    modes = {p.relative_to(tmp_path).as_posix(): stat.S_IMODE(p.stat().st_mode)
             for p in (plain, private, folder, folder / "sub", folder / "sub" / "points.bin")}
    assert modes == {"a.txt": 0o644, "b.bvh": 0o644, "model": 0o755, "model/sub": 0o755,
                     "model/sub/points.bin": 0o644}


def test_atomic_output_leaves_linked_sources_modes_alone(tmp_path, umask_022):
    """A folder output that hard-links its sources (WS/images, WS/videos) must not chmod them:
    a hard link shares its mode with the user's own file."""
    source = tmp_path / "photo.jpg"
    source.write_bytes(b"jpeg")
    os.chmod(source, 0o600)
    with atomic_output(tmp_path / "images") as tmp:
        tmp.mkdir()
        os.link(source, tmp / "photo.jpg")
        os.symlink(source, tmp / "alias.jpg")
    assert stat.S_IMODE(source.stat().st_mode) == 0o600
    assert stat.S_IMODE((tmp_path / "images").stat().st_mode) == 0o755


def test_atomic_output_modes_respect_a_stricter_umask(tmp_path):
    old = os.umask(0o077)
    try:
        with atomic_output(tmp_path / "a.txt") as tmp:
            tmp.write_text("plain")
            os.chmod(tmp, 0o666)
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o600


def test_file_digest_is_the_content_hash_read_in_chunks(tmp_path):
    # 2.5 MiB: more than one read of the streaming loop.
    content = np.random.default_rng(0).integers(0, 256, 5 << 19, dtype=np.uint8).tobytes()
    path = tmp_path / "video.bin"
    path.write_bytes(content)
    assert file_digest(path) == hashlib.sha256(content).hexdigest()[:16]
    assert len(file_digest(path)) == len(fingerprint("x"))
    path.write_bytes(content[:-1] + bytes([content[-1] ^ 1]))
    assert file_digest(path) != hashlib.sha256(content).hexdigest()[:16]


def test_steps_are_done_only_with_matching_fingerprint_and_outputs(tmp_path):
    ws = Workspace(tmp_path)
    out = tmp_path / "out.txt"
    fp = fingerprint("step", {"a": 1})
    assert fp == fingerprint("step", {"a": 1}) != fingerprint("step", {"a": 2})
    with pytest.raises(FileNotFoundError):  # a step cannot record an output it did not write
        ws.record_step("step", fp, outputs=[out], config={"a": 1}, seconds=0.5)
    out.write_text("x")
    ws.record_step("step", fp, outputs=[out], config={"a": 1}, seconds=0.5, summary={"n": 3})
    assert ws.is_done("step", fp, out)
    assert not ws.is_done("step", fingerprint("step", {"a": 2}), out)
    assert not ws.is_done("step", fp, out, tmp_path / "other.txt")  # not an output it signed
    assert ws.step("step").summary == {"n": 3}
    out.unlink()
    assert not ws.is_done("step", fp, out) and ws.step("step") is None


def test_a_damaged_output_is_not_trusted_and_a_copied_workspace_is(tmp_path):
    """Issue 23, point 3: reuse checked only that a file existed, so a truncated fused.ply was
    meshed and 'reused'. Each output's content signature is recorded; a truncated, appended or
    edited file, or a file deleted from an output folder, makes the step count as not run. A
    copy of the workspace (new mtimes and inodes) keeps its steps."""
    ws = Workspace(tmp_path / "ws")
    cloud = ws.dense_cloud_path
    cloud.parent.mkdir(parents=True)
    cloud.write_bytes(bytes(range(256)) * 20000)  # 5 MB: signed by its ends and size
    model = ws.model_dir
    model.mkdir(parents=True)
    for name in ("cameras.bin", "images.bin"):
        (model / name).write_bytes(name.encode() * 100)
    ws.record_step("mapping", "m", outputs=[model], config={}, seconds=0.1)
    ws.record_step("dense", "d", outputs=[cloud], config={}, seconds=0.1)
    assert ws.step("dense") and ws.step("mapping")

    copy = Workspace(tmp_path / "copy")
    shutil.copytree(ws.root, copy.root)  # copy2 keeps mtimes: touch them too
    for path in copy.root.rglob("*"):
        os.utime(path, (1, 1))
    assert copy.reusable("dense", "d", copy.dense_cloud_path) is not None
    assert copy.reusable("mapping", "m", copy.model_dir) is not None

    with cloud.open("r+b") as handle:
        handle.truncate(5_000_000 - 1)
    assert ws.step("dense") is None and ws.reusable("dense", "d", cloud) is None
    assert ws.changed_outputs("dense") == ["dense/fused.ply"]
    (model / "images.bin").unlink()
    assert ws.step("mapping") is None
    assert copy.step("dense") and copy.step("mapping")  # the copy is its own


def test_a_later_step_rewriting_a_shared_output_keeps_the_earlier_trusted(tmp_path):
    """The database is the output of features, matches and intrinsics in turn: each record
    trusts the signature the last writer left, so matches do not untrust features, while a
    change behind every step's back untrusts all of them."""
    ws = Workspace(tmp_path)
    ws.database_path.write_bytes(b"features")
    ws.record_step("features", "f", outputs=[ws.database_path], config={}, seconds=0.1)
    ws.database_path.write_bytes(b"features+matches")
    ws.record_step("matches", "m", updated=[ws.database_path], config={}, seconds=0.1)
    ws.database_path.write_bytes(b"features+matches+intrinsics")
    ws.record_step("intrinsics", "i", updated=[ws.database_path], config={}, seconds=0.1)
    assert ws.step("features") and ws.step("matches") and ws.step("intrinsics")
    ws.database_path.write_bytes(b"damaged")
    assert not (ws.step("features") or ws.step("matches") or ws.step("intrinsics"))


def test_a_step_that_rewrites_a_shared_output_drops_the_records_built_on_it(tmp_path):
    """Issue 23: after a damaged database, features recomputed a fresh one and matching was
    'reused' with no matches in it. A step that writes a file anew drops the other records of
    it; one that updates it in place drops those made after its own previous record."""
    ws = Workspace(tmp_path)
    db = ws.database_path
    db.write_bytes(b"f")
    ws.record_step("features", "f", outputs=[db], config={}, seconds=0.1)
    db.write_bytes(b"fm")
    ws.record_step("matches", "m", updated=[db], config={}, seconds=0.1)
    db.write_bytes(b"fmi")
    ws.record_step("intrinsics", "i", updated=[db], config={}, seconds=0.1)
    db.write_bytes(b"fm2")  # matching again (another matcher): intrinsics worked on the old
    ws.record_step("matches", "m2", updated=[db], config={}, seconds=0.1)
    assert ws.step("features") and ws.step("matches") and ws.step("intrinsics") is None
    db.write_bytes(b"f2")  # features anew: nothing built on the old database survives
    ws.record_step("features", "f", outputs=[db], config={}, seconds=0.1)
    assert ws.step("features") and ws.step("matches") is None
    assert not ws.is_done("matches", "m2", db)


def test_a_record_from_before_signatures_is_recomputed(tmp_path):
    ws = Workspace(tmp_path)
    (tmp_path / "out.txt").write_text("x")
    ws.record_step("step", "fp", outputs=[tmp_path / "out.txt"], config={}, seconds=0.1)
    run = json.loads(ws.run_json.read_text())
    del run["steps"]["step"]["content"], run["steps"]["step"]["outputs"]
    ws.run_json.write_text(json.dumps(run))
    assert ws.step("step") is None and not ws.is_done("step", "fp", tmp_path / "out.txt")


def test_a_new_step_version_is_not_reused_and_changes_what_follows(tmp_path, monkeypatch):
    """A step whose code changed its outputs for the same settings (STEP_VERSIONS) recomputes
    them in an old workspace, and the steps after it see another upstream fingerprint."""
    ws = Workspace(tmp_path)
    out = tmp_path / "out.txt"
    out.write_text("x")
    fp = fingerprint("step", {"a": 1})
    ws.record_step("step", fp, outputs=[out], config={}, seconds=0.1)
    old_upstream = ws.step("step").fingerprint
    assert ws.is_done("step", fp, out)
    monkeypatch.setitem(workspace_module.STEP_VERSIONS, "step", 2)
    assert not ws.is_done("step", fp, out) and ws.reusable("step", fp, out) is None
    ws.record_step("step", fp, outputs=[out], config={}, seconds=0.1)
    assert ws.is_done("step", fp, out) and ws.step("step").fingerprint != old_upstream


def _rows(path: Path) -> int:
    with contextlib.closing(sqlite3.connect(path)) as db:
        return db.execute("SELECT COUNT(*) FROM t").fetchone()[0]


def _database_with_stale_wal(tmp_path: Path) -> tuple[Path, Path]:
    """database.db (3 rows, WAL mode) and, beside its partial copy, the write-ahead log of a run
    that was killed after writing 100 rows into that copy (the copy itself removed, as
    `atomic_output` removed it)."""
    target = tmp_path / "database.db"
    with contextlib.closing(sqlite3.connect(target)) as db:
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("CREATE TABLE t (x INTEGER)")
        db.executemany("INSERT INTO t VALUES (?)", [(i,) for i in range(3)])
        db.commit()
    partial = tmp_path / "database.partial.db"
    shutil.copy2(target, partial)
    stash = tmp_path / "stale-wal"
    with contextlib.closing(sqlite3.connect(partial)) as db:
        db.execute("PRAGMA wal_autocheckpoint=0")
        db.executemany("INSERT INTO t VALUES (?)", [(i,) for i in range(100)])
        db.commit()
        shutil.copy2(partial.with_name(partial.name + "-wal"), stash)
    partial.unlink()
    os.replace(stash, partial.with_name(partial.name + "-wal"))
    return target, partial


def test_a_killed_runs_write_ahead_log_never_reaches_the_next_copy(tmp_path):
    target, partial = _database_with_stale_wal(tmp_path)
    # What SQLite does with it when nothing removes it: the stale rows come back.
    shutil.copy2(target, tmp_path / "copy.db")
    shutil.copy2(partial.with_name(partial.name + "-wal"), tmp_path / "copy.db-wal")
    assert _rows(tmp_path / "copy.db") == 103
    with atomic_output(target, seed_from=target) as db:
        assert _rows(db) == 3
        with contextlib.closing(sqlite3.connect(db)) as conn:
            conn.execute("INSERT INTO t VALUES (7)")
            conn.commit()
    assert _rows(target) == 4
    assert not any(p.name.startswith("database.partial") for p in tmp_path.iterdir())
