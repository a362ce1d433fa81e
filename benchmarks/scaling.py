"""Data-parallel workers (``dtd train --workers N``): what they cost and what they buy here, and
a model for larger N.

1. all-reduce: ms per all-reduce of float32 tensors of several sizes between 2 local gloo
   workers (the learner's flattened gradients among them), fitted to a latency per message and
   a cost per byte.
2. update: ms per learner update (FetchPush's sizes, 3x256) on its own and with its gradients
   averaged between 2 workers, 1 thread each.
3. training: env steps and updates per second of a short FetchPush ``dtd train`` with 1 and 2
   workers (1 thread each, episodes collected inline).
4. model: per update, the update's compute plus a ring all-reduce of the gradients among N
   workers, 2 (N - 1) latencies + 2 (N - 1) / N of the bytes; so env steps per second for N
   workers on a machine of at least N free cores, from the figures measured here.

    python benchmarks/scaling.py              # everything (about 3 minutes on 2 cores)
    python benchmarks/scaling.py --skip-training
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SIZES = (1_000, 10_000, 100_000, 1_000_000)
BATCHES = (256, 1024)


def gradient_sizes(batch: int = 256) -> tuple[int, int]:
    """Entries of the actor's and of the critic's gradients (FetchPush, 3x256): each update
    all-reduces the critic's, then the actor's."""
    from updates import ACT, GOAL, OBS  # benchmarks/updates.py: FetchPush's sizes

    from dtd.agents.ddpg import DDPGLearner
    from dtd.agents.networks import BoxActionHead
    from dtd.config import LearnerConfig

    learner = DDPGLearner(
        OBS, GOAL, ACT, BoxActionHead(1.0), LearnerConfig(batch_size=batch), 0.98, (-1.0, 0.0)
    )
    return sum(p.numel() for p in learner.actor.parameters()), sum(
        p.numel() for p in learner.critic.parameters()
    )


def worker(rank: int, workers: int, port: int, out: str) -> None:
    """One gloo worker: time all-reduces of each size, then updates with averaged gradients."""
    import torch
    import torch.distributed as dist

    torch.set_num_threads(1)
    store = dist.TCPStore("127.0.0.1", port, is_master=False)  # the one main() holds
    dist.init_process_group("gloo", store=store, rank=rank, world_size=workers)
    results: dict[str, object] = {}
    sizes = sorted({*SIZES, *gradient_sizes()})
    for size in sizes:
        tensor = torch.ones(size)
        for _ in range(20):
            dist.all_reduce(tensor)
        times = []
        for _ in range(200):
            dist.barrier()
            began = time.perf_counter()
            dist.all_reduce(tensor)
            times.append(time.perf_counter() - began)
        results[f"allreduce_{size}"] = 1000 * float(np.median(times))
    from dtd.agents.collective import ProcessGroup

    collective = ProcessGroup()
    for batch in BATCHES:
        results[f"update_averaged_{batch}"] = ms_per_update(batch, np.random.default_rng(rank), collective)
    dist.barrier()
    dist.destroy_process_group()
    if rank == 0:
        Path(out).write_text(json.dumps(results))


def ms_per_update(batch: int, rng: np.random.Generator, collective: object = None) -> float:
    """ms per update (mean of 200 after 10 to warm up) of a fresh learner of FetchPush's sizes,
    combining its gradients through ``collective`` where given."""
    from updates import ACT, GOAL, OBS, random_batch  # benchmarks/updates.py

    from dtd.agents.collective import ALONE
    from dtd.agents.ddpg import DDPGLearner
    from dtd.agents.networks import BoxActionHead
    from dtd.config import LearnerConfig

    config = LearnerConfig(batch_size=batch)
    learner = DDPGLearner(OBS, GOAL, ACT, BoxActionHead(1.0), config, 0.98, (-1.0, 0.0), collective or ALONE)
    batches = [random_batch(rng, batch) for _ in range(20)]
    for b in batches[:10]:
        learner.update(b)
    began = time.perf_counter()
    for index in range(200):
        learner.update(batches[index % 20])
    return 1000 * (time.perf_counter() - began) / 200


def updates_alone() -> dict[str, float]:
    """ms per update of a learner of its own, 1 thread."""
    import torch

    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    return {f"update_alone_{batch}": ms_per_update(batch, rng) for batch in BATCHES}


def training(workers: int, algo: str, folder: Path) -> dict[str, float]:
    """Env steps and updates (per worker) per second of a short FetchPush run."""
    run_dir = folder / f"{algo}-{workers}"
    args = ["--env", "FetchPush-v4", "--algo", algo, "--seed", "0", "--epochs", "2", "--n-cycles", "10",
            "--threads", "1", "--collector", "inline", "--no-progress",
            "--workers", str(workers)]  # fmt: skip
    subprocess.run([sys.executable, "-m", "dtd", "train", *args, "--run-dir", str(run_dir)], check=True,
                   stdout=subprocess.DEVNULL)  # fmt: skip
    with open(run_dir / "metrics.csv") as file:
        rows = list(csv.DictReader(file))
    # The second epoch: the first includes starting the environments and the first batches.
    steps = float(rows[1]["env_steps"]) - float(rows[0]["env_steps"])
    updates = float(rows[1]["updates"]) - float(rows[0]["updates"])
    wall = float(rows[1]["wall_s"]) - float(rows[0]["wall_s"])
    return {"env_steps_per_s": steps / wall, "updates_per_s_per_worker": updates / wall}


def fit(allreduce: dict[int, float]) -> tuple[float, float]:
    """Latency per message (ms) and cost per byte (ms) of 2 workers' all-reduces: t = 2a + b S."""
    sizes = np.array(sorted(allreduce), dtype=np.float64)
    times = np.array([allreduce[int(size)] for size in sizes])
    design = np.stack([np.full_like(sizes, 2.0), 4.0 * sizes], axis=1)  # 4 bytes per float32
    (latency, per_byte), *_ = np.linalg.lstsq(design, times, rcond=None)
    return float(max(latency, 0.0)), float(max(per_byte, 0.0))


def ring_allreduce_ms(workers: int, floats: int, latency: float, per_byte: float) -> float:
    if workers == 1:
        return 0.0
    return 2 * (workers - 1) * latency + 2 * (workers - 1) / workers * 4 * floats * per_byte


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--skip-training", action="store_true", help="only the all-reduce and update figures")
    args = parser.parse_args()
    import torch.distributed as dist
    import torch.multiprocessing as mp

    sys.path.insert(0, str(Path(__file__).parent))
    print(f"machine: {os.cpu_count()} cores; 2 gloo workers on 127.0.0.1, 1 torch thread each")
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "worker.json"
        # The rendezvous store is bound here on a port the system chooses, before the workers
        # start, as dtd train --workers does: no other job can take the port in between.
        store = dist.TCPStore("127.0.0.1", 0, is_master=True, wait_for_workers=False)
        mp.spawn(worker, args=(2, store.port, str(out)), nprocs=2, join=True)
        measured = json.loads(out.read_text())
        measured.update(updates_alone())
        trained = {}
        if not args.skip_training:
            for algo in ("dtd", "her"):
                for workers in (1, 2):
                    trained[(algo, workers)] = training(workers, algo, Path(folder))

    actor_floats, critic_floats = gradient_sizes()
    allreduce = {
        int(name.split("_")[1]): value for name, value in measured.items() if name.startswith("allreduce_")
    }
    print("\nall-reduce between 2 workers (median of 200)")
    for size, ms in sorted(allreduce.items()):
        mark = {actor_floats: "  <- the actor's gradients", critic_floats: "  <- the critic's gradients"}
        print(f"  {size:>9,} floats  {ms:7.3f} ms{mark.get(size, '')}")
    latency, per_byte = fit(allreduce)
    print(f"  fit: {latency * 1000:.0f} us per message, {1 / per_byte / 1e6:.2f} GB/s")

    print("\nlearner update, 1 thread (ms)")
    for batch in BATCHES:
        alone, averaged = measured[f"update_alone_{batch}"], measured[f"update_averaged_{batch}"]
        print(f"  batch {batch:>4}: alone {alone:6.2f}   gradients averaged over 2 workers {averaged:6.2f}"
              f"   (+{averaged - alone:.2f})")  # fmt: skip

    if trained:
        print("\nFetchPush dtd train, second epoch of 10 cycles (1 thread per worker, inline)")
        for (algo, workers), figures in trained.items():
            print(f"  {algo} {workers} worker(s): {figures['env_steps_per_s']:7.0f} env steps/s, "
                  f"{figures['updates_per_s_per_worker']:6.1f} updates/s per worker")  # fmt: skip

    print("\nmodel: N workers on a machine of at least N free cores (each as fast as one here)")
    print(f"  per update: compute + ring all-reduces of the critic's {critic_floats:,} and the actor's "
          f"{actor_floats:,} gradient entries")  # fmt: skip
    for batch in BATCHES:
        alone = measured[f"update_alone_{batch}"]
        print(f"  batch {batch}: update alone {alone:.2f} ms")
        for workers in (1, 2, 8, 19, 32, 64):
            sync = sum(
                ring_allreduce_ms(workers, n, latency, per_byte) for n in (actor_floats, critic_floats)
            )
            share = alone / (alone + sync)
            print(f"    N = {workers:>2}: all-reduces {sync:6.2f} ms per update; updates at "
                  f"{share:4.0%} of one worker's speed; {workers * share:5.1f}x its env steps/s "
                  "where updates bound the cycle")  # fmt: skip
    print("  Across machines the all-reduce's latency and bandwidth are the network's: put them in")
    print("  ring_allreduce_ms (e.g. 50 us and 1.25 GB/s for 10 Gb Ethernet).")


if __name__ == "__main__":
    main()
