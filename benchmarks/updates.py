"""Update speed of each learner (ddpg, td3, sac, tqc) in float32 and in bfloat16 (the networks'
passes under autocast, as ``--precision bfloat16`` runs them): ms per update for the given
networks and batch, and the FLOPs one update needs against this machine's matrix-multiply rate
in each format, measured in the same run.

    python benchmarks/updates.py --updates 300
    python benchmarks/updates.py --learners tqc --hidden-sizes 512 512 512 --batch-size 512
    python benchmarks/updates.py --learners ddpg --split

With ``--split``, the time of an update is also split (by torch's profiler, whose own cost lands
in "the rest") into the matrix products and everything else: the bound on what a faster format
of the products can gain is (products + rest) / rest.
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import time

import numpy as np
import torch
from torch.profiler import ProfilerActivity, profile
from torch.utils.flop_counter import FlopCounterMode

from dtd.agents.goal_learner import GoalLearner
from dtd.agents.learners import make_learner
from dtd.agents.networks import BoxActionHead
from dtd.agents.records import Batch
from dtd.config import LearnerConfig, LearnerKind

OBS, GOAL, ACT = 25, 3, 4  # FetchPush
DTYPES = {"float32": torch.float32, "bfloat16": torch.bfloat16}
MATRIX_PRODUCTS = frozenset({"aten::mm", "aten::addmm", "aten::bmm", "aten::baddbmm"})


def random_batch(rng: np.random.Generator, size: int) -> Batch:
    return Batch(
        obs=rng.normal(size=(size, OBS)).astype(np.float32),
        goal=rng.normal(size=(size, GOAL)).astype(np.float32),
        action=rng.uniform(-1, 1, size=(size, ACT)).astype(np.float32),
        reward=-rng.integers(0, 2, size=size).astype(np.float32),
        next_obs=rng.normal(size=(size, OBS)).astype(np.float32),
    )


def matmul_rate(n: int, dtype: torch.dtype = torch.float32, seconds: float = 2.0) -> float:
    """FLOP/s of an n x n by n x n product in ``dtype``, repeated for about ``seconds``."""
    a, b = torch.randn(n, n, dtype=dtype), torch.randn(n, n, dtype=dtype)
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
    parser.add_argument("--precisions", nargs="+", default=list(DTYPES), choices=list(DTYPES))
    parser.add_argument("--split", action="store_true", help="split each update's time: products / rest")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)

    base = LearnerConfig(hidden_sizes=tuple(args.hidden_sizes), batch_size=args.batch_size)
    rng = np.random.default_rng(0)
    batches = [random_batch(rng, base.batch_size) for _ in range(args.updates)]
    width = max(base.hidden_sizes)
    peaks = {name: matmul_rate(1024, DTYPES[name]) for name in args.precisions}
    layers = {name: matmul_rate(width, DTYPES[name]) for name in args.precisions}
    print(f"# updates, {base.hidden_sizes} hidden, batch {base.batch_size}, "
          f"{args.threads} torch thread(s), {platform.machine()}, torch {torch.__version__}")  # fmt: skip
    for name in args.precisions:
        big, layer = peaks[name] / 1e9, layers[name] / 1e9
        print(f"{name} matmul 1024^3 {big:.1f} GFLOP/s, {width}^3 {layer:.1f} GFLOP/s")
    columns = "MFLOP per update | ms per update | x float32 | GFLOP/s | of 1024^3"
    split_column = " ms in products + the rest |" if args.split else ""
    print(f"| learner | precision | {columns} | of {width}^3 |{split_column}")
    print("|---|---|---|---|---|---|---|---|" + ("---|" if args.split else ""))
    for name in args.learners:
        config = dataclasses.replace(base, learner=LearnerKind(name))
        float32_ms = None
        for precision in args.precisions:
            learner = fresh_learner(config, rng, DTYPES[precision])
            with FlopCounterMode(display=False) as counter:
                learner.update(batches[0])
            flops = counter.get_total_flops()
            rate = update_rate(learner, batches)
            ms = 1000 / rate
            float32_ms = ms if precision == "float32" else float32_ms
            speedup = f"{float32_ms / ms:.2f}" if float32_ms else "-"
            achieved = rate * flops
            shares = f"{achieved / peaks[precision]:.1%} | {achieved / layers[precision]:.1%}"
            measured = f"{flops / 1e6:.1f} | {ms:.2f} | {speedup} | {achieved / 1e9:.1f}"
            split = ""
            if args.split:
                products, rest = time_split(learner, batches[: min(50, len(batches))])
                split = f" {products:.2f} + {rest:.2f} |"
            print(f"| {name} | {precision} | {measured} | {shares} |{split}")


def fresh_learner(
    config: LearnerConfig, rng: np.random.Generator, precision: torch.dtype = torch.float32
) -> GoalLearner:
    learner = make_learner(OBS, GOAL, ACT, BoxActionHead(1.0), config, 0.98, (-1.0, 0.0), precision=precision)
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


def time_split(learner: GoalLearner, batches: list[Batch]) -> tuple[float, float]:
    """ms per update in the matrix products and in everything else, by the profiler's own
    (self) CPU time of each operation."""
    with profile(activities=[ProfilerActivity.CPU]) as profiler:
        for batch in batches:
            learner.update(batch)
    events = profiler.key_averages()
    products = sum(event.self_cpu_time_total for event in events if event.key in MATRIX_PRODUCTS)
    total = sum(event.self_cpu_time_total for event in events)
    per_update = 1000 * len(batches)  # profiler times are in microseconds
    return products / per_update, (total - products) / per_update


if __name__ == "__main__":
    main()
