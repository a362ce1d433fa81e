"""Making goal-conditioned environments by id, with a checked :class:`EnvSpec`."""

from __future__ import annotations

import ast
import contextlib
import difflib
import io
import json
import threading
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import gymnasium as gym

from dtd.envs.joint_reads import read_joints_by_index
from dtd.envs.spec import EnvSpec, env_spec
from dtd.envs.time_feature import TimeFeature
from dtd.errors import EnvError

_QUIET = threading.RLock()
"""Held while stderr is sent nowhere: the redirect swaps the process's one ``sys.stderr``, and two
threads making environments at once would otherwise restore each other's stand-in for good."""


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """stderr sent nowhere while the block runs (one thread at a time)."""
    with _QUIET, contextlib.redirect_stderr(io.StringIO()):
        yield


def register_robotics_envs() -> None:
    """Register the Gymnasium-Robotics environments (quietly: the package prints a notice)."""
    with _quiet():
        import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)


def env_kwargs(items: Sequence[str]) -> dict[str, Any]:
    """``KEY=VALUE`` items as keyword arguments: each VALUE read as JSON, else as a Python
    literal (``False``, ``None``), else as text; :class:`EnvError` for an item without a key."""
    kwargs: dict[str, Any] = {}
    for item in items:
        key, equals, text = item.partition("=")
        if not equals or not key.strip().isidentifier():
            raise EnvError(f"--env-kwargs takes KEY=VALUE items, got {_cut(repr(item))}")
        if key.strip() in kwargs:
            raise EnvError(f"--env-kwargs gives {key.strip()} twice; give each argument once")
        kwargs[key.strip()] = _literal(text.strip())
    return kwargs


def _cut(text: str, limit: int = 80) -> str:
    """``text`` as an error line shows it: at most ``limit`` characters, and how many it had."""
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text):,} characters)"


def _literal(text: str) -> Any:
    for read in (json.loads, ast.literal_eval):
        try:
            return read(text)
        except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
            continue
    return text


def make_env(env_id: str, kwargs: Mapping[str, Any] | None = None) -> gym.Env:
    """Make ``env_id`` (a registered id or ``module:EnvId``), its constructor given ``kwargs``,
    or raise :class:`EnvError`."""
    register_robotics_envs()
    kwargs = dict(kwargs or {})
    try:
        with _quiet():
            env = gym.make(env_id, disable_env_checker=True, **kwargs)
    except TypeError as exc:
        if not kwargs:
            raise
        raise EnvError(
            f"environment {env_id!r} refused --env-kwargs {_shown(kwargs)}: {_cut(str(exc), 300)}"
        ) from exc
    except ModuleNotFoundError as exc:
        module = env_id.split(":")[0]
        raise EnvError(f"cannot import module {module!r} named in environment id {env_id!r}") from exc
    except gym.error.Error as exc:
        raise EnvError(_unknown_env_message(env_id)) from exc
    read_joints_by_index(env)
    return env


def _unknown_env_message(env_id: str) -> str:
    known = list(gym.registry.keys())
    name = env_id.split(":")[-1]
    close = difflib.get_close_matches(name, known, n=3, cutoff=0.6)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    return f"unknown environment id {env_id!r}{hint}"


def _shown(kwargs: Mapping[str, Any]) -> str:
    return " ".join(f"{key}={_cut(repr(value))}" for key, value in kwargs.items())


def make_envs(
    env_id: str, count: int, kwargs: Mapping[str, Any] | None = None, time_feature: bool = False
) -> tuple[list[gym.Env], EnvSpec]:
    """``count`` instances of one environment (its constructor given ``kwargs``; with
    ``time_feature``, the fraction of the episode left appended to its observation) and its
    checked spec."""
    envs = [make_env(env_id, kwargs) for _ in range(count)]
    try:
        if time_feature:
            envs = [TimeFeature(env) for env in envs]
        return envs, env_spec(envs[0], env_id)
    except BaseException:
        for env in envs:
            env.close()
        raise
