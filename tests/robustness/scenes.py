"""Small inputs for the robustness suite, made once per test session and copied per case.

Six 320x240 photos of the synthetic room (:mod:`recon.evaluation.synthetic_room`; no download),
and workspaces of them after `mocap sfm`, `mocap dense` and `mocap mesh`, built through the
library with its defaults. Each case gets its own copy, so a case may damage it at will.
"""

from __future__ import annotations

import atexit
import functools
import shutil
import tempfile
from pathlib import Path


@functools.cache
def cache_folder() -> Path:
    """This session's folder for inputs built once (removed at exit)."""
    folder = Path(tempfile.mkdtemp(prefix="mocap-robustness-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return folder


@functools.cache
def _photos() -> Path:
    from recon.evaluation.synthetic_room import SyntheticSceneConfig, render_scene, write_scene

    out = cache_folder() / "photos"
    scene = render_scene(SyntheticSceneConfig(num_views=6, width=320, height=240,
                                              supersample=1))
    write_scene(scene, out, cache_folder() / "truth.txt")
    return out


@functools.cache
def built_workspace(stage: str) -> Path:
    """The session's own workspace after ``stage`` (read it, never change it: copy it with
    :func:`workspace`)."""
    from recon.dense.step import DenseConfig, densify
    from recon.mesh.step import MeshConfig, make_mesh
    from recon.sfm.pipeline import SfMConfig, run_sfm
    from recon.workspace import Workspace

    root = cache_folder() / f"ws-{stage}"
    if stage == "init":
        Workspace.create(root, _photos(), copy=True)
        return root
    shutil.copytree(built_workspace({"sfm": "init", "dense": "sfm", "mesh": "dense"}[stage]), root,
                    symlinks=True)
    ws = Workspace(root)
    if stage == "sfm":
        run_sfm(ws, SfMConfig())
    elif stage == "dense":
        densify(ws, DenseConfig())
    else:
        make_mesh(ws, MeshConfig())
    return root


def photos(folder: Path) -> Path:
    """A copy of the six photos in ``folder/photos``."""
    target = folder / "photos"
    shutil.copytree(_photos(), target)
    return target


def workspace(folder: Path, stage: str = "sfm") -> Path:
    """A copy in ``folder/ws`` of the photos' workspace after ``stage`` (init, sfm, dense or
    mesh; each includes the ones before it)."""
    target = folder / "ws"
    shutil.copytree(built_workspace(stage), target, symlinks=True)
    return target
