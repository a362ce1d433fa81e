"""Making goal-conditioned environments by id, with a checked :class:`EnvSpec`."""

from __future__ import annotations

import contextlib
import difflib
import io

import gymnasium as gym

from dtd.envs.joint_reads import read_joints_by_index
from dtd.envs.spec import EnvSpec, env_spec
from dtd.errors import EnvError


def register_robotics_envs() -> None:
    """Register the Gymnasium-Robotics environments (quietly: the package prints a notice)."""
    with contextlib.redirect_stderr(io.StringIO()):
        import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)


def make_env(env_id: str) -> gym.Env:
    """Make ``env_id`` (a registered id or ``module:EnvId``) or raise :class:`EnvError`."""
    register_robotics_envs()
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            env = gym.make(env_id, disable_env_checker=True)
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


def make_envs(env_id: str, count: int) -> tuple[list[gym.Env], EnvSpec]:
    """``count`` instances of one environment and its checked spec."""
    envs = [make_env(env_id) for _ in range(count)]
    return envs, env_spec(envs[0], env_id)
