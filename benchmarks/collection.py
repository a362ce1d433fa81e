"""Collection speed: env steps/s while collecting exploring episodes with the agent, against
the raw physics rate of the very same steps, measured in the same run.

The raw rate counts only the time spent inside ``mujoco.mj_step`` (the environment's
substeps of each env step, in the states the episodes actually visit): the most any
collector on one core could reach. Their ratio is what the Python around the physics
(environment, policy, noise, bookkeeping) leaves of it. A third figure, the environment
stepped alone with random actions, shows how much of that is the environment's own
``step`` (Gymnasium-Robotics' action, callback and observation code), which no collector
can avoid.

    python benchmarks/collection.py --env FetchPush-v4 --episodes 40
"""

from __future__ import annotations

import argparse
import platform
import time
from types import ModuleType
from typing import Any

import mujoco
import numpy as np
import torch

from dtd.config import Algo, Collection, TrainConfig
from dtd.envs.make import make_env
from dtd.training.components import build


class TimedPhysics:
    """Stands in for the ``mujoco`` module inside an environment, timing its ``mj_step``."""

    def __init__(self, module: ModuleType) -> None:
        self._module = module
        self.seconds = 0.0
        self.steps = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._module, name)

    def mj_step(self, *args: Any, **kwargs: Any) -> None:
        start = time.perf_counter()
        self._module.mj_step(*args, **kwargs)
        self.seconds += time.perf_counter() - start
        self.steps += 1


def measure(config: TrainConfig, episodes: int) -> tuple[float, float, int, int]:
    """(collection env steps/s, raw physics env steps/s, steps, horizon) over exploring
    episodes of a fresh agent, collected inline."""
    components = build(config, collection=Collection.inline)
    collector = components.collector
    timers = []
    for env in collector.envs:
        if not hasattr(env.unwrapped, "_mujoco"):
            raise SystemExit(f"{config.env} is not a Gymnasium-Robotics MuJoCo environment")
        timers.append(TimedPhysics(env.unwrapped._mujoco))
        env.unwrapped._mujoco = timers[-1]
    try:
        collector.submit()
        collector.result()  # warm up
        for timer in timers:
            timer.seconds, timer.steps = 0.0, 0
        steps = 0
        start = time.perf_counter()
        while steps < episodes * components.spec.horizon:
            collector.submit()
            steps += collector.result().count * components.spec.horizon
        elapsed = time.perf_counter() - start
        physics_steps = sum(timer.steps for timer in timers)
        physics_rate = physics_steps / sum(timer.seconds for timer in timers)
        return steps / elapsed, physics_rate, steps, components.spec.horizon
    finally:
        components.close()


def environment_alone(env_id: str, steps: int, horizon: int) -> tuple[float, float]:
    """(env steps/s, raw physics env steps/s) of one environment stepped with uniformly random
    actions drawn beforehand: the environment's ``step`` and nothing else."""
    env = make_env(env_id)
    timer = TimedPhysics(env.unwrapped._mujoco)
    env.unwrapped._mujoco = timer
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, (steps, *env.action_space.shape))
    actions = actions.astype(env.action_space.dtype)
    timer.seconds, timer.steps = 0.0, 0
    start = time.perf_counter()
    for t in range(steps):
        if t % horizon == 0:
            env.reset()
        env.step(actions[t])
    elapsed = time.perf_counter() - start
    env.close()
    return steps / elapsed, timer.steps / timer.seconds


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--env", default="FetchPush-v4")
    parser.add_argument("--algo", default="her", choices=[a.value for a in Algo])
    parser.add_argument("--episodes", type=int, default=40, help="episodes to time")
    parser.add_argument("--envs", type=int, default=2, help="environments stepped together")
    args = parser.parse_args()

    config = TrainConfig(env=args.env, algo=Algo(args.algo), episodes_per_cycle=args.envs)
    rate, raw, steps, horizon = measure(config, args.episodes)
    alone, alone_raw = environment_alone(args.env, steps, horizon)
    threads = torch.get_num_threads()
    print(f"# {args.algo} on {args.env}, {args.envs} env(s) in one process, {threads} torch thread(s), "
          f"{platform.machine()}, numpy {np.__version__}, mujoco {mujoco.__version__}")  # fmt: skip
    print(f"{'measure':<28} {'env steps/s':>12}")
    print(f"{'raw physics (mj_step)':<28} {raw:>12.0f}")
    print(f"{'collection with the agent':<28} {rate:>12.0f}   ({steps} steps)")
    print(f"{'ratio':<28} {rate / raw:>12.2f}")
    print(f"{'environment alone':<28} {alone:>12.0f}   (random actions; its own mj_step rate "
          f"{alone_raw:.0f}, ratio {alone / alone_raw:.2f})")  # fmt: skip


if __name__ == "__main__":
    main()
