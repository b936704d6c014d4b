"""Bad input through the real `mocap` command: exit code 2, one line naming the cause."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from recon.cli import main
from recon.errors import UserError
from tests.helpers import ROOT, fake_entry_points, run_cli


def _assert_one_line_error(result, *needles: str) -> None:
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    error = [line for line in lines if "error:" in line]
    assert len(error) == 1, result.stderr
    for needle in needles:
        assert needle in error[0], error[0]


def _noise_images(folder, count, size=(160, 120), seed=0):
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for i in range(count):
        pixels = rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)
        Image.fromarray(pixels).save(folder / f"img{i}.png")


def test_empty_folder(tmp_path):
    (tmp_path / "photos").mkdir()
    _assert_one_line_error(run_cli("init", tmp_path / "ws", "--images", tmp_path / "photos"),
                           "no images in")


def test_missing_folder(tmp_path):
    _assert_one_line_error(run_cli("init", tmp_path / "ws", "--images", tmp_path / "nope"),
                           "does not exist")


def test_corrupt_image_is_named_and_sources_untouched(tmp_path):
    photos = tmp_path / "photos"
    _noise_images(photos, 2)
    (photos / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0 this is not a jpeg")
    before = sorted((p.name, p.read_bytes()) for p in photos.iterdir())
    _assert_one_line_error(run_cli("sfm", tmp_path / "ws", "--images", photos), "broken.jpg")
    assert sorted((p.name, p.read_bytes()) for p in photos.iterdir()) == before


def test_single_image(tmp_path):
    _noise_images(tmp_path / "photos", 1)
    _assert_one_line_error(run_cli("init", tmp_path / "ws", "--images", tmp_path / "photos"),
                           "at least 2")


def test_workspace_is_a_file(tmp_path):
    _noise_images(tmp_path / "photos", 2)
    (tmp_path / "ws").write_text("")
    _assert_one_line_error(run_cli("init", tmp_path / "ws", "--images", tmp_path / "photos"),
                           "is a file")
    _assert_one_line_error(run_cli("sfm", tmp_path / "ws"), "is a file")


def test_sfm_on_a_folder_that_is_not_a_workspace(tmp_path):
    _assert_one_line_error(run_cli("sfm", tmp_path), "not a workspace")


def test_photos_that_do_not_overlap(tmp_path):
    """Unrelated noise images: nothing to register, and no model is left behind."""
    _noise_images(tmp_path / "photos", 3)
    result = run_cli("sfm", tmp_path / "ws", "--images", tmp_path / "photos")
    _assert_one_line_error(result, "registered no images")
    assert not (tmp_path / "ws" / "sparse").exists()


def test_unknown_plugin_and_bad_option(tmp_path):
    _noise_images(tmp_path / "photos", 2)
    run_cli("init", tmp_path / "ws", "--images", tmp_path / "photos")
    _assert_one_line_error(run_cli("sfm", tmp_path / "ws", "--intrinsics", "nope"),
                           "unknown intrinsics plugin 'nope'")
    _assert_one_line_error(run_cli("sfm", tmp_path / "ws", "--intrinsics", "fixed"),
                           "focal_px")


def test_sfm_options_colmap_would_abort_on_are_refused_first(tmp_path):
    _noise_images(tmp_path / "photos", 2)
    run_cli("init", tmp_path / "ws", "--images", tmp_path / "photos")
    for flags, message in ((("--matcher", "sequential", "--sequential-overlap", "0"),
                            "--sequential-overlap 0"),
                           (("--max-num-features", "0"), "--max-num-features 0"),
                           (("--max-num-features", "-1"), "--max-num-features -1")):
        _assert_one_line_error(run_cli("sfm", tmp_path / "ws", *flags), message)
    assert not (tmp_path / "ws" / "database.db").exists()  # COLMAP never ran


def test_plugins_lists_every_kind():
    result = run_cli("plugins")
    assert result.returncode == 0
    for name in ("intrinsics", "colmap-default", "exif", "fixed", "kruppa", "view-graph",
                 "dense", "cpu-stereo", "colmap-patchmatch", "mesh", "poisson", "ball-pivoting"):
        assert name in result.stdout


def test_view_without_display_prints_the_command(tmp_path):
    _noise_images(tmp_path / "photos", 2)
    run_cli("init", tmp_path / "ws", "--images", tmp_path / "photos")
    _assert_one_line_error(run_cli("view", tmp_path / "ws"), "no recordings")
    (tmp_path / "ws" / "logs").mkdir()
    (tmp_path / "ws" / "logs" / "sfm.rrd").write_bytes(b"")
    result = run_cli("view", tmp_path / "ws")
    assert result.returncode == 0
    assert "rerun" in result.stdout and "sfm.rrd" in result.stdout
    # The viewer's server on this machine only, unless asked (issue 21: rerun binds 0.0.0.0).
    commands = [line for line in result.stdout.splitlines() if "sfm.rrd" in line]
    assert len(commands) == 2 and all("--bind 127.0.0.1 " in line for line in commands)
    result = run_cli("view", tmp_path / "ws", "--bind", "0.0.0.0")
    assert result.returncode == 0 and "--bind 0.0.0.0 " in result.stdout
    _assert_one_line_error(run_cli("view", tmp_path / "ws", "--bind", "localhost:80"),
                           "--bind localhost:80: not an IP address")


def test_dense_and_mesh_need_their_inputs(tmp_path):
    _noise_images(tmp_path / "photos", 2)
    run_cli("init", tmp_path / "ws", "--images", tmp_path / "photos")
    _assert_one_line_error(run_cli("dense", tmp_path / "ws"), "no sparse model yet")
    _assert_one_line_error(run_cli("mesh", tmp_path / "ws"), "no dense cloud yet")


def test_colmap_patchmatch_without_cuda_names_the_cpu_backend():
    import pycolmap

    from recon.dense.backends import ColmapPatchMatchBackend
    from recon.errors import UserError

    if pycolmap.has_cuda:
        pytest.skip("this pycolmap has CUDA; the backend runs instead of refusing")
    backend = ColmapPatchMatchBackend(ColmapPatchMatchBackend.Options())
    with pytest.raises(UserError, match="use --dense cpu-stereo"):
        backend.densify(None)  # type: ignore[arg-type]


@pytest.mark.skipif(
    not __import__("pycolmap").has_cuda,
    reason="colmap-patchmatch needs pycolmap built with CUDA; this machine's has none",
)
def test_colmap_patchmatch_with_cuda(tmp_path):  # pragma: no cover - runs on CUDA machines
    out = tmp_path / "demo"
    assert run_cli("demo", "--out", out, "--num-views", "8", "--no-mesh").returncode == 0
    result = run_cli("dense", out, "--dense", "colmap-patchmatch")
    assert result.returncode == 0, result.stderr
    assert (out / "dense" / "fused.ply").stat().st_size > 10_000


# Commands are plugins --------------------------------------------------------------------------
class HelloCommand:
    """A third-party command, declared through a (faked) entry point."""

    help = "say hello"
    description = "Say hello to --name; --fail makes it a one-line error."

    def add_arguments(self, parser):
        parser.add_argument("--name", default="world")
        parser.add_argument("--fail", action="store_true")

    def run(self, args):
        if args.fail:
            raise UserError(f"{args.name} is not here")
        print(f"hello {args.name}")


class NoRunCommand:
    help = "cannot run"
    description = ""

    def add_arguments(self, parser):
        pass


class BadFlagsCommand(HelloCommand):
    def add_arguments(self, parser):
        raise RuntimeError("flags\nbroken")


def _fake_commands(monkeypatch):
    fake_entry_points(monkeypatch, "mocap.commands", hello=f"{__name__}:HelloCommand",
                      norun=f"{__name__}:NoRunCommand", gone="no_such_module_xyz:Gone",
                      badflags=f"{__name__}:BadFlagsCommand")


def test_a_third_party_command_runs_like_ours(monkeypatch, capsys):
    _fake_commands(monkeypatch)
    assert main(["hello", "--name", "you"]) == 0
    assert capsys.readouterr().out == "hello you\n"
    assert main(["-v", "hello", "--fail"]) == 2
    assert capsys.readouterr().err == "mocap hello: error: world is not here\n"


def test_broken_commands_are_listed_and_fail_in_one_line(monkeypatch, capsys):
    _fake_commands(monkeypatch)
    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    listing = capsys.readouterr().out
    assert "hello        say hello" in listing and "sfm          sparse" in listing
    for name in ("norun", "gone"):
        line = next(line for line in listing.splitlines() if line.strip().startswith(name))
        assert "BROKEN: command plugin" in line, listing
    for args, needle in ((["gone", "--anything"], "'gone' (no_such_module_xyz:Gone) failed to "
                          "import"),
                         (["norun"], "has no `run` method"),
                         (["badflags"], "cannot build its flags: RuntimeError: flags broken")):
        assert main(args) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        assert captured.err.startswith(f"mocap {args[0]}: error: command plugin")
        assert needle in captured.err and len(captured.err.splitlines()) == 1, captured.err
    # The others still work, and `mocap plugins` says which are broken.
    with pytest.raises(SystemExit):
        main(["sfm", "--help"])
    assert "--max-num-features" in capsys.readouterr().out
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "command (mocap.commands)" in out and "step (mocap.steps)" in out
    assert "  gone               BROKEN: command plugin 'gone'" in out
    assert "  hello              say hello" in out


_IMPORTED = """
import json, sys
from recon.cli import main
try:
    main(sys.argv[2:])
except SystemExit:
    pass
with open(sys.argv[1], "w") as out:
    json.dump(sorted(sys.modules), out)
"""

HEAVY = ("numba", "open3d", "pymeshlab", "rerun", "distributed", "scipy", "matplotlib")
"""Libraries that take a large part of a second to import, which listing commands and plugins
must not load."""


def _imported(tmp_path, *args: str) -> set[str]:
    out = tmp_path / "modules.json"
    subprocess.run([sys.executable, "-c", _IMPORTED, out, *args], cwd=ROOT, check=True,
                   capture_output=True)
    return set(json.loads(out.read_text()))


@pytest.mark.parametrize("args", [("--help",), ("plugins",)])
def test_listing_commands_and_plugins_imports_no_pipeline(args, tmp_path):
    """`mocap --help` imports the command modules only; `mocap plugins` the plugin modules too,
    which keep numba, Open3D, pycolmap and the tracker inside their functions."""
    modules = _imported(tmp_path, *args)
    loaded = sorted(m for m in modules if m.split(".")[0] in (*HEAVY, "pycolmap"))
    assert not loaded, loaded
    tracking = {m for m in modules if m.split(".")[0] == "tracking"}
    if args == ("--help",):
        assert "numpy" not in modules
        assert tracking == {"tracking", "tracking.commands"}
    else:
        plugin_modules = {"tracking", "tracking.commands", "tracking.batch_steps",
                          "tracking.track", "tracking.track.render", "tracking.rig",
                          "tracking.rig.cameras", "tracking.body", "tracking.body.plugins",
                          "tracking.body.mpfb", "tracking.body.mpfb.plugin"}
        assert tracking <= plugin_modules, sorted(tracking - plugin_modules)
        assert "tracking.track.render" in tracking  # the renderers were described

