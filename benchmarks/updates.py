"""Update speed of each learner (ddpg, td3, sac, tqc): ms per update for the given networks
and batch, and the FLOPs one update needs against this machine's float32 matrix-multiply rate
measured in the same run.

    python benchmarks/updates.py --updates 300
    python benchmarks/updates.py --learners tqc --hidden-sizes 512 512 512 --batch-size 512
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import time

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from dtd.agents.learner import GoalLearner
from dtd.agents.learners import make_learner
from dtd.agents.networks import BoxActionHead
from dtd.agents.records import Batch
from dtd.config import LearnerConfig, LearnerKind

OBS, GOAL, ACT = 25, 3, 4  # FetchPush


def random_batch(rng: np.random.Generator, size: int) -> Batch:
    return Batch(
        obs=rng.normal(size=(size, OBS)).astype(np.float32),
        goal=rng.normal(size=(size, GOAL)).astype(np.float32),
        action=rng.uniform(-1, 1, size=(size, ACT)).astype(np.float32),
        reward=-rng.integers(0, 2, size=size).astype(np.float32),
        next_obs=rng.normal(size=(size, OBS)).astype(np.float32),
    )


def matmul_rate(n: int, seconds: float = 2.0) -> float:
    """float32 FLOP/s of an n x n by n x n product, repeated for about ``seconds``."""
    a, b = torch.randn(n, n), torch.randn(n, n)
    torch.mm(a, b)
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        torch.mm(a, b)
        count += 1
    return 2 * n**3 * count / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--updates", type=int, default=300)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--learners", nargs="+", default=[kind.value for kind in LearnerKind])
    parser.add_argument("--hidden-sizes", type=int, nargs="+", default=list(LearnerConfig.hidden_sizes))
    parser.add_argument("--batch-size", type=int, default=LearnerConfig.batch_size)
    parser.add_argument("--compile", action="store_true", help="also time torch.compile'd networks")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    base = LearnerConfig(hidden_sizes=tuple(args.hidden_sizes), batch_size=args.batch_size)
    rng = np.random.default_rng(0)
    batches = [random_batch(rng, base.batch_size) for _ in range(args.updates)]
    big, layer = matmul_rate(1024), matmul_rate(256)
    print(f"# updates, {base.hidden_sizes} hidden, batch {base.batch_size}, "
          f"{args.threads} torch thread(s), {platform.machine()}, torch {torch.__version__}")  # fmt: skip
    print(f"float32 matmul 1024^3 {big / 1e9:.2f} GFLOP/s, 256^3 {layer / 1e9:.2f} GFLOP/s")
    print("| learner | mode | MFLOP per update | ms per update | GFLOP/s | of 1024^3 peak | of 256^3 |")
    print("|---|---|---|---|---|---|---|")
    for name in args.learners:
        config = dataclasses.replace(base, learner=LearnerKind(name))
        learner = fresh_learner(config, rng)
        with FlopCounterMode(display=False) as counter:
            learner.update(batches[0])
        flops = counter.get_total_flops()
        rates = {"eager": (update_rate(learner, batches), 0.0)}
        if args.compile:
            learner = fresh_learner(config, rng)
            learner.compile()
            start = time.perf_counter()
            learner.update(batches[0])
            learner.update(batches[1])  # the actor's own graph, compiled at its second use
            compile_s = time.perf_counter() - start
            rates["compiled"] = (update_rate(learner, batches), compile_s)
        for mode, (rate, compile_s) in rates.items():
            achieved = rate * flops
            note = f" (compiling {compile_s:.0f} s)" if compile_s else ""
            print(f"| {name} | {mode}{note} | {flops / 1e6:.1f} | {1000 / rate:.2f} | "
                  f"{achieved / 1e9:.2f} | {achieved / big:.1%} | {achieved / layer:.1%} |")  # fmt: skip


def fresh_learner(config: LearnerConfig, rng: np.random.Generator) -> GoalLearner:
    learner = make_learner(OBS, GOAL, ACT, BoxActionHead(1.0), config, gamma=0.98, sparse_rewards=(-1.0, 0.0))
    learner.update_normalizers(rng.normal(size=(1000, OBS)), rng.normal(size=(1000, GOAL)))
    return learner


def update_rate(learner: GoalLearner, batches: list[Batch]) -> float:
    """Updates per second over ``batches``, after 10 warm-up updates."""
    for batch in batches[:10]:
        learner.update(batch)
    start = time.perf_counter()
    for batch in batches:
        learner.update(batch)
    return len(batches) / (time.perf_counter() - start)


if __name__ == "__main__":
    main()
