"""Update speed: learner updates/s for the default networks and batch, and the FLOPs one
update needs, against this machine's float32 matrix-multiply rate measured in the same run.

    python benchmarks/updates.py --updates 300
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from dtd.config import LearnerConfig
from dtd.ddpg import DDPGLearner
from dtd.networks import BoxActionHead
from dtd.records import Batch

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
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    config = LearnerConfig()
    learner = DDPGLearner(OBS, GOAL, ACT, BoxActionHead(1.0), config, gamma=0.98)
    rng = np.random.default_rng(0)
    learner.update_normalizers(rng.normal(size=(1000, OBS)), rng.normal(size=(1000, GOAL)))
    batches = [random_batch(rng, config.batch_size) for _ in range(args.updates)]

    with FlopCounterMode(display=False) as counter:
        learner.update(batches[0])
    flops = counter.get_total_flops()

    for batch in batches[:10]:
        learner.update(batch)
    start = time.perf_counter()
    for batch in batches:
        learner.update(batch)
    rate = args.updates / (time.perf_counter() - start)

    big, layer = matmul_rate(1024), matmul_rate(256)
    print(f"# DDPG update, {config.hidden_sizes} hidden, batch {config.batch_size}, "
          f"{args.threads} torch thread(s), {platform.machine()}, torch {torch.__version__}")  # fmt: skip
    print(f"updates/s                         {rate:10.1f}   ({1000 / rate:.2f} ms each)")
    print(f"FLOPs per update (matmuls)        {flops / 1e6:10.1f} M")
    print(f"achieved                          {rate * flops / 1e9:10.2f} GFLOP/s")
    print(f"float32 matmul 1024^3             {big / 1e9:10.2f} GFLOP/s  -> {rate * flops / big:6.1%} of it")
    print(
        f"float32 matmul 256^3              {layer / 1e9:10.2f} GFLOP/s  -> {rate * flops / layer:6.1%} of it"
    )


if __name__ == "__main__":
    main()
