"""Plain JSON data and typed settings: a dataclass of settings read from a mapping, each value
checked against its field's type, and any value written as JSON's data."""

from __future__ import annotations

import dataclasses
import enum
import types
import typing
from typing import Any

from dtd.errors import ConfigError


def typed_fields(cls: type, data: Any, prefix: str) -> dict[str, Any]:
    """The fields of dataclass ``cls`` in ``data``, each checked against its type; a group of
    settings (a dataclass) is its default with the values given on top."""
    if not isinstance(data, dict):
        raise ConfigError(f"{prefix.rstrip('.') or 'the configuration'} must be a mapping of settings")
    _reject_unknown(cls, data)
    hints = typing.get_type_hints(cls)
    defaults = {field.name: field.default for field in dataclasses.fields(cls)}
    typed = {}
    for name, value in data.items():
        if dataclasses.is_dataclass(hints[name]):
            # Dot-to-Dot's settings are named as their options are, without a prefix.
            inner = prefix if name in UNPREFIXED_GROUPS else f"{prefix}{name}."
            typed[name] = dataclasses.replace(defaults[name], **typed_fields(hints[name], value, inner))
        else:
            typed[name] = _typed(prefix + name, value, hints[name])
    return typed


UNPREFIXED_GROUPS = frozenset({"dtd"})


def _typed(name: str, value: Any, kind: Any) -> Any:
    """``value`` as a value of type ``kind`` (a JSON list becomes a tuple, an int a float), or
    :class:`ConfigError` naming the setting."""
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        options = [option for option in typing.get_args(kind) if option is not type(None)]
        if value is None and len(options) < len(typing.get_args(kind)):
            return None
        (kind,) = options
    if isinstance(kind, type) and issubclass(kind, enum.Enum):
        try:
            return kind(value)
        except ValueError as exc:
            raise ConfigError(f"unknown {name} {value!r}") from exc
    if typing.get_origin(kind) is tuple:
        item_kind = typing.get_args(kind)[0]
        accepts_item = _is_int if item_kind is int else (lambda item: isinstance(item, str))
        if isinstance(value, list | tuple) and all(accepts_item(item) for item in value):
            return tuple(value)
        items = "integers" if item_kind is int else "strings"
        raise ConfigError(f"{name} must be a list of {items}, got {value!r}")
    checks = {
        bool: (lambda v: isinstance(v, bool), "true or false"),
        int: (_is_int, "an integer"),
        float: (lambda v: _is_int(v) or isinstance(v, float), "a number"),
        str: (lambda v: isinstance(v, str), "a string"),
    }
    accepts, expected = checks[kind]
    if not accepts(value):
        raise ConfigError(f"{name} must be {expected}, got {value!r}")
    return float(value) if kind is float else value


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def plain_data(value: Any) -> Any:
    """``value`` as JSON's data: mappings and sequences of plain values, enums as their values,
    numpy's arrays and scalars as lists and numbers."""
    if isinstance(value, dict):
        return {key: plain_data(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [plain_data(item) for item in value]
    if isinstance(value, enum.Enum):
        return value.value
    if hasattr(value, "tolist"):  # a numpy array or scalar
        return value.tolist()
    return value


def _reject_unknown(cls: type, data: dict[str, Any]) -> None:
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ConfigError(f"unknown setting(s) in configuration: {', '.join(unknown)}")
