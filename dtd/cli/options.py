"""The settings of a run as command-line options, and the parsing of a command line.

tyro builds the options from :class:`TrainConfig` itself; a rule in a tyro constructor registry
(:func:`settings_registry`) tells it, per command, each setting's help (its docstring read as
tyro reads docstrings, in whole sentences), the metavar and hint of the settings whose default
says nothing (``--env`` required, ``--high.gamma``'s default), the settings the command does not
take (``--algo`` for ``dtd sweep``), and the defaults of the preset given. A parse error
becomes one line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import inspect
import io
import sys
import typing
from collections.abc import Callable, Mapping, Sequence
from typing import Annotated, Any

import docstring_parser
import tyro
from tyro.constructors import ConstructorRegistry, StructConstructorSpec, StructFieldSpec, StructTypeInfo

from dtd.config import DotToDotConfig, LearnerConfig, TrainConfig, flat_items
from dtd.errors import DtdError

Command = Callable[[], None]


def settings_given(args: Sequence[str]) -> frozenset[str]:
    """The settings a command line gives, by their names in :func:`dtd.config.flat_items`
    (``n_cycles``, ``learner``, ``high.batch_size``, ``preset``), read from its options as typed
    (``--n-cycles 50``, ``--n-cycles=50``, ``--no-time-feature``), whatever their values: a
    setting given at its default is given all the same. Options that are no settings
    (``--resume``, ``--force``) are left out."""
    names = set(flat_items(TrainConfig()))
    flags = {name for name, value in flat_items(TrainConfig()).items() if isinstance(value, bool)}
    given = set()
    for arg in args:
        if arg == "--":
            break  # what follows is positional
        if not arg.startswith("--"):
            continue
        group, dot, name = arg[2:].partition("=")[0].replace("-", "_").rpartition(".")
        if name.startswith("no_") and group + dot + name[3:] in flags:
            name = name[3:]  # --no-time-feature, --high.no-layer-norm
        name = group + dot + name
        if name in names:
            given.add(name)
    return frozenset(given)


def optional(metavar: str, default: str) -> Any:
    """tyro's settings for an option whose None stands for ``default`` (said in its help)."""
    return tyro.conf.arg(metavar=metavar, help_behavior_hint=f"(default: {default})")


Hints = Mapping[str, tuple[str, str | None]]
"""Metavar and hint (shown where the default would be) of options whose default says nothing."""

LEARNER_HINTS: Hints = {
    "batch_size": ("INT", "(default: the algorithm's: 1024 for her and ddpg, 256 for dtd)"),
    "gamma": ("FLOAT", "(default: 1 - 1/T, T being the episode's length in steps)"),
    "target_entropy": ("FLOAT", "(default: minus the action's dimension)"),
}
HIGH_LEVEL_HINTS: Hints = {
    "batch_size": ("INT", None),
    "gamma": ("FLOAT", "(default: the low level's discount to the power of a segment's steps)"),
    "target_entropy": ("FLOAT", "(default: minus the goal's dimension)"),
}
HIGH_LEVEL_HELP = {
    "batch_size": "Transitions per update of the high level's learner.",
    "gamma": "Discount of the high level per segment.",
}
"""Help of the high level's settings where the low level's docstring would mislead."""

ENV_KWARGS_HINT = ("KEY=VALUE ...", "(default: none: the registered defaults)")
N_STEP_HINT = ("INT", "(default: the algorithm's: 3 for dtd, 1 for her and ddpg)")
REQUIRED_ENV: Hints = {"env": ("ID", "(required)"), "env_kwargs": ENV_KWARGS_HINT, "n_step": N_STEP_HINT}
REQUIRED_ENV_UNLESS_RESUMED: Hints = {
    **REQUIRED_ENV,
    "env": ("ID", "(required, unless --resume)"),
    "workers": ("INT", "(default: 1; resumed: the run's own)"),
}


@dataclasses.dataclass(frozen=True)
class _HighLevel(LearnerConfig):
    """The high level's learner settings, told apart from the low level's for their help."""


def settings_registry(omit: frozenset[str] = frozenset(), hints: Hints = REQUIRED_ENV) -> ConstructorRegistry:
    """How tyro builds the settings' options for one command: each with its help text, the
    metavar and hint ``hints`` give, and none for the settings in ``omit`` (they keep their
    default)."""
    registry = ConstructorRegistry()

    @registry.struct_rule
    def settings(info: StructTypeInfo) -> StructConstructorSpec | None:
        if info.type not in (TrainConfig, DotToDotConfig, LearnerConfig, _HighLevel):
            return None
        high = info.type is _HighLevel
        cls = LearnerConfig if high else info.type
        docs = {**field_help(cls), **(HIGH_LEVEL_HELP if high else {})}
        shown = (HIGH_LEVEL_HINTS if high else LEARNER_HINTS) if cls is LearnerConfig else hints
        annotations = typing.get_type_hints(cls, include_extras=True)
        fields = []
        for field in dataclasses.fields(cls):
            if field.name in omit:
                continue
            kind, default = annotations[field.name], getattr(info.default, field.name)
            if field.name == "high":
                kind, default = _HighLevel, _HighLevel(**dataclasses.asdict(default))
            elif field.name in shown:
                metavar, hint = shown[field.name]
                kind = Annotated[kind, tyro.conf.arg(metavar=metavar, help_behavior_hint=hint)]
            fields.append(StructFieldSpec(field.name, kind, default, docs[field.name]))
        instantiate = LearnerConfig if high else cls
        return StructConstructorSpec(functools.partial(_made, instantiate, info.default), tuple(fields))

    return registry


def _made(cls: type, defaults: Any, **given: Any) -> Any:
    """An instance of ``cls``: ``defaults`` with what was given (the options a command omits
    keep their default)."""
    return cls(
        **{**{field.name: getattr(defaults, field.name) for field in dataclasses.fields(cls)}, **given}
    )


@functools.cache
def field_help(cls: type) -> dict[str, str]:
    """The docstring below each field of dataclass ``cls``, as tyro reads it, in whole
    sentences: single line breaks joined, reST literals plain (``x`` becomes x)."""
    return {
        param.arg_name: as_sentences(param.description)
        for param in docstring_parser.parse_from_object(cls).params
        if param.description
    }


def as_sentences(text: str) -> str:
    """``text`` with single line breaks joined and reST literals plain: ``x`` becomes x."""
    paragraphs = inspect.cleandoc(text).split("\n\n")
    return "\n\n".join(" ".join(part.split()) for part in paragraphs).replace("``", "")


def reflowed(docstring: str) -> str:
    """A command's docstring with each paragraph on one line; blocks whose lines are indented
    (examples, ``Args:``) kept as they are."""
    blocks = inspect.cleandoc(docstring).split("\n\n")
    out = []
    for block in blocks:
        lines = block.splitlines()
        if lines[0] == "Args:":
            out.append("\n".join(_joined_arguments(lines)))
            continue
        indented = any(line.startswith(" ") for line in lines[1:]) or lines[0].endswith(":")
        out.append(block if indented else " ".join(line.strip() for line in lines))
    return "\n\n".join(out)


def _joined_arguments(lines: list[str]) -> list[str]:
    """An ``Args:`` block with each argument's text on one line: a line indented deeper than
    the arguments' names continues the one before (tyro would keep its line break)."""
    names = min((len(line) - len(line.lstrip()) for line in lines[1:] if line.strip()), default=0)
    joined = lines[:1]
    for line in lines[1:]:
        if len(line) - len(line.lstrip()) > names and len(joined) > 1:
            joined[-1] += " " + line.strip()
        else:
            joined.append(line)
    return joined


def deferred(
    function: Callable[..., None], defaults: TrainConfig | None = None, bound: Mapping[str, Any] | None = None
) -> Callable[..., Command]:
    """A stand-in for command ``function`` that tyro parses into: the same options (its
    ``config`` parameter's defaults ``defaults``) and help, returning the call to make
    instead of making it; the parameters named in ``bound`` are no options, but given these
    values."""
    bound = dict(bound or {})
    signature = inspect.signature(function)
    hints = typing.get_type_hints(function, include_extras=True)
    parameters = []
    for parameter in signature.parameters.values():
        if parameter.name in bound:
            continue
        annotation = as_declared(hints.get(parameter.name, parameter.annotation), parameter.default)
        if parameter.name == "config" and defaults is not None:
            parameter = parameter.replace(default=defaults)
        # Keyword-only: a default given to config may precede options without one.
        parameters.append(parameter.replace(annotation=annotation, kind=inspect.Parameter.KEYWORD_ONLY))

    def parse(**given: Any) -> Command:
        return functools.partial(function, **given, **bound)

    parse.__signature__ = signature.replace(parameters=parameters)  # type: ignore[attr-defined]
    parse.__annotations__ = {parameter.name: parameter.annotation for parameter in parameters}
    parse.__doc__ = reflowed(function.__doc__ or "")
    parse.__name__ = function.__name__
    return parse


def as_declared(hint: Any, default: Any) -> Any:
    """The annotation as written: before Python 3.11 ``typing.get_type_hints`` wraps Optional
    around a parameter's annotation when its default is None, which hides tyro's settings in
    an ``Annotated`` inside it."""
    if default is not None or sys.version_info >= (3, 11) or typing.get_origin(hint) is not typing.Union:
        return hint
    members = typing.get_args(hint)
    annotated = [member for member in members if typing.get_origin(member) is Annotated]
    return annotated[0] if len(members) == 2 and len(annotated) == 1 and type(None) in members else hint


def parse_command(
    commands: dict[str, Callable[..., Command]],
    description: str,
    args: list[str],
    registries: Mapping[str, ConstructorRegistry],
) -> Command:
    """The command ``args`` name, parsed (its settings' options as ``registries`` says, for a
    command that takes them); ``--help`` prints and exits 0, a parse error is a
    :class:`DtdError` of one line."""
    if args and not args[0].startswith("-") and args[0] not in commands:
        raise DtdError(f"unknown command {args[0]!r}; the commands are {', '.join(commands)}")
    registry = registries.get(args[0]) if args else None
    errors = io.StringIO()
    try:
        with contextlib.redirect_stderr(errors):
            return tyro.extras.subcommand_cli_from_dict(
                commands, prog="dtd", description=description, args=args, registry=registry
            )
    except SystemExit as exc:
        if exc.code in (0, None):
            raise
        raise DtdError(one_line(errors.getvalue(), args)) from None


def one_line(message: str, args: list[str]) -> str:
    """tyro's boxed parse error as one line, pointing to the command's help."""
    lines, suggested, section, suggesting = [], [], 0, False
    for line in message.splitlines():
        text = line.strip().strip("│╭╮╰╯─").strip()
        if line.strip().startswith("│ ─"):
            section += 1  # the message, then tyro's suggestions or the option's help, then a pointer
        elif section == 0 and text and not line.strip().startswith(("╭", "╰")):
            lines.append(text)
        elif section == 1 and text.startswith("Perhaps you meant"):
            suggesting = True
        elif section == 1 and suggesting and text.startswith("--"):
            suggested.append(text.split()[0])
    text = " ".join(lines) or "cannot parse the command line"
    if suggested:
        text += f"; perhaps you meant {' or '.join(dict.fromkeys(suggested))}"
    command = args[0] if args and not args[0].startswith("-") else ""
    return f"{text} (see dtd {command + ' ' if command else ''}--help)"
