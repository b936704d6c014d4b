"""Load plugins from Python entry points, check them against their kind's Protocol, fail loudly.

Third-party packages add a plugin by declaring, in their own ``pyproject.toml``::

    [project.entry-points."mocap.intrinsics"]
    my-init = "my_package.module:MyInitialiser"
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from plugins.options import OptionsError, describe_options, parse_options
from plugins.protocols import DenseBackend, IntrinsicInitialiser, MeshBackend, SilhouetteRenderer


class PluginError(Exception):
    """A plugin is unknown, cannot be imported, or does not satisfy its kind's Protocol."""


@dataclass(frozen=True)
class PluginKind:
    name: str
    group: str
    protocol: type
    method: str
    summary: str
    choose_flag: str
    """The CLI flag that picks a plugin of this kind."""
    option_flag: str
    """The CLI flag that passes options to this kind's plugins."""


KINDS: dict[str, PluginKind] = {
    "intrinsics": PluginKind(
        name="intrinsics",
        group="mocap.intrinsics",
        protocol=IntrinsicInitialiser,
        method="initialise",
        summary="intrinsic initialisers: set each camera's focal prior before mapping",
        choose_flag="--intrinsics",
        option_flag="-O",
    ),
    "dense": PluginKind(
        name="dense",
        group="mocap.dense",
        protocol=DenseBackend,
        method="densify",
        summary="dense backends: undistorted images and poses → coloured point cloud",
        choose_flag="--dense",
        option_flag="--dense-option",
    ),
    "mesh": PluginKind(
        name="mesh",
        group="mocap.mesh",
        protocol=MeshBackend,
        method="mesh",
        summary="mesh backends: oriented point cloud → triangle mesh with vertex colours",
        choose_flag="--mesher",
        option_flag="--mesh-option",
    ),
    "renderer": PluginKind(
        name="renderer",
        group="mocap.renderer",
        protocol=SilhouetteRenderer,
        method="render",
        summary="silhouette renderers: posed body mesh + camera → boolean mask",
        choose_flag="--renderer",
        option_flag="--renderer-option",
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


def _entry_points(kind: str) -> dict[str, EntryPoint]:
    found: dict[str, EntryPoint] = {}
    for ep in entry_points(group=_kind(kind).group):
        # Two distributions declaring the same name is ambiguous: refuse rather than pick one.
        if ep.name in found and found[ep.name].value != ep.value:
            raise PluginError(
                f"{kind} plugin {ep.name!r} is declared twice: "
                f"{found[ep.name].value} and {ep.value}"
            )
        found[ep.name] = ep
    return found


def available(kind: str) -> list[str]:
    return sorted(_entry_points(kind))


def load(kind: str, name: str) -> type:
    """The plugin class registered as ``name`` for ``kind``, checked against the Protocol."""
    spec = _kind(kind)
    eps = _entry_points(kind)
    if name not in eps:
        names = ", ".join(sorted(eps)) or "none registered"
        raise PluginError(f"unknown {kind} plugin {name!r}; available: {names}")
    try:
        cls = eps[name].load()
    except Exception as exc:  # noqa: BLE001 - any import failure is the plugin's fault
        raise PluginError(
            f"{kind} plugin {name!r} ({eps[name].value}) failed to import: {exc}"
        ) from exc
    problems = []
    if not isinstance(cls, type):
        problems.append("is not a class")
    else:
        options = getattr(cls, "Options", None)
        if options is None or not dataclasses.is_dataclass(options):
            problems.append("has no `Options` dataclass")
        if not isinstance(getattr(cls, "description", None), str):
            problems.append("has no `description` string")
        if not callable(getattr(cls, spec.method, None)):
            problems.append(f"has no `{spec.method}` method")
    if problems:
        raise PluginError(
            f"{kind} plugin {name!r} ({eps[name].value}) does not satisfy "
            f"{spec.protocol.__name__}: it {', '.join(problems)}"
        )
    return cls


def create(kind: str, name: str, options: list[str] | tuple[str, ...] = ()) -> Any:
    """Instantiate a plugin with options given as ``key=value`` strings."""
    cls = load(kind, name)
    try:
        parsed = parse_options(cls.Options, options)
    except OptionsError as exc:
        raise PluginError(f"{kind} plugin {name!r}: {exc}") from None
    instance = cls(parsed)
    if not isinstance(instance, _kind(kind).protocol):
        raise PluginError(f"{kind} plugin {name!r} does not satisfy its Protocol")
    return instance


def list_plugins() -> list[PluginInfo]:
    """Every registered plugin of every kind. Import failures are reported, not raised."""
    infos = []
    for kind in KINDS:
        for name, ep in sorted(_entry_points(kind).items()):
            dist = ep.dist.name if ep.dist is not None else "?"
            try:
                cls = load(kind, name)
                description = cls.description
                opts = describe_options(cls.Options)
            except PluginError as exc:
                description, opts = f"BROKEN: {exc}", ()
            infos.append(PluginInfo(kind, name, ep.value, dist, description, opts))
    return infos
