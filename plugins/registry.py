"""Load plugins from Python entry points, check them against their kind's Protocol, fail loudly.

Third-party packages add a plugin by declaring, in their own ``pyproject.toml``::

    [project.entry-points."mocap.intrinsics"]
    my-init = "my_package.module:MyInitialiser"

The ``mocap`` subcommands and the steps of ``mocap batch``, ours included, are plugins too
(groups ``mocap.commands`` and ``mocap.steps``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from plugins.options import OptionsError, describe_options, parse_options
from plugins.protocols import (
    BatchStep,
    BodyModelPlugin,
    Command,
    DenseBackend,
    IntrinsicInitialiser,
    MeshBackend,
    SilhouetteRenderer,
)


class PluginError(Exception):
    """A plugin is unknown, cannot be imported, or does not satisfy its kind's Protocol."""


@dataclass(frozen=True)
class PluginKind:
    name: str
    group: str
    protocol: type
    methods: tuple[str, ...]
    """Methods a plugin of this kind must have."""
    summary: str
    choose_flag: str | None = None
    """The CLI flag that picks a plugin of this kind."""
    option_flag: str | None = None
    """The CLI flag that passes options to this kind's plugins."""
    usage: str | None = None
    """How a plugin of a kind that no flag picks is used, for ``mocap plugins``."""
    attributes: tuple[tuple[str, type | tuple[type, ...]], ...] = (("description", str),)
    """Class attributes a plugin of this kind must have, and their types."""
    options: bool = True
    """Whether its plugins take an ``Options`` dataclass (else they are built with no
    arguments)."""
    line: str = "description"
    """The attribute that describes a plugin in one line."""

    def how_to_use(self) -> str:
        if self.choose_flag is None:
            return self.usage or ""
        return f"choose with {self.choose_flag} NAME; options with {self.option_flag} KEY=VALUE"


KINDS: dict[str, PluginKind] = {
    "intrinsics": PluginKind(
        name="intrinsics",
        group="mocap.intrinsics",
        protocol=IntrinsicInitialiser,
        methods=("initialise",),
        summary="intrinsic initialisers: set each camera's focal prior before mapping",
        choose_flag="--intrinsics",
        option_flag="-O",
    ),
    "dense": PluginKind(
        name="dense",
        group="mocap.dense",
        protocol=DenseBackend,
        methods=("densify",),
        summary="dense backends: undistorted images and poses → coloured point cloud",
        choose_flag="--dense",
        option_flag="--dense-option",
    ),
    "mesh": PluginKind(
        name="mesh",
        group="mocap.mesh",
        protocol=MeshBackend,
        methods=("mesh",),
        summary="mesh backends: oriented point cloud → triangle mesh with vertex colours",
        choose_flag="--mesher",
        option_flag="--mesh-option",
    ),
    "renderer": PluginKind(
        name="renderer",
        group="mocap.renderer",
        protocol=SilhouetteRenderer,
        methods=("render",),
        summary="silhouette renderers: posed body mesh + camera → boolean mask",
        choose_flag="--renderer",
        option_flag="--renderer-option",
    ),
    "body": PluginKind(
        name="body",
        group="mocap.body",
        protocol=BodyModelPlugin,
        methods=("posed",),
        summary="body models: a pose of the thesis' layout → posed surface mesh and joints",
        choose_flag="--body",
        option_flag="--body-option",
    ),
    "command": PluginKind(
        name="command",
        group="mocap.commands",
        protocol=Command,
        methods=("add_arguments", "run"),
        summary="commands: the subcommands of mocap",
        usage="run with mocap NAME; its flags with mocap NAME --help",
        attributes=(("help", str), ("description", str)),
        options=False,
        line="help",
    ),
    "step": PluginKind(
        name="step",
        group="mocap.steps",
        protocol=BatchStep,
        methods=("add_arguments", "settings", "run", "skip_reason", "fan_out", "figure"),
        summary="batch steps: one step of a workspace kind's pipeline, as mocap batch runs it",
        usage="run with mocap batch WS... --steps NAME,...; by default every step of each "
        "workspace's kind",
        attributes=(("description", str), ("workspace", str), ("follows", (str, type(None)))),
        options=False,
    ),
}


@dataclass(frozen=True)
class PluginInfo:
    kind: str
    name: str
    target: str
    """``module:attribute`` the entry point names."""
    distribution: str
    description: str
    options: tuple[tuple[str, str, str], ...]
    """(name, type and default, help) for each option."""


def _kind(kind: str) -> PluginKind:
    try:
        return KINDS[kind]
    except KeyError:
        raise PluginError(f"unknown plugin kind {kind!r}; kinds: {', '.join(KINDS)}") from None


def _entry_points(kind: str) -> tuple[dict[str, EntryPoint], dict[str, str]]:
    """The entry points of ``kind`` by name, and why some names cannot be loaded: two
    distributions declaring the same name is ambiguous, so that name is refused rather than
    one picked (the kind's other plugins still load)."""
    found: dict[str, EntryPoint] = {}
    clashes: dict[str, str] = {}
    for ep in entry_points(group=_kind(kind).group):
        if ep.name in found and found[ep.name].value != ep.value:
            clashes[ep.name] = (f"{kind} plugin {ep.name!r} is declared twice: "
                                f"{found[ep.name].value} and {ep.value}")
        found.setdefault(ep.name, ep)
    return found, clashes


def available(kind: str) -> list[str]:
    return sorted(_entry_points(kind)[0])


def _type_words(types: type | tuple[type, ...]) -> str:
    if types is str:
        return "string"
    names = [t.__name__ for t in (types if isinstance(types, tuple) else (types,))]
    return "of type " + " | ".join("None" if n == "NoneType" else n for n in names)


def load(kind: str, name: str) -> type:
    """The plugin class registered as ``name`` for ``kind``, checked against the Protocol."""
    eps, clashes = _entry_points(kind)
    if name not in eps:
        names = ", ".join(sorted(eps)) or "none registered"
        raise PluginError(f"unknown {kind} plugin {name!r}; available: {names}")
    return _load(kind, name, eps[name], clashes.get(name))


def load_all(kind: str) -> tuple[dict[str, type], dict[str, PluginError]]:
    """Every plugin class of ``kind`` by name (sorted), and the error of each broken one."""
    eps, clashes = _entry_points(kind)
    loaded: dict[str, type] = {}
    broken: dict[str, PluginError] = {}
    for name in sorted(eps):
        try:
            loaded[name] = _load(kind, name, eps[name], clashes.get(name))
        except PluginError as exc:
            broken[name] = exc
    return loaded, broken


def _load(kind: str, name: str, ep: EntryPoint, clash: str | None) -> type:
    spec = _kind(kind)
    if clash is not None:
        raise PluginError(clash)
    try:
        cls = ep.load()
    except Exception as exc:  # noqa: BLE001 - any import failure is the plugin's fault
        raise PluginError(f"{kind} plugin {name!r} ({ep.value}) failed to import: {exc}") from exc
    problems = []
    if not isinstance(cls, type):
        problems.append("is not a class")
    else:
        options = getattr(cls, "Options", None)
        if spec.options and (options is None or not dataclasses.is_dataclass(options)):
            problems.append("has no `Options` dataclass")
        for attribute, types in spec.attributes:
            if not hasattr(cls, attribute) or not isinstance(getattr(cls, attribute), types):
                problems.append(f"has no `{attribute}` {_type_words(types)}")
        problems += [f"has no `{m}` method" for m in spec.methods
                     if not callable(getattr(cls, m, None))]
    if problems:
        raise PluginError(
            f"{kind} plugin {name!r} ({ep.value}) does not satisfy "
            f"{spec.protocol.__name__}: it {', '.join(problems)}"
        )
    return cls


def create(kind: str, name: str, options: list[str] | tuple[str, ...] = ()) -> Any:
    """Instantiate a plugin with options given as ``key=value`` strings."""
    return instantiate(kind, name, load(kind, name), options)


def instantiate(kind: str, name: str, cls: type,
                options: list[str] | tuple[str, ...] = ()) -> Any:
    """An instance of the loaded plugin class ``cls`` (as :func:`create` makes it)."""
    spec = _kind(kind)
    if not spec.options:
        if options:
            raise PluginError(f"{kind} plugin {name!r} takes no options")
        instance = cls()
    else:
        try:
            parsed = parse_options(cls.Options, options)
        except OptionsError as exc:
            raise PluginError(f"{kind} plugin {name!r}: {exc}") from None
        instance = cls(parsed)
    if not isinstance(instance, spec.protocol):
        raise PluginError(f"{kind} plugin {name!r} does not satisfy its Protocol")
    return instance


def list_plugins(kinds: tuple[str, ...] | None = None) -> list[PluginInfo]:
    """Every registered plugin of every kind (or of ``kinds``). Import failures are reported,
    not raised."""
    infos = []
    for kind in kinds or tuple(KINDS):
        spec = _kind(kind)
        eps = _entry_points(kind)[0]
        loaded, broken = load_all(kind)
        for name, ep in sorted(eps.items()):
            dist = ep.dist.name if ep.dist is not None else "?"
            if name in broken:
                description, opts = f"BROKEN: {broken[name]}", ()
            else:
                cls = loaded[name]
                description = getattr(cls, spec.line)
                opts = describe_options(cls.Options) if spec.options else ()
            infos.append(PluginInfo(kind, name, ep.value, dist, description, opts))
    return infos
