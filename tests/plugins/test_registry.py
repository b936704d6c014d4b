from __future__ import annotations

from dataclasses import dataclass

import pytest

import plugins
from plugins import registry
from plugins.options import OptionsError, parse_options
from plugins.protocols import FocalPrior, IntrinsicsContext, IntrinsicsResult
from tests.helpers import fake_entry_points


class GoodInitialiser:
    description = "a third-party initialiser"

    @dataclass(frozen=True, kw_only=True)
    class Options:
        scale: float = 1.0

    def __init__(self, options: Options):
        self.options = options

    def initialise(self, context: IntrinsicsContext) -> IntrinsicsResult:
        return IntrinsicsResult(
            priors=tuple(
                FocalPrior(camera_id=c.camera_id, focal_px=self.options.scale * c.width, source="x")
                for c in context.cameras
            )
        )


class NoMethod:
    description = "broken"

    @dataclass(frozen=True)
    class Options:
        pass


class HalfCommand:
    """A command whose `help` is not a string and which has no `run`."""

    help = None
    description = "half a command"

    def add_arguments(self, parser):
        pass


def _with_entry_points(monkeypatch: pytest.MonkeyPatch, **targets: str) -> None:
    """Pretend a third-party distribution declared these `mocap.intrinsics` entry points."""
    fake_entry_points(monkeypatch, "mocap.intrinsics", **targets)


def test_builtins_are_registered_through_entry_points():
    assert {"colmap-default", "exif", "fixed"} <= set(plugins.available("intrinsics"))
    for name in ("colmap-default", "exif", "fixed"):
        cls = registry.load("intrinsics", name)
        assert isinstance(cls.description, str) and cls.description


def test_third_party_plugin_loads_and_runs(monkeypatch):
    _with_entry_points(monkeypatch, good=f"{__name__}:GoodInitialiser")
    initialiser = plugins.create("intrinsics", "good", ["scale=2"])
    assert isinstance(initialiser, plugins.IntrinsicInitialiser)
    camera = plugins.CameraInfo(camera_id=3, model="PINHOLE", width=100, height=50, image_names=())
    result = initialiser.initialise(
        IntrinsicsContext(database_path=None, images_dir=None, cameras=(camera,))  # type: ignore[arg-type]
    )
    assert result.priors[0].focal_px == 200.0
    assert any(i.name == "good" for i in plugins.list_plugins())


def test_plugin_without_method_fails_loudly(monkeypatch):
    _with_entry_points(monkeypatch, broken=f"{__name__}:NoMethod")
    with pytest.raises(plugins.PluginError, match="has no `initialise` method"):
        plugins.create("intrinsics", "broken")
    listed = {i.name: i.description for i in plugins.list_plugins()}
    assert listed["broken"].startswith("BROKEN")


def test_plugin_that_cannot_import_fails_loudly(monkeypatch):
    _with_entry_points(monkeypatch, missing="no_such_module_xyz:Thing")
    with pytest.raises(plugins.PluginError, match="failed to import"):
        registry.load("intrinsics", "missing")


def test_unknown_plugin_names_the_alternatives():
    expected = r"available: colmap-default, exif, fixed, kruppa, kruppa-pp, view-graph$"
    with pytest.raises(plugins.PluginError, match=expected):
        plugins.create("intrinsics", "nope")


def test_fixed_needs_its_focal_and_parses_types():
    with pytest.raises(plugins.PluginError, match="missing option focal_px"):
        plugins.create("intrinsics", "fixed")
    with pytest.raises(plugins.PluginError, match="expected float"):
        plugins.create("intrinsics", "fixed", ["focal_px=abc"])
    with pytest.raises(plugins.PluginError, match="must be positive"):
        plugins.create("intrinsics", "fixed", ["focal_px=-5"])
    fixed = plugins.create("intrinsics", "fixed", ["focal_px=812.5", "refine=yes"])
    assert fixed.options.focal_px == 812.5 and fixed.options.refine is True


def test_options_reject_unknown_keys():
    @dataclass(frozen=True, kw_only=True)
    class Opts:
        a: int = 1

    assert parse_options(Opts, ["a=4"]).a == 4
    with pytest.raises(OptionsError, match="unknown option 'b'"):
        parse_options(Opts, ["b=1"])
    with pytest.raises(OptionsError, match="not key=value"):
        parse_options(Opts, ["a"])


def test_commands_and_batch_steps_are_plugins_without_options():
    commands = {"init", "sfm", "dense", "mesh", "run", "batch", "compare", "experiment", "view",
                "plugins", "body", "track", "fit", "report", "synth", "init-video",
                "silhouettes", "demo"}
    assert commands <= set(plugins.available("command"))
    assert {"sfm", "dense", "mesh", "silhouettes", "track"} <= set(plugins.available("step"))
    command = plugins.create("command", "sfm")
    assert isinstance(command, plugins.Command) and command.help
    step = plugins.create("step", "dense")
    assert isinstance(step, plugins.BatchStep)
    assert (step.workspace, step.follows) == ("photo", "sfm")
    with pytest.raises(plugins.PluginError, match="takes no options"):
        plugins.create("command", "plugins", ["x=1"])
    listed = {(i.kind, i.name): i for i in plugins.list_plugins()}
    assert listed["command", "init"].description == "make a workspace from a folder of photos"
    assert listed["step", "track"].options == ()


def test_a_command_that_does_not_satisfy_the_protocol_names_what_it_lacks(monkeypatch):
    fake_entry_points(monkeypatch, "mocap.commands", half=f"{__name__}:HalfCommand")
    with pytest.raises(plugins.PluginError, match=r"does not satisfy Command: it has no `help` "
                       r"string, has no `run` method"):
        registry.load("command", "half")
    loaded, broken = registry.load_all("command")
    assert "half" in broken and "sfm" in loaded


def test_a_name_declared_twice_breaks_only_that_name(monkeypatch):
    _with_entry_points(monkeypatch, fixed=f"{__name__}:GoodInitialiser")
    with pytest.raises(plugins.PluginError, match="'fixed' is declared twice"):
        registry.load("intrinsics", "fixed")
    assert registry.load("intrinsics", "exif").description
    listed = {i.name: i.description for i in plugins.list_plugins(("intrinsics",))}
    assert listed["fixed"].startswith("BROKEN") and not listed["exif"].startswith("BROKEN")
