"""Command-line flags generated from typed config dataclasses, so help text lives in one place.

Each field becomes ``--field-name``; its ``metadata["help"]`` is the help text, its type picks
the parser (enums give choices, ``bool | None`` gives ``--x/--no-x``, tuples are repeatable),
and ``metadata["flags"]`` overrides the flag names.
"""

from __future__ import annotations

import argparse
import dataclasses
import enum
import types
import typing
from typing import Any


def _unwrap_optional(annotation: Any) -> Any:
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return annotation


def add_config_arguments(
    parser: argparse.ArgumentParser, cls: type, *, exclude: tuple[str, ...] = ()
) -> None:
    hints = typing.get_type_hints(cls)
    group = parser.add_argument_group(f"{cls.__name__} options")
    for f in dataclasses.fields(cls):
        if f.name in exclude:
            continue
        flags = f.metadata.get("flags", (f"--{f.name.replace('_', '-')}",))
        kind = _unwrap_optional(hints[f.name])
        default = f.default if f.default is not dataclasses.MISSING else None
        help_text = f.metadata.get("help", "")
        kwargs: dict[str, Any] = {"dest": f.name, "default": None}
        if kind is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        elif typing.get_origin(kind) is tuple:
            # Repeatable flag: each occurrence adds one element, parsed as the element type.
            element = typing.get_args(kind)[0]
            kwargs.update(action="append", metavar=f.metadata.get("metavar", "VALUE"))
            if isinstance(element, type) and issubclass(element, enum.Enum):
                kwargs.update(choices=[m.value for m in element], type=str, metavar=None)
            elif element in (int, float):
                kwargs["type"] = element
        elif isinstance(kind, type) and issubclass(kind, enum.Enum):
            kwargs.update(choices=[m.value for m in kind], type=str)
        else:
            kwargs.update(type=kind,
                          metavar=f.metadata.get("metavar", f.name.split("_")[-1].upper()))
        if isinstance(default, tuple) and default:
            shown = ", ".join(str(getattr(v, "value", v)) for v in default)
            help_text += f" (default: {shown})"
        elif default not in (None, ()):
            help_text += f" (default: {default})"
        group.add_argument(*flags, help=help_text, **kwargs)


def config_from_args(cls: type, args: argparse.Namespace, **overrides: Any) -> Any:
    """Build ``cls`` from parsed args; unset flags keep the dataclass defaults."""
    hints = typing.get_type_hints(cls)
    values: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        value = getattr(args, f.name, None)
        if value is None:
            continue
        kind = _unwrap_optional(hints[f.name])
        if isinstance(kind, type) and issubclass(kind, enum.Enum):
            value = kind(value)
        elif typing.get_origin(kind) is tuple:
            element = typing.get_args(kind)[0]
            is_enum = isinstance(element, type) and issubclass(element, enum.Enum)
            value = tuple(element(v) for v in value) if is_enum else tuple(value)
        values[f.name] = value
    values.update(overrides)
    return cls(**values)
