"""Collection speed: env steps/s while collecting episodes with the agent, against the raw
physics rate of the same task on the same machine, measured in the same run.

The raw rate is ``mujoco.mj_step`` for the environment's substeps per env step, with no
Python around it but the loop: the most any collector in one process can reach.

    python benchmarks/collection.py --env FetchPush-v4 --episodes 40
"""

from __future__ import annotations

import argparse
import platform
import time

import mujoco
import numpy as np
import torch

from dtd.config import Algo, Collection, TrainConfig
from dtd.runs import build, close_all


def raw_physics_rate(env, steps: int) -> float:
    """Env steps per second of bare ``mj_step`` calls (n_substeps each)."""
    model, data = env.unwrapped.model, env.unwrapped.data
    substeps = int(env.unwrapped.n_substeps)
    mujoco.mj_step(model, data, nstep=substeps)  # warm up
    start = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data, nstep=substeps)
    return steps / (time.perf_counter() - start)


def collection_rate(config: TrainConfig, episodes: int) -> tuple[float, int]:
    """Env steps per second of exploring episodes with a fresh agent, and the steps run."""
    components = build(config, collection=Collection.inline)
    collector = components.collector
    try:
        collector.submit()
        collector.result()  # warm up
        steps = 0
        start = time.perf_counter()
        while steps < episodes * components.spec.horizon:
            collector.submit()
            steps += collector.result().count * components.spec.horizon
        return steps / (time.perf_counter() - start), steps
    finally:
        close_all(components)


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
    components = build(config, collection=Collection.inline)
    raw = raw_physics_rate(components.eval_envs[0], steps=args.episodes * components.spec.horizon)
    close_all(components)
    rate, steps = collection_rate(config, args.episodes)
    threads = torch.get_num_threads()
    print(f"# {args.algo} on {args.env}, {args.envs} env(s) in one process, {threads} torch thread(s), "
          f"{platform.machine()}, numpy {np.__version__}, mujoco {mujoco.__version__}")  # fmt: skip
    print(f"{'measure':<28} {'env steps/s':>12}")
    print(f"{'raw physics (mj_step)':<28} {raw:>12.0f}")
    print(f"{'collection with the agent':<28} {rate:>12.0f}   ({steps} steps)")
    print(f"{'ratio':<28} {rate / raw:>12.2f}")


if __name__ == "__main__":
    main()
