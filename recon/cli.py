"""The `mocap` command: the top-level parser, command discovery and the one-line errors.

Every subcommand, recon's own included, is a plugin of kind ``command`` (entry-point group
``mocap.commands``, :class:`plugins.protocols.Command`), declared in ``pyproject.toml`` as a
third-party package declares its own: recon's in :mod:`recon.commands`. Only the invoked
command builds its flags (its ``add_arguments`` imports what it needs), so ``mocap --help``
lists every command from its ``help`` without importing the pipeline. A command that cannot be
loaded is listed as broken and, when invoked, fails with one line; the others still work.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

from recon.errors import UserError

if TYPE_CHECKING:
    from plugins.protocols import Command

_EPILOG = """examples:
  mocap demo                                  the three modules on generated data, vs truth
  mocap init ws/temple --images photos/       make a workspace from a folder of photos
  mocap sfm ws/temple                         sparse model in ws/temple/sparse/0
  mocap run ws/statue --images photos/        photos → sparse → dense → mesh (PLY/OBJ/GLB)
  mocap batch ws/* --scheduler tcp://HOST:8786   many workspaces as tasks on a Dask cluster
  mocap sfm ws/temple --intrinsics fixed -O focal_px=1520
  mocap compare ws/temple --gt photos/templeSR_par.txt   focal initialisers vs truth
  mocap experiment kruppa-noise               the thesis' noise experiment, table + plot
  mocap fit --cloud person.ply --out DIR      fit the body model to a point cloud
  mocap synth ws/walk --bvh clip.bvh          synthetic multi-camera silhouettes + ground truth
  mocap init-video ws/demo --videos videos/ --calibration Calib.qca.txt   a video workspace
  mocap silhouettes ws/demo                   foreground masks of every video frame
  mocap capture ws/lab --videos videos/ --calibration Calib.toml   videos → tracks → report
  mocap track ws/walk                         silhouette tracking → tracks/*.csv, .json, .bvh
  mocap report ws/walk                        joint angles, COM, joint loads → report/
  mocap view ws/temple                        open the recordings in the Rerun viewer
  mocap plugins                               list the registered plugins
"""


_BEFORE_COMMAND = ("-h", "--help", "--version")
"""Top-level flags that end the run before any command: the command after them is not built."""


def _command_name(argv: Sequence[str]) -> str | None:
    """The command ``argv`` names: its first word that is not a flag (no top-level flag takes
    a value), or None when there is none or a flag before it ends the run."""
    for arg in argv:
        if arg in _BEFORE_COMMAND:
            return None
        if not arg.startswith("-"):
            return arg
    return None


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def _load_commands() -> tuple[dict[str, type], dict[str, str]]:
    """Every registered command class by name, and why the broken ones are broken."""
    from plugins.registry import load_all

    commands, broken = load_all("command")
    return commands, {name: _one_line(exc) for name, exc in broken.items()}


def build_parser(
    argv: Sequence[str] = (),
) -> tuple[argparse.ArgumentParser, Command | None, str | None]:
    """The `mocap` parser with every command listed and only the one ``argv`` names built;
    returns it, that command (None if it names none) and, for a broken command, its error."""
    commands, broken = _load_commands()
    parser = argparse.ArgumentParser(
        prog="mocap",
        description="Markerless 3D human motion capture: photos → calibrated cameras → "
        "models → tracking, with Rerun recordings of every step.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=_version())
    parser.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="show COLMAP's own log lines (hidden unless they are errors)",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    parsers = {}
    for name in sorted({*commands, *broken}):
        if name in commands:
            cls = commands[name]
            parsers[name] = sub.add_parser(name, help=cls.help,
                                           description=cls.description or None)
        else:
            parsers[name] = sub.add_parser(name, help=f"BROKEN: {broken[name]}")
    name = _command_name(argv)
    if name in broken:
        return parser, None, broken[name]
    if name not in commands:
        return parser, None, None
    try:
        command = commands[name]()
        command.add_arguments(parsers[name])
    except Exception as exc:  # noqa: BLE001 - a third-party command's bug must not stop mocap
        return parser, None, (f"command plugin {name!r} cannot build its flags: "
                              f"{type(exc).__name__}: {_one_line(exc)}")
    return parser, command, None


def _version() -> str:
    from recon import __version__

    return f"mocap {__version__}"


def _quiet_colmap(verbose: bool) -> None:
    # glog levels: 0 INFO, 1 WARNING, 2 ERROR. COLMAP's warnings are about situations we report
    # ourselves in plain words, so only errors pass by default; errors we restate in our one
    # line (mapping's "Failed to create any sparse model") are held back at this level too, by
    # recon.sfm.pipeline._colmap_errors_restated.
    level = 0 if verbose else 2
    if "pycolmap" in sys.modules:
        sys.modules["pycolmap"].logging.minloglevel = level
    else:
        # glog reads its flags from the environment when pycolmap loads: a command that never
        # runs COLMAP (`mocap plugins`, `mocap report`) does not pay for importing it.
        os.environ["GLOG_minloglevel"] = str(level)  # noqa: SIM112 - glog's own spelling


def _workspace_lock(
    command: Command, args: argparse.Namespace
) -> contextlib.AbstractContextManager[None]:
    """The lock of the workspace a command writes (its ``WS`` argument), so that a second
    `mocap` run on it is refused in one line; none for commands that declare
    ``writes_workspace = False`` (`mocap view`) or take no workspace."""
    workspace = getattr(args, "workspace", None)
    if not isinstance(workspace, os.PathLike) or not getattr(command, "writes_workspace", True):
        return contextlib.nullcontext()
    from recon.workspace import workspace_lock

    return workspace_lock(workspace, f"mocap {args.command}")


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser, command, broken = build_parser(argv)
    if broken is not None:
        print(f"mocap {_command_name(argv)}: error: {broken}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    if command is None or args.command != _command_name(argv):  # argparse read argv otherwise
        parser.error(f"cannot tell the command from {' '.join(argv)!r}")
    _quiet_colmap(args.verbose)
    from plugins.registry import PluginError

    try:
        with _workspace_lock(command, args):
            command.run(args)
    except (UserError, PluginError) as exc:
        print(f"mocap {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            f"mocap {args.command}: interrupted; finished steps are kept, the unfinished "
            "one left no output",
            file=sys.stderr,
        )
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
