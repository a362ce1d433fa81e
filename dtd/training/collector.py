"""Collecting training episodes: in the learner's process, or in a process beside it.

Either way a cycle's episodes are asked for with :meth:`Collector.submit` (the policy as it
is at that moment) and taken with :meth:`Collector.result`; the trainer submits the next
cycle's episodes before it makes this cycle's updates, so a collector in its own process
steps the environments on one core while the learner updates on another. Both collectors
produce the same episodes from the same seeds.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import pickle
import signal
import traceback
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch

from dtd.agents.interface import Agent
from dtd.agents.records import Episodes
from dtd.envs.spec import EnvSpec
from dtd.errors import DtdError, MachineError
from dtd.training.rollout import run_episodes

ExploringSide = Callable[[], tuple[list[gym.Env], Agent, EnvSpec, np.random.Generator]]
"""Builds, in the collecting process, its environments, an agent that only acts, the task's
spec and the exploration generator."""


class Collector(Protocol):
    """Exploring episodes of the training environments, one batch per cycle."""

    def submit(self) -> None:
        """Start one batch of episodes with the agent's policy as it is now."""
        ...

    def result(self) -> Episodes:
        """The episodes of the last :meth:`submit` (waits for them)."""
        ...

    def state_dict(self) -> dict[str, Any]:
        """Random states of the exploration and of the environments (between batches only)."""
        ...

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned."""
        ...

    def close(self) -> None:
        """Release the environments (and the process)."""
        ...


def env_rng_states(envs: Sequence[gym.Env]) -> list[dict[str, Any]]:
    """The random state of each environment (it draws initial states and goals)."""
    return [env.unwrapped.np_random.bit_generator.state for env in envs]


def restore_env_rng_states(envs: Sequence[gym.Env], states: Sequence[dict[str, Any]]) -> None:
    """Inverse of :func:`env_rng_states`."""
    for env, state in zip(envs, states, strict=True):
        env.unwrapped.np_random.bit_generator.state = state


class InlineCollector:
    """Collects in the learner's process, with the learning agent itself, at :meth:`submit`."""

    def __init__(self, envs: list[gym.Env], agent: Agent, spec: EnvSpec, rng: np.random.Generator) -> None:
        self.envs = envs
        self.agent = agent
        self.spec = spec
        self.rng = rng
        self._pending: Episodes | None = None

    def submit(self) -> None:
        self._pending = run_episodes(self.envs, self.agent, self.spec, explore=True, rng=self.rng)

    def result(self) -> Episodes:
        assert self._pending is not None, "submit() comes first"
        episodes, self._pending = self._pending, None
        return episodes

    def state_dict(self) -> dict[str, Any]:
        return {"rng": self.rng.bit_generator.state, "envs": env_rng_states(self.envs)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.rng.bit_generator.state = state["rng"]
        restore_env_rng_states(self.envs, state["envs"])

    def close(self) -> None:
        for env in self.envs:
            env.close()


class CollectorProcessError(RuntimeError):
    """The collecting process failed; the message holds its traceback."""


class ProcessCollector:
    """Collects in a process of its own, with a copy of the agent that only acts.

    :meth:`submit` sends the agent's acting state (actors and normalisers, a few hundred kB)
    and returns at once; the environments step while the learner goes on.
    """

    def __init__(self, exploring_side: ExploringSide, agent: Agent) -> None:
        self.agent = agent
        context = multiprocessing.get_context("spawn")
        self._conn, child_conn = context.Pipe()
        self._process = context.Process(
            target=_serve, args=(child_conn, exploring_side), name="dtd-collector", daemon=True
        )
        self._process.start()
        child_conn.close()
        self._waiting = False
        self._receive()  # built, or the error that stopped it

    def submit(self) -> None:
        assert not self._waiting, "result() of the last submit() comes first"
        # Pickled here, by value: sent as they are, torch tensors would travel as shared
        # memory that the learner's next updates overwrite while the episodes run.
        self._conn.send(("collect", pickle.dumps(self.agent.acting_state())))
        self._waiting = True

    def result(self) -> Episodes:
        assert self._waiting, "submit() comes first"
        self._waiting = False
        return self._receive()

    def state_dict(self) -> dict[str, Any]:
        return self._call("get_state")

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self._call("set_state", state)

    def close(self) -> None:
        if self._process.is_alive():
            try:
                if self._waiting:
                    self._receive()
                self._conn.send(("close", None))
            except (OSError, EOFError, CollectorProcessError):
                pass
            self._process.join(timeout=10)
            if self._process.is_alive():
                self._process.terminate()
                self._process.join()
        self._conn.close()

    def _call(self, command: str, payload: Any = None) -> Any:
        assert not self._waiting, "result() of the last submit() comes first"
        self._conn.send((command, payload))
        return self._receive()

    def _receive(self) -> Any:
        try:
            status, reply = self._conn.recv()
        except EOFError:
            raise CollectorProcessError(
                f"the collecting process ended unexpectedly (exit code {self._process.exitcode})"
            ) from None
        if status == "refused":  # the user's to fix, said in one line as inline collection says it
            raise reply
        if status == "error":
            raise CollectorProcessError(f"the collecting process failed:\n{reply}")
        return reply


def _serve(conn: multiprocessing.connection.Connection, exploring_side: ExploringSide) -> None:
    """The collecting process: answers the learner's requests until told to stop or orphaned."""
    # Ctrl-C is the learner's to handle; it closes this process.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    torch.set_num_threads(1)
    try:
        envs, agent, spec, rng = exploring_side()
    except Exception as exc:
        conn.send(_failure(exc))
        return
    collector = InlineCollector(envs, agent, spec, rng)
    conn.send(("ok", None))
    try:
        while True:
            try:
                command, payload = conn.recv()
            except EOFError:  # the learner is gone
                break
            if command == "close":
                break
            try:
                if command == "collect":
                    agent.load_acting_state(pickle.loads(payload))
                    collector.submit()
                    reply: Any = collector.result()
                elif command == "get_state":
                    reply = collector.state_dict()
                elif command == "set_state":
                    collector.load_state_dict(payload)
                    reply = None
                else:
                    raise ValueError(f"unknown request {command!r}")
            except Exception as exc:
                conn.send(_failure(exc))
            else:
                conn.send(("ok", reply))
    finally:
        collector.close()


def _failure(exc: Exception) -> tuple[str, Any]:
    """What the collecting process sends of an exception: a user's error or the machine's
    itself (raised again as it is by the learner), anything else its traceback."""
    if isinstance(exc, DtdError | MachineError):
        try:
            pickle.dumps(exc)
        except Exception:
            return "error", traceback.format_exc()
        return "refused", exc
    return "error", traceback.format_exc()
