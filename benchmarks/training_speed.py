"""Training speed: wall time per 1,000 env steps of whole training cycles (collect, store,
update), for each algorithm and learner (at both levels of dtd), with episodes collected inline
or in a process beside the learner. Prints the ratios the speed targets are about: dtd against
her, and what the collecting process gains.

    python benchmarks/training_speed.py --env FetchPush-v4 --cycles 100
    python benchmarks/training_speed.py --learners ddpg,tqc --collectors inline
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time

import torch

from dtd.config import Algo, Collection, TrainConfig, with_settings
from dtd.training.components import build


def seconds_per_kilostep(
    config: TrainConfig, collection: Collection, cycles: int, warmup: int
) -> tuple[float, int]:
    """Wall seconds per 1,000 env steps of training cycles, after ``warmup`` cycles, and the
    learner's torch threads."""
    components = build(config, collection=collection)
    threads = torch.get_num_threads()
    agent, collector, horizon = components.agent, components.collector, components.spec.horizon
    try:
        collector.submit()
        steps, start = 0, 0.0
        for cycle in range(warmup + cycles):
            if cycle == warmup:
                steps, start = 0, time.perf_counter()
            episodes = collector.result()
            agent.store(episodes, components.rng)
            collector.submit()
            agent.train(config.updates_per_cycle, components.rng)
            steps += episodes.count * horizon
        collector.result()
        return 1000.0 * (time.perf_counter() - start) / steps, threads
    finally:
        components.close()


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--env", default="FetchPush-v4")
    parser.add_argument("--algos", default="her,dtd")
    parser.add_argument("--learners", default="ddpg", help="learners, each at both levels")
    parser.add_argument("--collectors", default="inline,process")
    parser.add_argument("--cycles", type=int, default=100, help="cycles to time")
    parser.add_argument("--warmup", type=int, default=10, help="cycles before timing (fills the replay)")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="any setting, as for learning_curve.py",
    )
    args = parser.parse_args()

    base = with_settings(TrainConfig(env=args.env), args.set)
    print(f"# {args.env}, {args.cycles} cycles of {base.episodes_per_cycle} episodes + "
          f"{base.updates_per_cycle} updates, {os.cpu_count()} cores, "
          f"{platform.machine()}, torch {torch.__version__}")  # fmt: skip
    header = f"{'algo':<6} {'learner':<8} {'collector':<10} {'threads':>7}"
    print(f"{header} {'s / 1k steps':>13} {'env steps/s':>12}")
    results: dict[tuple[str, str, str], float] = {}
    collections = [Collection(name) for name in args.collectors.split(",")]
    for algo in args.algos.split(","):
        for learner in args.learners.split(","):
            config = with_settings(
                dataclasses.replace(base, algo=Algo(algo)), [f"learner={learner}", f"high.learner={learner}"]
            )
            for collection in collections:
                per_k, threads = seconds_per_kilostep(config, collection, args.cycles, args.warmup)
                results[algo, learner, collection.value] = per_k
                print(f"{algo:<6} {learner:<8} {collection.value:<10} {threads:>7} {per_k:>13.2f} "
                      f"{1000 / per_k:>12.0f}")  # fmt: skip
    for (algo, learner, collector), per_k in results.items():
        if collector == "inline" and (algo, learner, "process") in results:
            gain = per_k / results[algo, learner, "process"]
            print(f"collecting process gain, {algo} {learner}: {gain:.2f}x")
        if algo == "dtd" and ("her", learner, collector) in results:
            ratio = per_k / results["her", learner, collector]
            print(f"dtd / her wall per env step, {learner} ({collector}): {ratio:.2f}x")


if __name__ == "__main__":
    main()
