"""The settings of a run as command-line options, and the parsing of a command line.

tyro reads :class:`TrainConfig`'s field docstrings as help text but keeps their source line
breaks, and knows nothing of a setting that is required only when starting a run. So each
command gets a view of the configuration built here: the same fields and defaults (those of
the preset given), each with its docstring as whole sentences and one default, ``--env``
marked as required, and fields a command does not take (``--algo`` for ``dtd sweep``) left
out. A parse error becomes one line.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import functools
import inspect
import io
import itertools
import re
import sys
import textwrap
import typing
from collections.abc import Callable, Mapping
from typing import Annotated, Any

import tyro

from dtd.config import DotToDotConfig, LearnerConfig, TrainConfig
from dtd.errors import DtdError

Command = Callable[[], None]


def optional(metavar: str, default: str) -> Any:
    """tyro's settings for an option whose None stands for ``default`` (said in its help)."""
    return tyro.conf.arg(metavar=metavar, help_behavior_hint=f"(default: {default})")


HIGH_LEVEL_HELP = {
    "batch_size": "Transitions per update of the high level's learner.",
    "gamma": "Discount of the high level per segment.",
}
"""Help of the high level's settings where the low level's docstring would mislead."""

TARGET_ENTROPY_HINT = ("FLOAT", "(default: minus the action's dimension)")
LEARNER_HINTS = {
    "batch_size": ("INT", "(default: the algorithm's: 1024 for her and ddpg, 256 for dtd)"),
    "gamma": ("FLOAT", "(default: 1 - 1/T, T being the episode's length in steps)"),
    "target_entropy": TARGET_ENTROPY_HINT,
}
HIGH_LEVEL_HINTS = {
    "batch_size": ("INT", None),
    "gamma": ("FLOAT", "(default: the low level's discount to the power of a segment's steps)"),
    "target_entropy": ("FLOAT", "(default: minus the goal's dimension)"),
}
"""Metavar and hint of the learners' settings whose default (None) says nothing."""

ENV_KWARGS_HINT = ("KEY=VALUE ...", "(default: none: the registered defaults)")
N_STEP_HINT = ("INT", "(default: the algorithm's: 3 for dtd, 1 for her and ddpg)")
REQUIRED_ENV = {"env": ("ID", "(required)"), "env_kwargs": ENV_KWARGS_HINT, "n_step": N_STEP_HINT}
REQUIRED_ENV_UNLESS_RESUMED = {
    "env": ("ID", "(required, unless --resume)"),
    "env_kwargs": ENV_KWARGS_HINT,
    "n_step": N_STEP_HINT,
    "workers": ("INT", "(default: 1; resumed: the run's own)"),
}
"""Metavar and hint (shown where the default would be) of options whose default says nothing."""


@functools.cache
def field_help(cls: type) -> dict[str, str]:
    """The docstring below each field of dataclass ``cls``, as one paragraph per blank line."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs = {}
    for field, after in itertools.pairwise(body):
        if (
            isinstance(field, ast.AnnAssign)
            and isinstance(field.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[field.target.id] = as_sentences(after.value.value)
    return docs


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


def options_class(
    defaults: TrainConfig,
    omit: frozenset[str] = frozenset(),
    hints: dict[str, tuple[str, str]] = REQUIRED_ENV,
) -> type:
    """A frozen dataclass of :class:`TrainConfig`'s fields but ``omit``, defaults from
    ``defaults``, each with its help text (and the metavar and hint ``hints`` give);
    :func:`to_config` turns an instance back."""
    return _options(TrainConfig, defaults, omit, hints, "TrainOptions")


def _options(
    cls: type, defaults: Any, omit: frozenset[str], hints: dict[str, tuple[str, str]], name: str
) -> type:
    types = typing.get_type_hints(cls)
    docs = field_help(cls)
    fields: list[tuple[str, Any, Any]] = []
    for field in dataclasses.fields(cls):
        if field.name in omit:
            continue
        value = getattr(defaults, field.name)
        if isinstance(value, LearnerConfig):
            level = _learner_options(value, high=field.name == "high")
            annotation: Any = Annotated[level, tyro.conf.arg(help=docs[field.name])]
            if field.name == "learner":
                annotation = tyro.conf.OmitArgPrefixes[annotation]
            value = level()
        elif isinstance(value, DotToDotConfig):
            # Its options keep their names (--segments, --high.batch-size): no prefix.
            group = _options(DotToDotConfig, value, omit, hints, "DotToDotOptions")
            annotation = Annotated[group, tyro.conf.arg(name="")]
            value = group()
        else:
            metavar, hint = hints.get(field.name, (None, None))
            arg = tyro.conf.arg(help=docs[field.name], metavar=metavar, help_behavior_hint=hint)
            annotation = Annotated[types[field.name], arg]
        fields.append((field.name, annotation, dataclasses.field(default=value)))
    return dataclasses.make_dataclass(name, fields, frozen=True)


def _learner_options(defaults: LearnerConfig, high: bool) -> type:
    hints = typing.get_type_hints(LearnerConfig)
    docs = {**field_help(LearnerConfig), **(HIGH_LEVEL_HELP if high else {})}
    metavars = HIGH_LEVEL_HINTS if high else LEARNER_HINTS
    fields = []
    for field in dataclasses.fields(LearnerConfig):
        metavar, hint = metavars.get(field.name, (None, None))
        arg = tyro.conf.arg(help=docs[field.name], metavar=metavar, help_behavior_hint=hint)
        default = dataclasses.field(default=getattr(defaults, field.name))
        fields.append((field.name, Annotated[hints[field.name], arg], default))
    return dataclasses.make_dataclass("HighLevelOptions" if high else "LearnerOptions", fields, frozen=True)


def to_config(options: Any) -> TrainConfig:
    """The :class:`TrainConfig` an instance of an :func:`options_class` stands for."""
    return TrainConfig(**_values(options))


def _values(options: Any) -> dict[str, Any]:
    values = {field.name: getattr(options, field.name) for field in dataclasses.fields(options)}
    for name in ("learner", "high"):
        if name in values:
            values[name] = LearnerConfig(**dataclasses.asdict(values[name]))
    if "dtd" in values:
        values["dtd"] = DotToDotConfig(**_values(values["dtd"]))
    return values


def deferred(
    function: Callable[..., None], options: type | None = None, bound: Mapping[str, Any] | None = None
) -> Callable[..., Command]:
    """A stand-in for command ``function`` that tyro parses into: the same options (its
    ``config`` parameter as the view ``options``) and help, returning the call to make
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
        if parameter.name == "config" and options is not None:
            annotation = Annotated[options, tyro.conf.arg(name="")]
            parameter = parameter.replace(default=options())
        # Keyword-only: a default given to config may precede options without one.
        parameters.append(parameter.replace(annotation=annotation, kind=inspect.Parameter.KEYWORD_ONLY))

    def parse(**given: Any) -> Command:
        if "config" in given:
            given["config"] = to_config(given["config"])
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


def parse_command(commands: dict[str, Callable[..., Command]], description: str, args: list[str]) -> Command:
    """The command ``args`` name, parsed; ``--help`` prints and exits 0, a parse error is a
    :class:`DtdError` of one line."""
    if args and not args[0].startswith("-") and args[0] not in commands:
        raise DtdError(f"unknown command {args[0]!r}; the commands are {', '.join(commands)}")
    errors = io.StringIO()
    try:
        with contextlib.redirect_stderr(errors):
            return tyro.extras.subcommand_cli_from_dict(
                commands, prog="dtd", description=description, args=args
            )
    except SystemExit as exc:
        if exc.code in (0, None):
            raise
        raise DtdError(one_line(errors.getvalue(), args)) from None


def one_line(message: str, args: list[str]) -> str:
    """tyro's boxed parse error as one line, pointing to the command's help."""
    lines = []
    for line in message.splitlines():
        text = line.strip().strip("│╭╮╰╯─").strip()
        if line.strip().startswith("│ ─") or text.startswith("For full helptext"):
            break
        if text and not line.strip().startswith(("╭", "╰")):
            lines.append(text)
    text = " ".join(lines) or "cannot parse the command line"
    option = r"(--[\w.-]+)"
    not_int = r"invalid literal for int\(\) with base 10"
    not_float = "could not convert string to float"
    choices = r"Expected one of \((.*)\)\."
    rewrites = [
        (rf"Error parsing {option}: {not_int}: (.*)", r"\1 takes an integer, got \2"),
        (rf"Error parsing {option}: {not_float}: (.*)", r"\1 takes a number, got \2"),
        (rf"invalid choice (.*) for argument '{option}'\. {choices}", r"\2: \1 is none of \3"),
    ]
    for pattern, replacement in rewrites:
        text = re.sub(pattern, replacement, text)
    command = args[0] if args and not args[0].startswith("-") else ""
    return f"{text} (see dtd {command + ' ' if command else ''}--help)"
