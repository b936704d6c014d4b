"""Typed option dataclasses filled from ``key=value`` strings (plugin options on the CLI)."""

from __future__ import annotations

import dataclasses
import enum
import types
import typing
from typing import Any


class OptionsError(ValueError):
    pass


def _convert(name: str, text: str, annotation: Any) -> Any:
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if text.lower() in ("none", "null", ""):
            return None
        return _convert(name, text, args[0])
    if annotation is bool:
        if text.lower() in ("1", "true", "yes", "on"):
            return True
        if text.lower() in ("0", "false", "no", "off"):
            return False
        raise OptionsError(f"option {name}={text!r}: expected true or false")
    if isinstance(annotation, type) and issubclass(annotation, enum.Enum):
        try:
            return annotation(text)
        except ValueError:
            choices = ", ".join(str(m.value) for m in annotation)
            raise OptionsError(f"option {name}={text!r}: expected one of {choices}") from None
    if annotation in (int, float, str):
        try:
            return annotation(text)
        except ValueError:
            raise OptionsError(
                f"option {name}={text!r}: expected {annotation.__name__}"
            ) from None
    raise OptionsError(f"option {name}: unsupported type {annotation!r}")


def parse_options(cls: type, items: typing.Iterable[str]) -> Any:
    """Build ``cls`` (a dataclass) from ``key=value`` strings, converting by field type."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    values: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep:
            raise OptionsError(f"option {item!r} is not key=value")
        if key not in fields:
            known = ", ".join(fields) or "none"
            raise OptionsError(f"unknown option {key!r}; options: {known}")
        values[key] = _convert(key, text.strip(), hints[key])
    try:
        return cls(**values)
    except TypeError as exc:
        missing = [
            n
            for n, f in fields.items()
            if n not in values
            and f.default is dataclasses.MISSING
            and f.default_factory is dataclasses.MISSING
        ]
        if missing:
            raise OptionsError(f"missing option {', '.join(f'{m}=...' for m in missing)}") from None
        raise OptionsError(str(exc)) from None
    except ValueError as exc:
        raise OptionsError(str(exc)) from None


def describe_options(cls: type) -> tuple[tuple[str, str, str], ...]:
    """(name, "type = default", help) for each field of an options dataclass."""
    hints = typing.get_type_hints(cls)
    rows = []
    for f in dataclasses.fields(cls):
        tname = getattr(hints[f.name], "__name__", str(hints[f.name]))
        if f.default is not dataclasses.MISSING:
            tname += f" = {f.default}"
        elif f.default_factory is dataclasses.MISSING:
            tname += " (required)"
        rows.append((f.name, tname, f.metadata.get("help", "")))
    return tuple(rows)
