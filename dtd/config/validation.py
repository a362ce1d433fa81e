"""The bounds of settings: each setting's type carries its own (``Annotated[int, AT_LEAST_1]``),
and :func:`validate` checks them all, failing with the option's name and what it must be."""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
from collections.abc import Callable
from typing import Any

from dtd.errors import ConfigError


@dataclasses.dataclass(frozen=True)
class Bound:
    """What a setting's value must be: ``holds`` it, as ``must`` says (``be at least 1``)."""

    holds: Callable[[Any], bool]
    must: str


def at_least(low: int) -> Bound:
    return Bound(lambda value: value >= low, f"be at least {low}")


def within(low: float, high: float, unit: str = "") -> Bound:
    return Bound(lambda value: math.isfinite(value) and low <= value <= high, f"lie in [{low}, {high}]{unit}")


AT_LEAST_1 = at_least(1)
AT_LEAST_2 = at_least(2)
HALF_TURN = within(0, 180, " degrees")
ZERO_OR_MORE = Bound(lambda value: value >= 0, "be 0 or more")
NOT_NEGATIVE = Bound(lambda value: math.isfinite(value) and value >= 0, "be >= 0")
POSITIVE = Bound(lambda value: math.isfinite(value) and value > 0, "be > 0")
PROBABILITY = within(0, 1)
FINITE = Bound(math.isfinite, "be a finite number")
DISCOUNT = Bound(lambda value: math.isfinite(value) and 0 < value <= 1, "lie in (0, 1]")
WIDTHS = Bound(lambda value: len(value) >= 1 and min(value) >= 1, "be positive widths")
GIVEN = Bound(lambda value: value.strip() != "", "be given")
AUTOMATIC_OR_MORE = Bound(lambda value: value >= 0, "be 0 (automatic) or more")

UNSET_BY_ALGORITHM = frozenset({"--batch-size", "--n-step"})
"""Options whose unset value is their algorithm's (the high level's batch has none)."""


def validate(settings: Any, prefix: str = "--") -> None:
    """Raise :class:`ConfigError` naming the first setting of the dataclass ``settings`` (and of
    its groups of settings) outside its bound; an unset value (None) passes where its option
    may be left out (``--env`` until a run starts: :func:`required_env`)."""
    hints = _annotations(type(settings))
    for field in dataclasses.fields(settings):
        value, option = getattr(settings, field.name), prefix + field.name.replace("_", "-")
        if dataclasses.is_dataclass(value):
            validate(value, "--high." if field.name == "high" else prefix)
            continue
        bounds = [item for item in getattr(hints[field.name], "__metadata__", ()) if isinstance(item, Bound)]
        if value is None:
            if option == "--high.batch-size":
                raise ConfigError(f"{option} must be at least 1, got None")
            continue
        for bound in bounds:
            if not bound.holds(value):
                unset = " (left out: the algorithm's)" if option in UNSET_BY_ALGORITHM else ""
                raise ConfigError(f"{option} must {bound.must}{unset}, got {value!r}")
    dropped, quantiles = getattr(settings, "dropped_quantiles", 0), getattr(settings, "quantiles", 1)
    if dropped >= quantiles:
        raise ConfigError(f"{prefix}dropped-quantiles must be fewer than {prefix}quantiles, got {dropped}")


@functools.cache
def _annotations(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls, include_extras=True)


def required_env(env: str | None) -> str:
    """The environment of a run to start, which must be given."""
    if env is None:
        raise ConfigError("--env is required")
    return env
